"""Landmark shortest-path forests: where the exact engine's starts come from.

Built once per mesh on the host (scipy's Dijkstra on the edge graph, lengths = edge
lengths). Slot j holds one landmark per connected component, chosen by farthest
point sampling (slot 0: the vertex nearest each component's centroid; slot j: the
vertex farthest from the landmarks of slots < j), and the shortest-path forest of
those landmarks: `pred_spoke[j, v]` is the spoke of v (`fan_spokes[v, k]`) that
leads one edge towards the landmark, `dist[j, v]` the graph distance to it.

A query (s, t) then reads a graph path through landmark ℓ with no search: walk s
and t up the forest of ℓ's slot to their lowest common ancestor. Its length
`dist[j, s] + dist[j, t]` (an upper bound of the path's) ranks the slots; the
engine refines the best few as parallel lanes (`jaxgeo.exact`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

#: Landmark slots per mesh (memory: 12 bytes per vertex and slot).
DEFAULT_LANDMARKS = 32


def landmark_forests(
    vertices: np.ndarray,
    edges: np.ndarray,
    fan_spokes: np.ndarray,
    vertex_component: np.ndarray,
    n_slots: int = DEFAULT_LANDMARKS,
) -> dict[str, np.ndarray]:
    """`pred_spoke (M, V)` int32 (−1 at the landmark and at unused vertices),
    `dist (M, V)` float32 and `root (M, V)` int32 (−1 where unreachable)."""
    n = vertices.shape[0]
    v = vertices.astype(np.float64)
    w = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    graph = sp.coo_matrix(
        (
            np.concatenate([w, w]),
            (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]),
        ),
        shape=(n, n),
    ).tocsr()
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
    nearest = np.full(n, np.inf)
    pred_spoke = np.full((n_slots, n), -1, np.int32)
    dist = np.full((n_slots, n), np.inf, np.float32)
    root = np.full((n_slots, n), -1, np.int32)
    for j in range(n_slots):
        sources = _best_per_component(score, vertex_component, comps)
        d, pred, src = dijkstra(
            graph, indices=sources, return_predecessors=True, min_only=True
        )
        reach = np.isfinite(d)
        dist[j] = np.where(reach, d, np.inf)
        root[j] = np.where(reach, src, -1)
        has_pred = pred >= 0
        spoke = np.argmax(fan_spokes == pred[:, None], axis=1)
        pred_spoke[j] = np.where(has_pred, spoke, -1)
        nearest = np.minimum(nearest, d)
        score = np.where(used & np.isfinite(nearest), nearest, -np.inf)
    return {"pred_spoke": pred_spoke, "dist": dist, "root": root}


def _best_per_component(
    score: np.ndarray, component: np.ndarray, comps: np.ndarray
) -> np.ndarray:
    """The vertex of highest score in each component."""
    order = np.lexsort((-score, component))
    comp_sorted = component[order]
    first = np.searchsorted(comp_sorted, comps, side="left")
    return order[first]
