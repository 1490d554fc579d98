"""Exact, locally-shortest polyhedral geodesics, and their differentiable length.

**The method.** A geodesic of a triangle mesh (a polyhedral surface) is a polyline
that is straight inside every face it crosses, crosses edges "straight" (it is a
straight segment once the two faces are unfolded into a plane), and passes through
a vertex only when the total face angle on *both* sides of the path there is at
least π (saddle vertices, angle sum over 2π) or the vertex is on the boundary. It
never passes through a vertex of positive curvature (angle sum under 2π). Given a
*corridor* (a strip of faces from the start to the end point):

1. unfold the strip into the plane and pull the string: the funnel algorithm
   (`jaxgeo._funnel`) gives the shortest path inside the strip in one sweep, with
   its *contacts*, the strip vertices it wraps around, as explicit vertex states
   (never as edge parameters clipped to 0 or 1; a vertex the path grazes within
   1e-9 mean edge lengths is made a contact too);
2. at every contact v compute the angle on the side away from the strip,
   Θ(v) − (angle swept inside the strip); if it is below π the path can be
   shortened by passing v on that side: replace the strip's faces around v by the
   fan on the other side (the "wedge" argument, as in Sharp & Crane's FlipOut).
   The old path still fits the new strip and has a corner of less than π there,
   so the new string is strictly shorter and the loop cannot cycle;
3. repeat until no contact admits such a move. Boundary contacts never move (the
   other side is outside the surface): the path then wraps around the boundary.

Why this and not Newton on the crossing parameters: with the crossed edges fixed
the length is convex in the parameters, but its minimiser sits on a parameter
bound (a vertex) in a large share of the crossings, which Newton handles badly and
clipping handles wrongly; the funnel is exact (no iteration, no tolerance), O(n)
per strip, and yields the contacts that step 2 needs.

**Global choice.** The result is *locally* shortest. `exact_geodesic` runs the
loop from every corridor it is given and from the corridors of Dijkstra paths on
the edge graph (the shortest and `n_via` through other vertices), and returns the
shortest result, then explores around nearby vertices of positive curvature. On a
surface without interior positive curvature every homotopy class holds a single
locally-shortest path, so a corridor homotopic to one already refined is skipped.
This is globally shortest in practice on the test surfaces (sphere, catenoid, cone
tent, saddle): the tests compare against the exact MMP solver of pygeodesic on
hundreds of vertex pairs.

**Gradients.** `exact_length` recomputes the length from `mesh.vertices` and the
endpoints' barycentric coordinates with the combinatorics frozen (the strips
between consecutive pinned points — endpoints and vertex contacts — and the
contacts themselves). Between two pinned points the geodesic is the straight
segment of the strip's unfolding, so its length is the planar distance of the two
unfolded points; the unfolding is written in `jax.numpy` (a `lax.scan` over the
portals), so `jax.grad` goes through it. The crossing parameters need no implicit
correction: they minimise the length, so by the envelope theorem the derivative of
the minimal length equals the partial derivative at fixed crossings, which the
unfolded distance already is. Norms go through `safe_norm`: no NaN gradients.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._corridor import EndPoint, Topology, check_corridor, clean_corridor, topology
from ._errors import JaxgeoError
from ._funnel import Solution, Strip, solve, unfold
from ._numerics import safe_norm
from .mesh import Mesh

__all__ = [
    "ExactPath",
    "PathStructure",
    "dijkstra_corridor",
    "exact_geodesic",
    "exact_length",
]

#: Point kinds of `ExactPath.kinds`.
KIND_FACE, KIND_EDGE, KIND_VERTEX = 0, 1, 2

#: A contact moves to the other side when the angle there is below π − this.
ANGLE_TOL = 1e-9
#: Explore releases the held vertex of this many forced paths (the shortest).
RELEASE_TRIES = 8
#: A vertex within this many mean edge lengths of the path becomes a contact.
TOUCH_TOL = 1e-9


class PathStructure(eqx.Module):
    """The frozen combinatorics of an exact path, for `exact_length`.

    The path is cut at its *pinned* points (the endpoints and the vertex contacts)
    into segments; segment `s` crosses the portals (shared edges) of steps
    `seg_first[s] … seg_last[s]`. Step `t` unfolds across the portal with left and
    right vertices `step_l[t]`, `step_r[t]` into the face whose third vertex is
    `step_w[t]`; `step_apex[t]` is the vertex behind the portal (used at a
    segment's first step, `step_first[t]`), `step_keep_left[t]` says which portal
    end the next step keeps. A segment's end points are combinations of three
    vertices `a_vid`/`b_vid` with coefficients `coef[a_src]`/`coef[b_src]`, where
    `coef = [start_bary, end_bary, 1, 0]`; for a segment with steps these vertices
    are (left, right, apex) of its first step and (left, right, third) of its last.
    Arrays are padded (to powers of two, to limit recompilation); `seg_mask` marks
    the real segments.
    """

    step_l: Int[Array, " T"]
    step_r: Int[Array, " T"]
    step_w: Int[Array, " T"]
    step_apex: Int[Array, " T"]
    step_first: Bool[Array, " T"]
    step_keep_left: Bool[Array, " T"]
    seg_first: Int[Array, " S"]
    seg_last: Int[Array, " S"]
    seg_has_steps: Bool[Array, " S"]
    seg_mask: Bool[Array, " S"]
    a_vid: Int[Array, "S 3"]
    a_src: Int[Array, "S 3"]
    b_vid: Int[Array, "S 3"]
    b_src: Int[Array, "S 3"]


class ExactPath(eqx.Module):
    """An exact locally-shortest geodesic of a triangle mesh.

    **Attributes:**

    - `points`: `(n, 3)` the polyline: start, edge crossings and vertex contacts,
      end.
    - `kinds`: `(n,)` 0 for an endpoint (a point of face `elements[i]`), 1 for a
      point on edge `elements[i]`, 2 for a mesh vertex `elements[i]`.
    - `elements`: `(n,)` the face, edge or vertex id.
    - `params`: `(n,)` on an edge `e` the point is
      `(1 - u)·V[edges[e, 0]] + u·V[edges[e, 1]]`; 0 otherwise.
    - `length`: the length of the polyline.
    - `faces`: the final face corridor (start face to end face).
    - `start_face`, `start_bary`, `end_face`, `end_bary`: the query.
    - `structure`: the frozen combinatorics, for `exact_length`.
    - `converged`: False when the contact loop hit its iteration limit (the path
      is then a valid surface path, maybe not locally shortest).
    """

    points: Float[Array, "n 3"]
    kinds: Int[Array, " n"]
    elements: Int[Array, " n"]
    params: Float[Array, " n"]
    length: Float[Array, ""]
    faces: Int[Array, " m"]
    start_face: Int[Array, ""]
    start_bary: Float[Array, " 3"]
    end_face: Int[Array, ""]
    end_bary: Float[Array, " 3"]
    structure: PathStructure
    converged: Bool[Array, ""]

    @property
    def n_contacts(self) -> int:
        """Number of vertex contacts."""
        return int(np.sum(np.asarray(self.kinds) == KIND_VERTEX))


# ------------------------------------------------------------------ corridors


def dijkstra_corridor(
    mesh: Mesh,
    start_face: int,
    start_bary: ArrayLike,
    end_face: int,
    end_bary: ArrayLike,
) -> list[int]:
    """A face corridor along the Dijkstra shortest path of the mesh's edge graph.

    **Arguments:**

    - `mesh`: the mesh.
    - `start_face`, `start_bary`: the start point (face id, barycentric coords).
    - `end_face`, `end_bary`: the end point.

    **Returns:** a list of face ids, consecutive faces sharing an edge, from a face
    holding the start point to a face holding the end point. Around each vertex of
    the edge path it takes the faces on the side of the smaller angle.
    """
    topo = topology(mesh)
    start = EndPoint(topo, start_face, start_bary)
    end = EndPoint(topo, end_face, end_bary)
    path = topo.vertex_paths(start, end)[0]
    return topo.vertex_path_corridor(path, start, end)


# ------------------------------------------------------------ contact moves


def _ray_coord(topo: Topology, strip: Strip, v: int, k: int, target: int) -> float:
    """Angular position, around contact instance `v`, of the ray towards instance
    `target`, which lies in corridor face `k`: the angle swept from the outer edge
    of the first face of `v`'s run, through the run, to the ray."""
    i = int(strip.run_start[v])
    vid = int(strip.vid[v])
    faces = strip.faces.tolist()
    acc = 0.0
    for m in range(i, k):
        acc += topo.angle_at(faces[m], vid)
    if k == i:
        other = _other_end(strip, i, v)
        corners = strip.corner_inst[i]
        s = int(corners[(corners != v) & (corners != other)][0])
    else:
        s = _other_end(strip, k - 1, v)
    ox, oy = strip.xy[v].tolist()
    ax, ay = strip.xy[target].tolist()
    bx, by = strip.xy[s].tolist()
    ax, ay, bx, by = ax - ox, ay - oy, bx - ox, by - oy
    ang = math.atan2(abs(ax * by - ay * bx), ax * bx + ay * by)
    corner = topo.angle_at(faces[k], vid)
    return acc + min(ang, corner)


def _other_end(strip: Strip, portal: int, v: int) -> int:
    return int(strip.right[portal] if strip.left[portal] == v else strip.left[portal])


def _moves(
    topo: Topology, sol: Solution, frozen: frozenset[int] = frozenset()
) -> list[tuple[float, int, int, int]]:
    """Contacts where the path can be shortened: (angle on the far side, first and
    last corridor index of the faces to replace, mesh vertex). Contacts at
    `frozen` vertices stay."""
    strip = sol.strip
    out = []
    for t in range(1, len(sol.points) - 1):
        v = sol.points[t]
        vid = int(strip.vid[v])
        if topo.boundary_vertex[vid] or vid in frozen:
            continue
        i, j = int(strip.run_start[v]), int(strip.run_end[v])
        k_in = sol.seg_face[t - 1] if sol.seg_face[t - 1] >= 0 else i
        k_out = sol.seg_face[t] if sol.seg_face[t] >= 0 else j + 1
        if k_out <= k_in:
            continue
        swept = _ray_coord(topo, strip, v, k_out, sol.points[t + 1]) - _ray_coord(
            topo, strip, v, k_in, sol.points[t - 1]
        )
        far = topo.angle_sum[vid] - abs(swept)
        if far < math.pi - ANGLE_TOL:
            out.append((far, k_in, k_out, vid))
    return out


def _apply_moves(
    topo: Topology, corridor: list[int], moves: list[tuple[float, int, int, int]]
) -> list[int]:
    chosen: list[tuple[int, int, int]] = []
    for _, lo, hi, vid in sorted(moves):
        if all(hi < a or lo > b for a, b, _ in chosen):
            chosen.append((lo, hi, vid))
    out = list(corridor)
    for lo, hi, vid in sorted(chosen, reverse=True):
        ccw = topo.rotate(out[lo], vid, True) == out[lo + 1]
        fan = topo.fan(vid, out[lo], out[hi], not ccw)
        if fan is not None:
            out[lo : hi + 1] = fan
    return out


def _refine(
    topo: Topology,
    corridor: Sequence[int],
    start: EndPoint,
    end: EndPoint,
    max_iter: int,
    frozen: frozenset[int] = frozenset(),
) -> tuple[Solution, list[int], bool]:
    corridor = clean_corridor(check_corridor(topo, corridor).tolist(), start, end, topo)
    if not start.in_face(topo, corridor[0]) or not end.in_face(topo, corridor[-1]):
        raise JaxgeoError(
            "a corridor must run from a face holding the start point to a face "
            "holding the end point"
        )
    tol = TOUCH_TOL * topo.mean_edge_length
    best = None
    for _ in range(max_iter):
        sol = solve(unfold(topo, corridor, start, end), tol)
        if best is None or sol.length <= best[0].length:
            best = (sol, corridor)
        moves = _moves(topo, sol, frozen)
        if not moves:
            return sol, corridor, True
        corridor = clean_corridor(_apply_moves(topo, corridor, moves), start, end, topo)
    return best[0], best[1], False


def _homotopic_to_any(topo: Topology, c, done, start: EndPoint, end: EndPoint) -> bool:
    if not (start.in_face(topo, c[0]) and end.in_face(topo, c[-1])):
        return False
    try:
        return any(topo.homotopic(c, d, start, end) for d in done)
    except JaxgeoError:  # ends that do not meet: refine it, as without the test
        return False


def _near_walls(sol: Solution, radius: float) -> list[tuple[float, int]]:
    """Corridor vertices (instances) the path passes within `radius` of without
    touching them, nearest first: (distance, instance)."""
    strip = sol.strip
    out = []
    for s, (p0, p1) in enumerate(sol.seg_portals):
        if p1 < p0:
            continue
        cand = np.unique(
            np.concatenate([strip.left[p0 : p1 + 1], strip.right[p0 : p1 + 1]])
        )
        cand = cand[(strip.run_start[cand] >= p0) & (strip.run_end[cand] <= p1)]
        a, b = strip.xy[sol.points[s]], strip.xy[sol.points[s + 1]]
        d = b - a
        rel = strip.xy[cand] - a
        dist = np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]) / np.linalg.norm(d)
        out += [
            (float(x), int(c)) for x, c in zip(dist, cand, strict=True) if x < radius
        ]
    return sorted(out)


def _explore(
    topo: Topology,
    sol: Solution,
    corridor: list[int],
    start: EndPoint,
    end: EndPoint,
    max_iter: int,
    radius: float,
    max_tries: int,
) -> tuple[Solution, list[int]]:
    """Look for a shorter locally-shortest path in neighbouring classes: force the
    path to the other side of a vertex it passes near (within `radius`), relax
    with that vertex held (`frozen`); if the result still leans on the vertex,
    release it and relax again; keep the result if it is shorter.

    Only vertices of positive curvature (angle sum below 2π) are tried: two
    geodesics from A to B bound a bigon whose enclosed curvature is, by
    Gauss-Bonnet, the sum of its two corner angles, so it must hold a vertex of
    positive curvature; around flat or saddle vertices there is nothing to find.
    """
    tried: set[int] = set()
    tries = 0
    improved = True
    while improved and tries < max_tries:
        improved = False
        held = []  # forced paths that still lean on their vertex
        for _, inst in _near_walls(sol, radius):
            vid = int(sol.strip.vid[inst])
            if (
                vid in tried
                or topo.boundary_vertex[vid]
                or topo.angle_sum[vid] >= 2.0 * math.pi - ANGLE_TOL
                or tries >= max_tries
            ):
                continue
            tried.add(vid)
            tries += 1
            lo = int(sol.strip.run_start[inst])
            hi = int(sol.strip.run_end[inst]) + 1
            ccw = topo.rotate(corridor[lo], vid, True) == corridor[lo + 1]
            fan = topo.fan(vid, corridor[lo], corridor[hi], not ccw)
            if fan is None:
                continue
            trial = corridor[:lo] + fan + corridor[hi + 1 :]
            new, faces, ok = _refine(
                topo, trial, start, end, max_iter, frozenset([vid])
            )
            if not ok:
                continue
            if any(int(new.strip.vid[p]) == vid for p in new.points[1:-1]):
                held.append((new.length, vid, faces))
            elif new.length < sol.length * (1.0 - 1e-14):
                sol, corridor, improved = new, faces, True
                tried = {vid}  # the path moved: the others are worth a new try
                break
        if improved:
            continue
        # Held against its vertex, the rest of a forced path may have moved into
        # another basin; released, it may stay there (a shorter geodesic up to an
        # edge aside needs this: found on perturbed spheres) or slide back. The
        # forced paths closest to the current length are released.
        for _, vid, faces in sorted(held)[:RELEASE_TRIES]:
            new, faces, ok = _refine(topo, faces, start, end, max_iter)
            if ok and new.length < sol.length * (1.0 - 1e-14):
                sol, corridor, improved = new, faces, True
                tried = {vid}
                break
    return sol, corridor


# ------------------------------------------------------------------ results


def _i(x) -> np.ndarray:
    return np.asarray(x, dtype=np.int32)


def _f(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _bucket(n: int) -> int:
    return 1 << max(n - 1, 0).bit_length()


def _structure(
    topo: Topology, sol: Solution, start: EndPoint, end: EndPoint
) -> PathStructure:
    strip = sol.strip
    sf, ef = topo.faces[start.face].tolist(), topo.faces[end.face].tolist()
    last_point = len(sol.points) - 1

    def src(point_index: int, vids: list[int]) -> list[int]:
        if point_index == 0:
            return [sf.index(x) if x in sf else 7 for x in vids]
        if point_index == last_point:
            return [3 + ef.index(x) if x in ef else 7 for x in vids]
        me = int(strip.vid[sol.points[point_index]])
        return [6 if x == me else 7 for x in vids]

    steps: list[tuple[int, int, int, int, bool, bool]] = []
    seg_first, seg_last, has_steps = [], [], []
    a_vid, a_src, b_vid, b_src = [], [], [], []
    for s, (p0, p1) in enumerate(sol.seg_portals):
        if p1 >= p0:
            seg_first.append(len(steps))
            for k in range(p0, p1 + 1):
                li, ri = int(strip.left[k]), int(strip.right[k])
                keep = k < p1 and int(strip.left[k + 1]) == li
                apex = int(topo.faces[strip.faces[k], strip.apex_corner[k]])
                steps.append(
                    (
                        int(strip.vid[li]),
                        int(strip.vid[ri]),
                        int(strip.vid[3 + k]),
                        apex,
                        k == p0,
                        keep,
                    )
                )
            seg_last.append(len(steps) - 1)
            has_steps.append(True)
            first, last = steps[seg_first[-1]], steps[-1]
            va = [first[0], first[1], first[3]]
            vb = [last[0], last[1], last[2]]
        else:
            seg_first.append(0)
            seg_last.append(0)
            has_steps.append(False)
            va = vb = topo.faces[strip.faces[sol.seg_face[s]]].tolist()
        a_vid.append(va)
        a_src.append(src(s, va))
        b_vid.append(vb)
        b_src.append(src(s + 1, vb))
    n_steps, n_seg = _bucket(max(len(steps), 1)), _bucket(len(seg_first))
    f0 = topo.faces[0].tolist()
    steps += [(f0[0], f0[1], f0[2], f0[2], True, False)] * (n_steps - len(steps))
    pad = n_seg - len(seg_first)
    st = np.array(steps, dtype=np.int64)

    def ints(x, fill=None):
        x = np.asarray(x, dtype=np.int64)
        if fill is not None:
            x = np.concatenate([x, np.full((pad,) + x.shape[1:], fill)])
        return _i(x)

    return PathStructure(
        step_l=ints(st[:, 0]),
        step_r=ints(st[:, 1]),
        step_w=ints(st[:, 2]),
        step_apex=ints(st[:, 3]),
        step_first=st[:, 4] != 0,
        step_keep_left=st[:, 5] != 0,
        seg_first=ints(seg_first, 0),
        seg_last=ints(seg_last, 0),
        seg_has_steps=np.array(has_steps + [False] * pad, dtype=bool),
        seg_mask=np.arange(n_seg) < len(seg_first),
        a_vid=ints(a_vid, 0),
        a_src=ints(a_src, 7),
        b_vid=ints(b_vid, 0),
        b_src=ints(b_src, 7),
    )


def _polyline(topo: Topology, sol: Solution, start: EndPoint, end: EndPoint):
    strip = sol.strip
    v = topo.vertices
    pts, kinds, elems, params = [start.xyz], [KIND_FACE], [start.face], [0.0]
    for s, (p0, p1) in enumerate(sol.seg_portals):
        a, b = strip.xy[sol.points[s]], strip.xy[sol.points[s + 1]]
        d = b - a
        for k in range(p0, p1 + 1):
            li, ri = strip.left[k], strip.right[k]
            pr, pl = strip.xy[ri], strip.xy[li]
            e = pl - pr
            den = e[0] * d[1] - e[1] * d[0]
            q = a - pr
            t = (q[0] * d[1] - q[1] * d[0]) / den if den != 0 else 0.5
            t = min(max(float(t), 0.0), 1.0)
            edge = int(topo.face_edges[strip.faces[k], strip.apex_corner[k]])
            u = t if int(strip.vid[ri]) == topo.edges[edge, 0] else 1.0 - t
            e0, e1 = topo.edges[edge]
            pts.append((1.0 - u) * v[e0] + u * v[e1])
            kinds.append(KIND_EDGE)
            elems.append(edge)
            params.append(u)
        if s + 1 < len(sol.seg_portals):
            vid = int(strip.vid[sol.points[s + 1]])
            pts.append(v[vid])
            kinds.append(KIND_VERTEX)
            elems.append(vid)
            params.append(0.0)
    pts.append(end.xyz)
    kinds.append(KIND_FACE)
    elems.append(end.face)
    params.append(0.0)
    return np.array(pts), np.array(kinds), np.array(elems), np.array(params)


def exact_geodesic(
    mesh: Mesh,
    start_face: int,
    start_bary: ArrayLike,
    end_face: int,
    end_bary: ArrayLike,
    corridors: Sequence[Sequence[int]] | None = None,
    *,
    dijkstra: bool = True,
    max_iter: int = 1000,
    explore: bool = True,
    explore_radius: float = 1.0,
    explore_tries: int = 40,
    n_via: int = 2,
) -> ExactPath:
    """The exact locally-shortest polyhedral geodesic between two surface points,
    the shortest over several starting corridors.

    **Arguments:**

    - `mesh`: a concrete `Mesh` (this runs in numpy, outside jit).
    - `start_face`, `start_bary`: the start point as a face id and barycentric
      coordinates `(3,)` (normalised to sum 1).
    - `end_face`, `end_bary`: the end point.
    - `corridors`: initial face corridors, each a sequence of face ids from a face
      holding the start point to one holding the end point, consecutive faces
      sharing an edge (for instance the faces a laser-ray path crossed).
    - `dijkstra`: also start from the corridor of the edge graph's Dijkstra path.
    - `max_iter`: limit of the contact-move loop per corridor.

    **Returns:** the shortest `ExactPath` found.

    **Raises** `JaxgeoError` for bad points or corridors, or points on different
    connected components.
    """
    path = _exact_geodesic_numpy(
        mesh,
        start_face,
        start_bary,
        end_face,
        end_bary,
        corridors,
        dijkstra=dijkstra,
        max_iter=max_iter,
        explore=explore,
        explore_radius=explore_radius,
        explore_tries=explore_tries,
        n_via=n_via,
    )
    return jax.device_put(path)  # one transfer for all the leaves


def _exact_geodesic_numpy(
    mesh: Mesh,
    start_face: int,
    start_bary: ArrayLike,
    end_face: int,
    end_bary: ArrayLike,
    corridors: Sequence[Sequence[int]] | None = None,
    *,
    dijkstra: bool = True,
    max_iter: int = 1000,
    explore: bool = True,
    explore_radius: float = 1.0,
    explore_tries: int = 40,
    n_via: int = 2,
) -> ExactPath:
    """`exact_geodesic` with numpy leaves (inside a callback: no jax dispatch)."""
    topo = topology(mesh)
    start = EndPoint(topo, start_face, start_bary)
    end = EndPoint(topo, end_face, end_bary)
    todo = [list(c) for c in (corridors or [])]
    failure = None
    if dijkstra:
        for path in topo.vertex_paths(start, end, n_via):
            # A vertex path next to an endpoint that lies on an edge or at a vertex
            # can fail to give a corridor (known limitation of
            # `vertex_path_corridor`); the other corridors still count.
            try:
                todo.append(topo.vertex_path_corridor(path, start, end))
            except (JaxgeoError, IndexError) as e:
                failure = e
    if not todo:
        if failure is not None:
            raise JaxgeoError(f"no starting corridor: {failure}") from failure
        raise JaxgeoError("exact_geodesic needs a corridor or dijkstra=True")
    results, starts = [], []
    for c in todo:
        c = clean_corridor(check_corridor(topo, c).tolist(), start, end, topo)
        # On a surface without positive curvature the refinement's result depends
        # only on the corridor's homotopy class (which its moves keep): a corridor
        # homotopic to one already refined would end at the same geodesic.
        skip = topo.nonpositive and _homotopic_to_any(topo, c, starts, start, end)
        if c in starts or skip:
            continue
        results.append(_refine(topo, c, start, end, max_iter))
        starts.append(c)
    results.sort(key=lambda r: r[0].length)
    sol, faces, ok = results[0]
    if explore and ok:
        sol, faces = _explore(
            topo,
            sol,
            faces,
            start,
            end,
            max_iter,
            explore_radius * topo.mean_edge_length,
            explore_tries,
        )
    pts, kinds, elems, params = _polyline(topo, sol, start, end)
    return ExactPath(
        points=_f(pts),
        kinds=_i(kinds),
        elements=_i(elems),
        params=_f(params),
        length=_f(sol.length),
        faces=_i(faces),
        start_face=_i(start.face),
        start_bary=_f(start.bary),
        end_face=_i(end.face),
        end_bary=_f(end.bary),
        structure=_structure(topo, sol, start, end),
        converged=np.bool_(ok),
    )


# ------------------------------------------------------ differentiable length


@eqx.filter_jit
def _structure_length(
    vertices: Float[Array, "V 3"], st: PathStructure, coef: Float[Array, " 8"]
) -> Float[Array, ""]:
    v = vertices
    zero2 = jnp.zeros(2, dtype=v.dtype)

    # gathers outside the scan: inside it their transpose would scatter into a
    # (V, 3) cotangent at every step
    e = v[st.step_l] - v[st.step_r]
    qw = v[st.step_w] - v[st.step_r]
    qa = v[st.step_apex] - v[st.step_r]
    el = safe_norm(e)
    el_ = jnp.where(el > 0, el, 1.0)
    wx, wy = jnp.sum(e * qw, -1) / el_, safe_norm(jnp.cross(e, qw)) / el_
    ax, ay = jnp.sum(e * qa, -1) / el_, safe_norm(jnp.cross(e, qa)) / el_

    def step(carry, x):
        l2c, r2c = carry
        first, keep, el, wx, wy, ax, ay = x
        l2 = jnp.where(first, jnp.stack([jnp.zeros_like(el), el]), l2c)
        r2 = jnp.where(first, zero2, r2c)
        d = l2 - r2
        nd = safe_norm(d)
        dn = d / jnp.where(nd > 0, nd, 1.0)
        fwd = jnp.stack([dn[1], -dn[0]])
        w2 = r2 + wx * dn + wy * fwd
        a2 = r2 + ax * dn - ay * fwd
        nxt = (jnp.where(keep, l2, w2), jnp.where(keep, w2, r2))
        return nxt, (l2, r2, w2, a2)

    xs = (st.step_first, st.step_keep_left, el, wx, wy, ax, ay)
    _, (l2, r2, w2, a2) = jax.lax.scan(step, (zero2, zero2), xs)
    ca, cb = coef[st.a_src], coef[st.b_src]
    f, g = st.seg_first, st.seg_last
    pa = ca[:, :1] * l2[f] + ca[:, 1:2] * r2[f] + ca[:, 2:] * a2[f]
    pb = cb[:, :1] * l2[g] + cb[:, 1:2] * r2[g] + cb[:, 2:] * w2[g]
    a3 = jnp.einsum("sk,skd->sd", ca, v[st.a_vid])
    b3 = jnp.einsum("sk,skd->sd", cb, v[st.b_vid])
    seg = jnp.where(st.seg_has_steps, safe_norm(pb - pa), safe_norm(b3 - a3))
    return jnp.sum(jnp.where(st.seg_mask, seg, 0.0))


def exact_length(
    mesh: Mesh,
    path: ExactPath,
    start_bary: Float[ArrayLike, " 3"] | None = None,
    end_bary: Float[ArrayLike, " 3"] | None = None,
) -> Float[Array, ""]:
    """The length of `path`'s geodesic as a differentiable function of
    `mesh.vertices` and the endpoints' barycentric coordinates.

    The combinatorics (crossed edges, vertex contacts) stay those of `path`; the
    length is the sum of the planar distances between consecutive pinned points in
    the unfolding of the faces between them (see the module docstring for why the
    gradient is exact). Works under `jax.grad`, `jax.jit` and with tracers.

    **Arguments:**

    - `mesh`: the mesh, possibly `mesh.with_vertices(tracer)`.
    - `path`: an `ExactPath` from `exact_geodesic`.
    - `start_bary`, `end_bary`: barycentric coordinates of the endpoints in
      `path.start_face` / `path.end_face` (default: the path's own). They are
      divided by their sum. When an endpoint lies on an edge or vertex and the path
      leaves it through a neighbouring face, coordinates that are zero in the query
      do not enter (the one-sided derivative into the query face is not defined
      by the path).

    **Returns:** the length, a scalar.
    """
    sb = path.start_bary if start_bary is None else jnp.asarray(start_bary)
    eb = path.end_bary if end_bary is None else jnp.asarray(end_bary)
    dtype = mesh.vertices.dtype
    sb = sb.astype(dtype) / jnp.sum(sb)
    eb = eb.astype(dtype) / jnp.sum(eb)
    coef = jnp.concatenate([sb, eb, jnp.array([1.0, 0.0], dtype=dtype)])
    return _structure_length(mesh.vertices, path.structure, coef)
