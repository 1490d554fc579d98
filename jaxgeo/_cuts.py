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

**Systole.** `annulus_systoles` bounds from below the length of every closed
curve that winds round an annulus (its *systole*, the shortest such curve): such
a curve meets every edge path from one boundary loop to the other (the annulus
cut along one is a disc, where the curve would be contractible). Of K such
paths (`SYSTOLE_CUTS`, from vertices spread along one loop, each the graph's
shortest path to the other loop), the curve meets every one: taken in their
order along it, one point of each makes a closed polygon through the K sets,
whose legs are no longer than the curve between them (a chord is no longer than
a surface path) and at least the sets' Euclidean distances. That cycle is a
spanning tree of the sets and one more leg: at least the minimum spanning tree
of their distances plus the least distance. The exact engine reads it
(`jaxgeo.exact`, "Certificate"): a path of another winding from s to t closes
with the converged path L* into such a curve, so it is at least systole − L*,
and where 2 L* ≤ the bound no other winding can be shorter.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra, minimum_spanning_tree
from scipy.spatial import cKDTree

#: Edge paths across an annulus whose Euclidean distances bound its systole
#: (`annulus_systoles`).
SYSTOLE_CUTS = 8


Annulus = tuple[int, np.ndarray, np.ndarray]


def annuli(
    edges: np.ndarray,
    edge_faces: np.ndarray,
    face_component: np.ndarray,
    vertex_component: np.ndarray,
) -> list[Annulus]:
    """The annuli of a mesh: (component, vertices of one boundary loop, of the
    other) per component of Euler characteristic 0 with two boundary loops;
    `vertex_component`: −1 for a vertex in no face."""
    n_v = vertex_component.shape[0]
    on_boundary = edge_faces[:, 1] < 0
    if not on_boundary.any():
        return []
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
    boundary_vertex = np.zeros(n_v, bool)
    boundary_vertex[b.reshape(-1)] = True
    out = []
    for c in np.flatnonzero((euler == 0) & (n_loops == 2)):
        first, second = loops[loops[:, 0] == c, 1]
        out.append(
            (
                int(c),
                np.flatnonzero(boundary_vertex & (loop == first)),
                np.flatnonzero(boundary_vertex & (loop == second)),
            )
        )
    return out


def _edge_graph(vertices, edges):
    """The mesh's edges as a symmetric sparse graph weighted by their lengths."""
    n_v = vertices.shape[0]
    lengths = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    return sp.coo_matrix(
        (
            np.r_[lengths, lengths],
            (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]),
        ),
        shape=(n_v, n_v),
    ).tocsr()


def _trace(pred, v: int) -> np.ndarray:
    """The vertices of a shortest-path tree's path from `v` to its root."""
    path = [v]
    while pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    return np.array(path)


def annulus_cuts(
    vertices: np.ndarray,
    faces: np.ndarray,
    edges: np.ndarray,
    edge_faces: np.ndarray,
    rings: list[Annulus],
) -> np.ndarray:
    """`edge_cut (E,)` int32 (see the module docstring) of the annuli `rings`
    (`annuli`)."""
    n_v, n_e = vertices.shape[0], edges.shape[0]
    cut = np.zeros(n_e, np.int32)
    if not rings:
        return cut
    everything = _edge_graph(vertices, edges)
    key = np.minimum(edges[:, 0], edges[:, 1]) * n_v + np.maximum(
        edges[:, 0], edges[:, 1]
    )
    order = np.argsort(key)
    for _, source, target in rings:
        dist, pred, _ = dijkstra(
            everything, indices=source, min_only=True, return_predecessors=True
        )
        path = _trace(pred, int(target[np.argmin(dist[target])]))
        u, w = path[:0:-1], path[-2::-1]  # in path order
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


def _spread(points: np.ndarray, k: int) -> np.ndarray:
    """Indices of k of `points` far apart (farthest-point sampling)."""
    chosen = [0]
    gap = np.linalg.norm(points - points[0], axis=1)
    for _ in range(1, k):
        chosen.append(int(np.argmax(gap)))
        gap = np.minimum(gap, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return np.array(chosen)


def annulus_systoles(
    vertices: np.ndarray, edges: np.ndarray, rings: list[Annulus], n_labels: int
) -> np.ndarray:
    """Per component label (`(n_labels,)`, F as `face_component`'s), a lower
    bound of the length of every closed curve winding round the component where
    it is one of the annuli `rings` (`annuli`; see the module docstring), 0
    elsewhere.

    K = `SYSTOLE_CUTS` edge paths join the two boundary loops: the graph's
    shortest paths from K vertices spread along the shorter loop to the longer
    one (they spread outwards rather than merge). Of two paths with vertex sets
    P_i, P_j and longest edges h_i, h_j, every point is within h/2 of a vertex,
    so the sets are at least D_ij = min |P_i − P_j| − (h_i + h_j)/2 apart. A
    closed walk through all K sets has at least K legs, each between two sets,
    among them a spanning tree: it is at least MST(D) + min D. Paths of the
    graph may merge (ties of its distances), and any subset of them bounds the
    walk too: the bound is the best subset's."""
    bound = np.zeros(n_labels, vertices.dtype)
    if not rings:
        return bound
    everything = _edge_graph(vertices, edges)
    for c, one, other in rings:
        extent = [np.ptp(vertices[x], axis=0).sum() for x in (one, other)]
        short, long_ = (one, other) if extent[0] <= extent[1] else (other, one)
        k = min(SYSTOLE_CUTS, len(short))
        if k < 2:
            continue
        _, pred, _ = dijkstra(
            everything, indices=long_, min_only=True, return_predecessors=True
        )
        paths = [_trace(pred, int(v)) for v in short[_spread(vertices[short], k)]]
        reach = [
            np.linalg.norm(np.diff(vertices[q], axis=0), axis=1).max(initial=0.0)
            for q in paths
        ]
        trees = [cKDTree(vertices[q]) for q in paths]
        gap = np.zeros((k, k))
        for i in range(k):
            for j in range(i + 1, k):
                near = trees[j].query(vertices[paths[i]])[0].min()
                gap[i, j] = max(near - (reach[i] + reach[j]) / 2, 0.0)
        bound[c] = max(
            _walk_bound(gap[np.ix_(sub, sub)])
            for size in range(2, k + 1)
            for sub in itertools.combinations(range(k), size)
        )
    return bound


def _walk_bound(gap: np.ndarray) -> float:
    """A lower bound of a closed walk through n sets at distances `gap` (upper
    triangle): at least n legs, among them a spanning tree, MST + least gap."""
    least = gap[np.triu_indices(len(gap), 1)].min()
    # (zero gaps are no edges to scipy: floored, its tree is the true one)
    tiny = np.finfo(float).tiny
    return float(minimum_spanning_tree(np.triu(np.maximum(gap, tiny), 1)).sum() + least)
