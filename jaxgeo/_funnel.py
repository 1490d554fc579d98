"""Shortest path inside a face corridor: planar unfolding and the funnel algorithm.

The faces of a corridor are laid out in the plane one after the other, each
rotated about the edge (*portal*) it shares with the previous one; distances inside
every face are kept exactly, so a straight segment of the unfolding that stays in
the corridor is a path on the surface of the same length. The shortest path inside
the corridor is then the taut string of the planar *sleeve*: Lee & Preparata's
funnel algorithm (here in the restart form of Mononen's "simple stupid funnel")
finds it in one sweep over the portals. It bends only at corridor vertices, the
*contacts*, where it wraps around a wall of the sleeve.

Everything here is numpy and plain Python floats (discrete, outside jit). Each
vertex appearance in the unfolding is an *instance*: a mesh vertex can appear more
than once when the corridor passes it twice, at different planar places. A contact
is always an instance, never a clipped edge parameter.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._corridor import EndPoint, Topology
from ._errors import JaxgeoError


@dataclass
class Strip:
    """A corridor unfolded into the plane.

    Instances: `0` the apex of face 0 (the corner opposite portal 0), `1` and `2`
    the left and right ends of portal 0, `3 + k` the new vertex of face `k + 1`,
    then the start point `S` and the end point `E`.
    """

    faces: np.ndarray  # (n,) corridor faces
    xy: np.ndarray  # (I, 2) instance positions
    vid: np.ndarray  # (I,) mesh vertex of each instance (-1 for S, E)
    left: np.ndarray  # (n-1,) portal left instance
    right: np.ndarray  # (n-1,) portal right instance
    apex_corner: np.ndarray  # (n-1,) corner of faces[k] opposite portal k
    corner_inst: np.ndarray  # (n, 3) instance of each corner, mesh corner order
    run_start: np.ndarray  # (I,) first portal holding the instance (-1: none)
    run_end: np.ndarray  # (I,) last portal holding the instance
    start: int = 0
    end: int = 0


def unfold(
    topo: Topology, corridor: list[int], start: EndPoint, end: EndPoint
) -> Strip:
    """Lay a corridor out in the plane (face 0 at the origin, portal 0 on the y
    axis, the corridor heading to +x) and place the start and end points."""
    faces = np.asarray(corridor, dtype=np.int64)
    n = faces.size
    fv = topo.faces[faces]
    v = topo.vertices
    n_inst = 3 + max(n - 1, 0) + 2
    xy = np.zeros((n_inst, 2))
    vid = np.full(n_inst, -1, dtype=np.int64)
    corner_inst = np.zeros((n, 3), dtype=np.int64)
    if n == 1:
        vid[:3] = fv[0]
        xy[:3] = _place_triangle(v[fv[0]])
        corner_inst[0] = [0, 1, 2]
        left = right = apex_corner = np.zeros(0, dtype=np.int64)
    else:
        shared = (fv[:-1, :, None] == fv[1:, None, :]).any(-1)
        if not np.all(shared.sum(1) == 2):
            raise JaxgeoError("corridor faces do not share edges")
        apex_corner = np.argmin(shared, axis=1)
        k = np.arange(n - 1)
        r_vid = fv[k, (apex_corner + 1) % 3]
        l_vid = fv[k, (apex_corner + 2) % 3]
        nxt = fv[1:]
        w_mask = (nxt != l_vid[:, None]) & (nxt != r_vid[:, None])
        w_vid = nxt[w_mask]
        keep_left = np.zeros(n - 1, dtype=bool)
        keep_left[:-1] = l_vid[1:] == l_vid[:-1]
        e = v[l_vid] - v[r_vid]
        q = v[w_vid] - v[r_vid]
        el = np.linalg.norm(e, axis=1)
        px = np.sum(e * q, axis=1) / el
        py = np.linalg.norm(_cross3(e, q), axis=1) / el
        a_vid = fv[0, apex_corner[0]]
        qa = v[a_vid] - v[r_vid[0]]
        ax = float(np.dot(e[0], qa) / el[0])
        ay = float(np.linalg.norm(np.cross(e[0], qa)) / el[0])
        vid[0], vid[1], vid[2] = a_vid, l_vid[0], r_vid[0]
        vid[3 : 3 + n - 1] = w_vid
        # portal instances: a portal end is replaced by the new vertex w_{k-1}
        idx = np.arange(n - 1)
        new_left = np.concatenate([[True], ~keep_left[:-1]])
        new_right = np.concatenate([[True], keep_left[:-1]])
        last_l = np.maximum.accumulate(np.where(new_left, idx, 0))
        last_r = np.maximum.accumulate(np.where(new_right, idx, 0))
        left = np.where(last_l == 0, 1, 2 + last_l)
        right = np.where(last_r == 0, 2, 2 + last_r)
        # frame of portal k: right end at 0, left end on the +y axis (complex
        # numbers); face k + 1 ahead (x > 0). T_k maps portal k+1's frame into
        # portal k's, and the prefix compositions map every frame to portal 0's.
        w_loc = py + 1j * px
        l_loc = 1j * el
        big_r = np.where(keep_left, w_loc, 0.0)
        big_l = np.where(keep_left, l_loc, w_loc)
        d = big_l - big_r
        a = -1j * d / np.abs(d)
        rot = np.concatenate([[1.0 + 0j], np.cumprod(a[:-1])])
        shift = np.concatenate([[0j], np.cumsum(rot[:-1] * big_r[:-1])])
        w = rot * w_loc + shift
        xy[0] = (-ay, ax)
        xy[1] = (0.0, el[0])
        xy[3 : 3 + n - 1, 0] = w.real
        xy[3 : 3 + n - 1, 1] = w.imag
        corner_inst[0] = _match(fv[0], vid[[0, 1, 2]], np.arange(3))
        ids = np.stack([left, right, 3 + k], axis=1)
        hit = np.argmax(fv[1:, :, None] == vid[ids][:, None, :], axis=2)
        corner_inst[1:] = np.take_along_axis(ids, hit, axis=1)
    s_inst, e_inst = n_inst - 2, n_inst - 1
    xy[s_inst] = _point_xy(start, fv[0], corner_inst[0], xy)
    xy[e_inst] = _point_xy(end, fv[-1], corner_inst[-1], xy)
    run_start = np.full(n_inst, -1, dtype=np.int64)
    run_end = np.full(n_inst, -1, dtype=np.int64)
    portal = np.arange(left.size)
    for side in (left, right):  # runs are contiguous: first and last occurrence
        run_end[side] = portal
        run_start[side[::-1]] = portal[::-1]
    return Strip(
        faces,
        xy,
        vid,
        left,
        right,
        apex_corner,
        corner_inst,
        run_start,
        run_end,
        s_inst,
        e_inst,
    )


def _cross3(e: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.stack(
        [
            e[..., 1] * q[..., 2] - e[..., 2] * q[..., 1],
            e[..., 2] * q[..., 0] - e[..., 0] * q[..., 2],
            e[..., 0] * q[..., 1] - e[..., 1] * q[..., 0],
        ],
        axis=-1,
    )


def _place_triangle(p: np.ndarray) -> np.ndarray:
    e = p[1] - p[0]
    q = p[2] - p[0]
    el = np.linalg.norm(e)
    return np.array(
        [
            [0.0, 0.0],
            [el, 0.0],
            [np.dot(e, q) / el, np.linalg.norm(np.cross(e, q)) / el],
        ]
    )


def _match(face_vids: np.ndarray, inst_vids: np.ndarray, inst: np.ndarray) -> list[int]:
    return [int(inst[np.flatnonzero(inst_vids == fv)[0]]) for fv in face_vids]


def _point_xy(p: EndPoint, face_vids, corners, xy) -> np.ndarray:
    out = np.zeros(2)
    for vtx, w in p.support.items():
        hit = np.flatnonzero(face_vids == vtx)
        if not hit.size:
            raise JaxgeoError("the corridor does not start/end at the given point")
        out += w * xy[corners[hit[0]]]
    return out


def funnel(strip: Strip) -> list[int]:
    """The contacts (instances) of the shortest path through the strip, in order.

    A portal end exactly on the funnel's other side counts as crossing it, so a
    path grazing a vertex makes that vertex a contact.
    """
    n_portal = strip.left.size
    lefts = strip.left.tolist() + [strip.end]
    rights = strip.right.tolist() + [strip.end]
    run_end = strip.run_end.tolist()
    xs, ys = strip.xy[:, 0].tolist(), strip.xy[:, 1].tolist()
    apex, left, right = strip.start, lefts[0], rights[0]
    # the cross products are written out: this loop is the refinement's hot spot
    ax, ay = xs[apex], ys[apex]
    lx, ly, rx, ry = xs[left] - ax, ys[left] - ay, xs[right] - ax, ys[right] - ay
    corners: list[int] = []
    i = 1
    while i <= n_portal:
        nl, nr = lefts[i], rights[i]
        restart = -1
        if i == n_portal:  # the end point: inside the funnel, or past a side
            px, py = xs[nl] - ax, ys[nl] - ay
            if lx * py - ly * px > 0.0:
                restart = left
            elif rx * py - ry * px < 0.0:
                restart = right
            else:
                break
        else:
            if nr != right:
                px, py = xs[nr] - ax, ys[nr] - ay
                if rx * py - ry * px >= 0.0:
                    if lx * py - ly * px < 0.0:
                        right, rx, ry = nr, px, py
                    else:
                        restart = left
            if restart < 0 and nl != left:
                px, py = xs[nl] - ax, ys[nl] - ay
                if lx * py - ly * px <= 0.0:
                    if rx * py - ry * px > 0.0:
                        left, lx, ly = nl, px, py
                    else:
                        restart = right
        if restart < 0:
            i += 1
            continue
        corners.append(restart)
        apex = restart
        ax, ay = xs[apex], ys[apex]
        j = run_end[apex] + 1
        left, right, i = lefts[j], rights[j], j + 1
        lx, ly = xs[left] - ax, ys[left] - ay
        rx, ry = xs[right] - ax, ys[right] - ay
    return corners


@dataclass
class Solution:
    """A path in a strip: points `[S, contacts..., E]` (instances), and per segment
    between consecutive points the range of portals it crosses, `[p0, p1]`
    (`p1 = p0 - 1`: no portal, both points in one face, `face` then names it)."""

    strip: Strip
    points: list[int]
    seg_portals: list[tuple[int, int]] = field(default_factory=list)
    seg_face: list[int] = field(default_factory=list)
    length: float = 0.0


def solve(strip: Strip, touch_tol: float) -> Solution:
    """Funnel, then make every vertex the path passes within `touch_tol` of an
    explicit contact, then work out the segments' portal ranges and the length."""
    corners = funnel(strip)
    points = [strip.start, *corners, strip.end]
    points = _add_touches(strip, points, touch_tol)
    sol = Solution(strip, points)
    n_portal = strip.left.size
    total = 0.0
    for a, b in zip(points[:-1], points[1:], strict=True):
        p0 = 0 if a == strip.start else int(strip.run_end[a]) + 1
        p1 = n_portal - 1 if b == strip.end else int(strip.run_start[b]) - 1
        if p1 < p0:
            p1 = p0 - 1
            sol.seg_face.append(_common_face(strip, a, b))
        else:
            sol.seg_face.append(-1)
        sol.seg_portals.append((p0, p1))
        total += float(np.linalg.norm(strip.xy[b] - strip.xy[a]))
    sol.length = total
    return sol


def _faces_of(strip: Strip, inst: int) -> tuple[int, int]:
    """Range of corridor faces holding an instance."""
    n = strip.faces.size
    if inst == strip.start:
        return 0, 0
    if inst == strip.end:
        return n - 1, n - 1
    if strip.run_start[inst] < 0:  # apex of face 0 or vertex of the last face only
        rows = np.flatnonzero((strip.corner_inst == inst).any(1))
        return int(rows[0]), int(rows[-1])
    return int(strip.run_start[inst]), int(strip.run_end[inst]) + 1


def _common_face(strip: Strip, a: int, b: int) -> int:
    lo_a, hi_a = _faces_of(strip, a)
    lo_b, hi_b = _faces_of(strip, b)
    lo, hi = max(lo_a, lo_b), min(hi_a, hi_b)
    if lo > hi:
        raise JaxgeoError("internal error: consecutive path points share no face")
    return lo


def _add_touches(strip: Strip, points: list[int], tol: float) -> list[int]:
    """Insert, as contacts, the corridor vertices within `tol` of a segment."""
    n_portal = strip.left.size
    if n_portal == 0:
        return points
    # segment of each portal
    firsts = [0] + [int(strip.run_end[p]) + 1 for p in points[1:-1]]
    seg_of = np.searchsorted(np.asarray(firsts), np.arange(n_portal), "right") - 1
    # the instances on some portal, but not already path points
    on_portal = strip.run_start >= 0
    on_portal[points] = False
    cand = np.flatnonzero(on_portal)
    seg = seg_of[strip.run_start[cand]]
    ok = seg == seg_of[strip.run_end[cand]]
    pts = np.asarray(points)
    a, b = strip.xy[pts[seg]], strip.xy[pts[seg + 1]]
    d, rel = b - a, strip.xy[cand] - a
    ll = np.maximum(np.sum(d * d, axis=1), 1e-300)
    t = np.sum(rel * d, axis=1) / ll
    dist = np.abs(rel[:, 0] * d[:, 1] - rel[:, 1] * d[:, 0]) / np.sqrt(ll)
    hit = ok & (dist <= tol) & (t > 0) & (t < 1)
    if not hit.any():
        return points
    cand, seg = cand[hit], seg[hit]
    order = np.argsort(strip.run_start[cand], kind="stable")
    out = list(points)
    inserted = []
    last = -1
    for c in cand[order].tolist():
        if strip.run_start[c] > last:
            inserted.append(c)
            last = int(strip.run_end[c])
    out = sorted(out[1:-1] + inserted, key=lambda i: (int(strip.run_start[i]), i))
    return [points[0], *out, points[-1]]
