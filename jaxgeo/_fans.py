"""Vertex fans in rotational order: the tables the exact engine walks (host-side,
built once per mesh with numpy).

Around a vertex v of a consistently oriented manifold mesh the faces form one fan.
`fan_faces[v, k]` is the k-th face counter-clockwise (seen from the side the face
normals point to); face k has corners (v, a_k, b_k) in its own counter-clockwise
order and shares the *spoke* (v, b_k) = (v, a_{k+1}) with face k + 1. A boundary
vertex's fan is open: it starts at the face whose spoke a_0 is a boundary edge.

- `fan_spokes[v, k] = a_k` (and, for an open fan of n faces, `fan_spokes[v, n] =
  b_{n-1}`): spoke k lies between faces k − 1 and k.
- `corner_fan_pos[f, c]`: the position of face f in the fan of its corner c.
- For a boundary vertex (an open fan) face 0 runs v → a_0 along the boundary
  edge (v, a_0), so following `fan_spokes[v, 0]` from boundary vertex to
  boundary vertex walks each boundary loop the way the faces are oriented (the
  surface on the left, seen from the side the normals point to):
  `Mesh.boundary_next`.
"""

from __future__ import annotations

import numpy as np


def vertex_fans(
    faces: np.ndarray, edge_faces: np.ndarray, face_edges: np.ndarray, n_vertices: int
) -> dict[str, np.ndarray]:
    """`fan_faces (V, K)`, `fan_spokes (V, K + 1)` (−1 padded), `fan_size (V,)`,
    `fan_closed (V,)` and `corner_fan_pos (F, 3)` for a validated manifold mesh."""
    f = faces.astype(np.int64)
    n_faces = f.shape[0]
    corner_vertex = f.reshape(-1)

    def across(edge_slot: int) -> np.ndarray:
        """For every corner (f, c): the corner of the same vertex in the face
        across edge `face_edges[f, (c + edge_slot) % 3]`, or −1."""
        c = np.tile(np.arange(3), n_faces)
        fid = np.repeat(np.arange(n_faces), 3)
        e = face_edges[fid, (c + edge_slot) % 3]
        ef = edge_faces[e]
        g = np.where(ef[:, 0] == fid, ef[:, 1], ef[:, 0])
        ok = g >= 0
        gc = np.argmax(f[np.maximum(g, 0)] == corner_vertex[:, None], axis=1)
        return np.where(ok, 3 * g + gc, -1)

    # next counter-clockwise face: across spoke (v, b) = the edge opposite a
    nxt = across(1)
    prv = across(2)
    # fan start: a corner with no predecessor (boundary), else the vertex's first
    n_corners = 3 * n_faces
    order = np.argsort(corner_vertex, kind="stable")
    valence = np.bincount(corner_vertex, minlength=n_vertices)
    first = np.full(n_vertices, -1, np.int64)
    has = valence > 0
    starts = np.concatenate([[0], np.cumsum(valence)[:-1]])
    first[has] = order[starts[has]]
    open_start = np.full(n_vertices, -1, np.int64)
    boundary_corners = np.flatnonzero(prv < 0)
    open_start[corner_vertex[boundary_corners]] = boundary_corners
    start = np.where(open_start >= 0, open_start, first)
    closed = has & (open_start < 0)

    width = max(int(valence.max()), 1)
    fan_c = np.full((n_vertices, width), -1, np.int64)
    cur = start.copy()
    for k in range(width):
        live = cur >= 0
        fan_c[live, k] = cur[live]
        step = np.where(live, nxt[np.maximum(cur, 0)], -1)
        step[step == start] = -1  # closed fan: back at the start
        cur = step
    size = (fan_c >= 0).sum(axis=1)
    if (size != valence).any():  # cannot happen for a validated manifold mesh
        raise AssertionError("vertex fan walk did not cover every face")

    fan_faces = np.where(fan_c >= 0, fan_c // 3, -1)
    flat = f.reshape(-1)

    def corner_after(c: np.ndarray, step: int) -> np.ndarray:
        """The vertex `step` corners after corner id `c` in its face."""
        return flat[(c // 3) * 3 + (c % 3 + step) % 3]

    a = np.where(fan_c >= 0, corner_after(np.maximum(fan_c, 0), 1), -1)
    spokes = np.full((n_vertices, width + 1), -1, np.int64)
    spokes[:, :width] = a
    last = np.maximum(size - 1, 0)
    last_c = fan_c[np.arange(n_vertices), last]
    b_last = corner_after(np.maximum(last_c, 0), 2)
    is_open = has & ~closed
    spokes[np.flatnonzero(is_open), size[is_open]] = b_last[is_open]

    corner_pos = np.zeros(n_corners, np.int64)
    live = fan_c >= 0
    corner_pos[fan_c[live]] = np.nonzero(live)[1]
    return {
        "fan_faces": fan_faces.astype(np.int32),
        "fan_spokes": spokes.astype(np.int32),
        "fan_size": size.astype(np.int32),
        "fan_closed": closed,
        "corner_fan_pos": corner_pos.reshape(n_faces, 3).astype(np.int32),
    }
