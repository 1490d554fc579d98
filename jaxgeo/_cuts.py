"""A cut across every annulus of a mesh: the exact engine's homotopy classes.

Built once per mesh on the host (scipy). A connected component with Euler
characteristic 0 and a boundary is an annulus (a catenoid, a tent with one ring):
its paths between two points fall into classes by how many times they wind round
it, and a path's class is its signed count of crossings of a *cut*, an edge path
from one boundary loop to the other. The exact engine reads a start corridor's
class from the cut edges its portals cross (`jaxgeo.exact._winding`): on a
component with no cone vertex, two starts of one class reach the same locally
shortest path, so the later ones can stop.

`edge_cut[e]` is +1 where crossing edge e from face `edge_faces[e, 0]` to
`edge_faces[e, 1]` counts +1 (the cut runs along e with face 0 on its left), −1
the other way, and 0 off the cut (and on boundary edges, which no corridor
crosses).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra


def annulus_cuts(
    vertices: np.ndarray,
    faces: np.ndarray,
    edges: np.ndarray,
    edge_faces: np.ndarray,
    face_component: np.ndarray,
    vertex_component: np.ndarray,
) -> np.ndarray:
    """`edge_cut (E,)` int32 (see the module docstring); `vertex_component`: −1
    for a vertex in no face."""
    n_v, n_e = vertices.shape[0], edges.shape[0]
    cut = np.zeros(n_e, np.int32)
    on_boundary = edge_faces[:, 1] < 0
    if not on_boundary.any():
        return cut
    # boundary loops: components of the graph of boundary edges
    b = edges[on_boundary]
    graph = sp.coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n_v, n_v))
    _, loop = connected_components(graph, directed=False)
    n_c = int(face_component.max()) + 1
    edge_comp = face_component[edge_faces[:, 0]]
    used = vertex_component >= 0
    euler = (
        np.bincount(vertex_component[used], minlength=n_c)
        - np.bincount(edge_comp, minlength=n_c)
        + np.bincount(face_component, minlength=n_c)
    )
    # boundary loops per component: (component, loop) pairs of boundary edges
    loops = np.unique(np.c_[edge_comp[on_boundary], loop[b[:, 0]]], axis=0)
    n_loops = np.bincount(loops[:, 0], minlength=n_c)
    annuli = np.flatnonzero((euler == 0) & (n_loops == 2))
    if not annuli.size:
        return cut
    boundary_vertex = np.zeros(n_v, bool)
    boundary_vertex[b.reshape(-1)] = True
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    everything = sp.coo_matrix(
        (
            np.r_[lengths, lengths],
            (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]),
        ),
        shape=(n_v, n_v),
    ).tocsr()
    key = np.minimum(edges[:, 0], edges[:, 1]) * n_v + np.maximum(
        edges[:, 0], edges[:, 1]
    )
    order = np.argsort(key)
    for c in annuli:
        first, second = loops[loops[:, 0] == c, 1]
        source = np.flatnonzero(boundary_vertex & (loop == first))
        target = np.flatnonzero(boundary_vertex & (loop == second))
        dist, pred, _ = dijkstra(
            everything, indices=source, min_only=True, return_predecessors=True
        )
        path = [int(target[np.argmin(dist[target])])]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        u, w = np.array(path[:0:-1]), np.array(path[-2::-1])  # in path order
        e = order[
            np.searchsorted(key[order], np.minimum(u, w) * n_v + np.maximum(u, w))
        ]
        inner = edge_faces[e, 1] >= 0
        f = faces[edge_faces[e, 0]]
        # face 0 holds the directed edge u → w (counter-clockwise) where the cut
        # has it on its left
        k = np.argmax(f == u[:, None], axis=1)
        left = f[np.arange(len(e)), (k + 1) % 3] == w
        cut[e[inner]] = np.where(left, 1, -1)[inner]
    return cut
