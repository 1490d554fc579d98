"""Landmark shortest-path forests: where the exact engine's starts come from.

Built once per mesh on the host (scipy's Dijkstra). The graph has a node at every
vertex and at the midpoint of every edge (a Steiner point), joined by straight
segments that lie in the surface: the mesh edges, and in every face its three
midlines and its three medians' halves (corner to the opposite edge's midpoint).
A vertex-only graph path on a regular mesh zigzags and can run many rows away from
the geodesic (the shortest edge paths of a lattice fill a parallelogram), and the
flip loop then creeps across those rows one per round; paths through midpoints
bend less and stay within about a row of it (`docs/accuracy.md`, "Starts").

Nodes are numbered 2·v for vertex v and 2·e + 1 for the midpoint of edge e, so the
numbering does not depend on the vertex count and survives the padding of a mesh
to its size class (`jaxgeo._padding`).

Slot j holds one landmark per connected component, chosen by farthest point
sampling over the vertices (slot 0: the vertex nearest each component's centroid;
slot j: the vertex farthest from the landmarks of slots < j), and the shortest-path
forest of those landmarks: `pred_vertex[j, v]` / `pred_edge[j, e]` is the node one
step towards the landmark (−1 at the landmark and where unreachable),
`dist_vertex[j, v]` the graph distance to it (inf where unreachable).

A query (s, t) then reads a graph path through landmark ℓ with no search: walk s
and t up the forest of ℓ's slot to their lowest common ancestor. Its length
`dist[j, s] + dist[j, t]` (an upper bound of the path's) ranks the slots; the
engine refines the best few as parallel lanes (`jaxgeo.exact`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

#: Landmark slots per mesh (memory: 8 bytes per vertex and slot, 4 per edge).
DEFAULT_LANDMARKS = 32


def vertex_node(v):
    """Graph node of vertex v."""
    return 2 * v


def edge_node(e):
    """Graph node of the midpoint of edge e."""
    return 2 * e + 1


def steiner_graph(
    vertices: np.ndarray, faces: np.ndarray, edges: np.ndarray, face_edges: np.ndarray
) -> sp.csr_matrix:
    """The graph of the module docstring, on nodes 0 … V − 1 (vertices) and
    V … V + E − 1 (edge midpoints), weighted by Euclidean length."""
    n_v = vertices.shape[0]
    v = vertices.astype(np.float64)
    mid = (v[edges[:, 0]] + v[edges[:, 1]]) / 2
    corner = faces.reshape(-1)  # corner c of face f: faces[f, c]
    opposite = face_edges.reshape(-1)  # the edge opposite it
    e0, e1, e2 = face_edges[:, 0], face_edges[:, 1], face_edges[:, 2]
    a = np.concatenate([edges[:, 0], corner, n_v + e0, n_v + e1, n_v + e2])
    b = np.concatenate([edges[:, 1], n_v + opposite, n_v + e1, n_v + e2, n_v + e0])
    pos = np.concatenate([v, mid])
    w = np.linalg.norm(pos[a] - pos[b], axis=1)
    n = n_v + edges.shape[0]
    return sp.coo_matrix(
        (np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(n, n)
    ).tocsr()


def landmark_forests(
    vertices: np.ndarray,
    faces: np.ndarray,
    edges: np.ndarray,
    face_edges: np.ndarray,
    vertex_component: np.ndarray,
    n_slots: int = DEFAULT_LANDMARKS,
) -> dict[str, np.ndarray]:
    """`pred_vertex (M, V)`, `pred_edge (M, E)` int32 (parent nodes, −1 at a
    landmark and where unreachable) and `dist_vertex (M, V)` float32."""
    n_v, n_e = vertices.shape[0], edges.shape[0]
    graph = steiner_graph(vertices, faces, edges, face_edges)
    v = vertices.astype(np.float64)
    used = vertex_component >= 0
    comps = np.unique(vertex_component[used])
    # slot 0: per component, the vertex nearest the component's centroid
    centroid = np.zeros((comps.max() + 1 if comps.size else 1, 3))
    counts = np.bincount(vertex_component[used], minlength=centroid.shape[0])
    for d in range(3):
        centroid[:, d] = np.bincount(
            vertex_component[used], v[used, d], minlength=centroid.shape[0]
        ) / np.maximum(counts, 1)
    score = np.where(
        used,
        -np.linalg.norm(v - centroid[np.maximum(vertex_component, 0)], axis=1),
        -np.inf,
    )
    # scipy's node k → our node number (2·v, 2·e + 1)
    ours = np.r_[2 * np.arange(n_v), 2 * np.arange(n_e) + 1]
    nearest = np.full(n_v, np.inf)
    pred_vertex = np.full((n_slots, n_v), -1, np.int32)
    pred_edge = np.full((n_slots, n_e), -1, np.int32)
    dist = np.full((n_slots, n_v), np.inf, np.float32)
    for j in range(n_slots):
        sources = _best_per_component(score, vertex_component, comps)
        d, pred, _ = dijkstra(
            graph, indices=sources, return_predecessors=True, min_only=True
        )
        parent = np.where(pred >= 0, ours[np.maximum(pred, 0)], -1)
        pred_vertex[j], pred_edge[j] = parent[:n_v], parent[n_v:]
        dist[j] = d[:n_v]
        nearest = np.minimum(nearest, d[:n_v])
        score = np.where(used & np.isfinite(nearest), nearest, -np.inf)
    return {"pred_vertex": pred_vertex, "pred_edge": pred_edge, "dist_vertex": dist}


def _best_per_component(
    score: np.ndarray, component: np.ndarray, comps: np.ndarray
) -> np.ndarray:
    """The vertex of highest score in each component."""
    order = np.lexsort((-score, component))
    comp_sorted = component[order]
    first = np.searchsorted(comp_sorted, comps, side="left")
    return order[first]
