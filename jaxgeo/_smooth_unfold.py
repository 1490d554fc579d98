"""Host-side (numpy) geometry of the eager strip repair
`jaxgeo.smooth.smooth_shortest_path`: a vertex's fan in order (read from the
mesh's fan tables, `jaxgeo._fans`), the two ways round it between two of its
faces, and where the straight line between a contact's neighbours crosses them
with the fan unfolded into the plane.
(`jaxgeo._smooth_repair` is the same repair as fixed-shape JAX.)"""

from __future__ import annotations

import numpy as np


def vertex_fan(mesh_np: dict, v: int) -> tuple[list[int], list[int], bool]:
    """Faces around vertex v in order, the edge between consecutive faces
    (`edges[j]` joins `faces[j]` and `faces[j + 1]`, cyclically when closed), and
    whether the fan is closed.

    Read from the mesh's fan tables (`Mesh.fan_faces`, `jaxgeo._fans`):
    counter-clockwise, an open fan from its boundary edge. Face j, with corners
    (v, a, b) in its own order, meets face j + 1 across its spoke (v, b): the edge
    opposite corner a."""
    n = int(mesh_np["fan_size"][v])
    closed = bool(mesh_np["fan_closed"][v])
    order = mesh_np["fan_faces"][v, :n]
    corner = np.argmax(mesh_np["faces"][order] == v, axis=1)
    between = mesh_np["face_edges"][order, (corner + 1) % 3]
    return order.tolist(), between[: n if closed else n - 1].tolist(), closed


def fan_arcs(fan, f_in: int, f_out: int) -> list[list[int]]:
    """The edge sequences leading around the vertex from face f_in to f_out, one per
    side (one when the fan is open)."""
    order, between, closed = fan
    if f_in not in order or f_out not in order:
        return []
    i, o, m = order.index(f_in), order.index(f_out), len(order)
    if not closed:
        return [between[i:o] if i <= o else between[o:i][::-1]]
    forward = [between[(i + j) % m] for j in range((o - i) % m)]
    backward = [between[(i - 1 - j) % m] for j in range((i - o) % m)]
    return [forward, backward]


#: Rounding tolerance on the unfolded segment's parameter λ ∈ [0, 1].
_UNFOLD_TOL = 1e-9


def unfolded_crossings(verts, faces, edges, v, arc, f_in, f_out, a, b):
    """Parameters where the segment a → b, unfolded into the plane with the faces
    of the fan of v from f_in across the edges `arc` to f_out, crosses those edges
    (0.02 from v where it misses)."""

    def other(e):
        return int(edges[e, 1] if edges[e, 0] == v else edges[e, 0])

    def corner(f, e1, e2):  # flat angle at v between edges e1, e2 of face f
        d1, d2 = verts[other(e1)] - verts[v], verts[other(e2)] - verts[v]
        return np.arctan2(np.linalg.norm(np.cross(d1, d2)), d1 @ d2)

    def face_edge(f, not_e):  # the edge at v of face f other than not_e
        w = [int(x) for x in faces[f] if x != v and x != other(not_e)][0]
        lo, hi = min(v, w), max(v, w)
        return int(np.flatnonzero((edges[:, 0] == lo) & (edges[:, 1] == hi))[0])

    def place(p, f, e_known, angle_known, sign):
        """2-D image of point p of face f, given edge e_known at angle_known; the
        face's other edge at v lies at angle_known + sign·corner."""
        e_other = face_edge(f, e_known)
        alpha = corner(f, e_known, e_other)
        d1 = verts[other(e_known)] - verts[v]
        d2 = verts[other(e_other)] - verts[v]
        st = np.linalg.lstsq(np.stack([d1, d2], 1), p - verts[v], rcond=None)[0]
        t1, t2 = angle_known, angle_known + sign * alpha
        return st[0] * np.linalg.norm(d1) * np.array([np.cos(t1), np.sin(t1)]) + st[
            1
        ] * np.linalg.norm(d2) * np.array([np.cos(t2), np.sin(t2)])

    angles = [0.0]
    faces_seq = [f_in]
    for k in range(1, len(arc)):
        shared = [
            f
            for f in set(np.flatnonzero((faces == v).any(1)).tolist())
            if set(faces[f].tolist()) >= {v, other(arc[k - 1]), other(arc[k])}
        ]
        faces_seq.append(shared[0])
        angles.append(angles[-1] + corner(shared[0], arc[k - 1], arc[k]))
    a2 = place(a, f_in, arc[0], 0.0, -1.0)
    b2 = place(b, f_out, arc[-1], angles[-1], 1.0)
    out = []
    for e, phi in zip(arc, angles):
        ray = np.array([np.cos(phi), np.sin(phi)])
        m = np.stack([b2 - a2, -ray], 1)
        try:
            lam, mu = np.linalg.solve(m, -a2)
        except np.linalg.LinAlgError:
            lam, mu = -1.0, -1.0
        length = np.linalg.norm(verts[other(e)] - verts[v])
        # closed segment, with rounding: when the next node is the far end of an
        # arc edge (two vertex contacts in a row) the line ends exactly on that
        # edge, at λ = 1 to rounding, and must count as crossing it there
        hit = -_UNFOLD_TOL < lam < 1 + _UNFOLD_TOL and mu > 0
        t = mu / length if hit else 0.02
        t = float(np.clip(t, 1e-3, 1 - 1e-3))
        out.append(t if edges[e, 0] == v else 1 - t)
    return out
