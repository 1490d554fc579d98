"""The landmark forests on the graph of vertices and edge midpoints
(`jaxgeo._landmarks`), checked with numpy only (no compile).

Tolerance: graph distances are sums of float64 segment lengths stored as float32,
so they agree to float32 rounding (rtol 1e-6)."""

from __future__ import annotations

import numpy as np
import scipy.sparse.csgraph as csgraph

import jaxgeo as jg
from jaxgeo import _landmarks, surfaces


def test_forest_parents_are_graph_neighbours_one_step_nearer():
    mesh = jg.Mesh(*surfaces.catenoid(n_around=12, n_height=6), landmarks=4)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    edges, face_edges = np.asarray(mesh.edges), np.asarray(mesh.face_edges)
    graph = _landmarks.steiner_graph(v, f, edges, face_edges)
    n_v = v.shape[0]
    # nodes 2·v / 2·e + 1 → the graph's numbering (vertices, then midpoints)
    parent_v = np.asarray(mesh.landmark_pred_vertex)
    parent_e = np.asarray(mesh.landmark_pred_edge)
    dist_v = np.asarray(mesh.landmark_dist)

    def index(node):
        return np.where(node % 2 == 0, node // 2, n_v + node // 2)

    for j in range(parent_v.shape[0]):
        parents = np.r_[parent_v[j], parent_e[j]]
        roots = np.flatnonzero(parents < 0)
        assert len(roots) == 1  # one component, one landmark per slot
        assert roots[0] < n_v  # landmarks are vertices
        d = csgraph.dijkstra(graph, indices=roots[0])
        np.testing.assert_allclose(dist_v[j], d[:n_v], rtol=1e-6)
        child = np.flatnonzero(parents >= 0)
        par = index(parents[child])
        w = np.asarray(graph[child, par]).ravel()
        assert np.all(w > 0)  # every parent is a neighbour in the graph
        np.testing.assert_allclose(
            d[child], d[par] + w, rtol=1e-9
        )  # on a shortest path


def test_midpoint_graph_paths_are_shorter_than_edge_paths():
    """The reason for the midpoints: on a regular mesh, graph distances through
    them are closer to the geodesic distance than edge-graph distances."""
    mesh = jg.Mesh(*surfaces.catenoid(n_around=24, n_height=12), landmarks=1)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    edges, face_edges = np.asarray(mesh.edges), np.asarray(mesh.face_edges)
    full = _landmarks.steiner_graph(v, f, edges, face_edges)
    n_v = v.shape[0]
    edge_only = full[:n_v, :n_v]
    src = np.arange(0, n_v, 37)
    d_full = csgraph.dijkstra(full, indices=src)[:, :n_v]
    d_edge = csgraph.dijkstra(edge_only, indices=src)
    far = d_edge > 0
    assert np.all(d_full <= d_edge * (1 + 1e-12))
    assert np.mean(d_full[far] < d_edge[far] * (1 - 1e-3)) > 0.5
