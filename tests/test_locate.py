"""Endpoints: locating 3-D points on the mesh and the errors for bad endpoints."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo.locate import snap

from .helpers import unit_icosphere

MESH = unit_icosphere(2)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_locate_recovers_face_and_barycentrics():
    rng = np.random.default_rng(0)
    v, f = np.asarray(MESH.vertices), np.asarray(MESH.faces)
    for face in rng.integers(0, MESH.n_faces, 10):
        bary = rng.dirichlet([2, 2, 2])
        p = bary @ v[f[face]]
        sp, dist = jg.locate(MESH, jnp.asarray(p))
        assert int(sp.face) == face
        np.testing.assert_allclose(sp.bary, bary, atol=1e-12)
        assert float(dist) < 1e-12


@pytest.mark.slow
def test_locate_equals_brute_force_near_and_far_under_vmap():
    """The pruned search (bounding spheres) and its full-search fallback find the
    brute-force nearest distance, on a face that realises it (faces tied to
    rounding, e.g. around a vertex, may differ). Points on vertices, near the
    surface and far off it share one vmap; the centre is equally far from every
    face, so it takes the full-search fallback."""
    import jax

    from jaxgeo.locate import _nearest_of

    mesh = unit_icosphere(3)  # 1,280 faces: above the size searched in full
    rng = np.random.default_rng(1)
    v = np.asarray(mesh.vertices)
    near = v[rng.integers(len(v), size=20)] * rng.uniform(0.97, 1.03, (20, 1))
    far = rng.normal(scale=3.0, size=(10, 3))
    pts = jnp.asarray(np.concatenate([v[:10], near, far, np.zeros((1, 3))]))
    tri = mesh.vertices[mesh.faces]
    got, dist = jax.vmap(lambda p: jg.locate(mesh, p))(pts)
    per_face = jax.vmap(
        lambda p: jax.vmap(lambda f: _nearest_of(p, tri, f[None])[2])(
            jnp.arange(mesh.n_faces, dtype=mesh.faces.dtype)
        )
    )(pts)
    best = np.sqrt(np.min(per_face, axis=1))
    # Distances are O(1): rounding of the closest-point formulas is a few 1e-16.
    np.testing.assert_allclose(dist, best, rtol=0, atol=1e-14)
    chosen = np.sqrt(np.asarray(per_face)[np.arange(len(pts)), np.asarray(got.face)])
    np.testing.assert_allclose(chosen, best, rtol=0, atol=1e-14)


def test_points_on_vertices_and_edges_snap():
    v, f = np.asarray(MESH.vertices), np.asarray(MESH.faces)
    sp, _ = jg.locate(MESH, jnp.asarray(v[f[3, 1]]))
    kind, idx = snap(MESH, sp, 1e-9)
    assert (int(kind), int(idx)) == (2, f[3, 1])
    mid = 0.5 * (v[f[3, 0]] + v[f[3, 2]])
    sp, _ = jg.locate(MESH, jnp.asarray(mid))
    kind, idx = snap(MESH, sp, 1e-9)
    assert int(kind) == 1
    assert set(np.asarray(MESH.edges)[int(idx)]) == {f[3, 0], f[3, 2]}


def test_surface_points_on_edges_and_vertices():
    """`SurfacePoint.on_edge(mesh, e, t)` is the point at `t` along edge `e` in a
    face beside it (`snap` finds the edge again, or its vertex at t = 0 or 1),
    also vmapped over traced edges; `vertex` is the vertex; out of range: NaN."""
    import jax

    v, edges = np.asarray(MESH.vertices), np.asarray(MESH.edges)
    ts = np.array([0.25, 0.0, 1.0, 0.7])
    es = np.array([5, 17, 17, len(edges) - 1])
    pts = jax.vmap(lambda e, t: jg.SurfacePoint.on_edge(MESH, e, t))(es, ts)
    want = (1 - ts[:, None]) * v[edges[es, 0]] + ts[:, None] * v[edges[es, 1]]
    np.testing.assert_allclose(pts.position(MESH), want, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.sum(pts.bary, axis=1), 1.0, rtol=1e-15)
    assert (np.asarray(MESH.edge_faces)[es, 0] == np.asarray(pts.face)).all()
    kinds, idx = jax.vmap(lambda sp: snap(MESH, sp, 1e-9))(pts)
    assert np.asarray(kinds).tolist() == [1, 2, 2, 1]
    assert np.asarray(idx).tolist() == [5, edges[17, 0], edges[17, 1], len(edges) - 1]
    at = jg.SurfacePoint.vertex(MESH, 9)
    np.testing.assert_allclose(at.position(MESH), v[9], rtol=0, atol=1e-15)
    assert np.isnan(
        np.asarray(jg.SurfacePoint.on_edge(MESH, len(edges), 0.5).bary)
    ).all()


@pytest.mark.slow  # 16 s niced beside CI: among the fast set's longest (12-08)
def test_path_from_a_vertex_to_an_edge_point():
    v, f = np.asarray(MESH.vertices), np.asarray(MESH.faces)
    a = v[f[0, 0]]
    b = 0.5 * (v[f[200, 1]] + v[f[200, 2]])
    path = jg.shortest_path(MESH, a, b)
    assert int(path.status) == jg.Status.SUCCESS
    np.testing.assert_allclose(path.polyline()[[0, -1]], [a, b], atol=1e-12)
    # the path carries its endpoints: where it starts and ends, in its end faces
    assert path.start is not None and path.end is not None
    ends = [path.start.position(MESH), path.end.position(MESH)]
    np.testing.assert_allclose(ends, path.polyline()[[0, -1]], atol=1e-12)
    elements = np.asarray(path.elements)[[0, int(path.count) - 1]]
    assert [int(path.start.face), int(path.end.face)] == elements.tolist()
    for sp in (path.start, path.end):
        bary = np.asarray(sp.bary)
        assert bary.shape == (3,) and (bary >= -1e-12).all()
        assert abs(bary.sum() - 1) <= 1e-12
    # a: a corner of its face; b: on a side (one coordinate 0, two ½)
    np.testing.assert_allclose(np.sort(path.start.bary), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.sort(path.end.bary), [0, 0.5, 0.5], atol=1e-12)


def test_far_point_raises_and_names_the_distance():
    with pytest.raises(jg.JaxgeoError, match="too far from the surface"):
        jg.shortest_path(MESH, np.array([0.0, 0.0, 3.0]), np.array([1.0, 0, 0]))


@pytest.mark.slow
def test_far_point_under_jit_is_a_status():
    import jax

    lengths_status = jax.jit(
        lambda a, b: jg.shortest_path(MESH, a, b, throw=False).status
    )(jnp.array([0.0, 0.0, 3.0]), jnp.array([1.0, 0, 0]))
    assert int(lengths_status) == jg.Status.FAR_FROM_SURFACE


@pytest.mark.slow  # a mesh of its own (two spheres): compiles
def test_points_on_different_components_raise():
    v, f = np.asarray(MESH.vertices), np.asarray(MESH.faces)
    two = jg.Mesh(np.vstack([v, v + [5.0, 0, 0]]), np.vstack([f, f + len(v)]))
    with pytest.raises(jg.JaxgeoError, match="different connected components"):
        jg.shortest_path(two, v[0], v[0] + [5.0, 0, 0])


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.array([0.0, 1.0]), r"shape \(3,\)"),
        (np.array([np.nan, 0.0, 1.0]), "NaN"),
        (np.array(["a", "b", "c"]), "dtype"),
    ],
)
def test_bad_endpoints_raise(bad, message):
    with pytest.raises(jg.JaxgeoError, match=message):
        jg.shortest_path(MESH, bad, np.array([1.0, 0, 0]))


def test_bad_surface_point_raises():
    with pytest.raises(jg.JaxgeoError, match="out of range"):
        jg.shortest_path(
            MESH, jg.SurfacePoint(10**6, np.ones(3) / 3), np.array([1.0, 0, 0])
        )
    with pytest.raises(jg.JaxgeoError, match="sum to 1"):
        jg.shortest_path(
            MESH, jg.SurfacePoint(0, np.array([0.5, 0.5, 0.5])), np.array([1.0, 0, 0])
        )


@pytest.mark.mistyped
def test_mesh_argument_must_be_a_mesh():
    with pytest.raises(jg.JaxgeoError, match="jaxgeo.Mesh"):
        jg.shortest_path(np.zeros((3, 3)), np.zeros(3), np.zeros(3))


def test_element_reads_vertex_edge_and_face_points():
    """`SurfacePoint.element` is the tagged reading (geometry-central's vertex,
    edge + t, face): the inverse of `vertex` and `on_edge` (t exactly, in
    `mesh.edges` orientation; t = 0 or 1 is the vertex), the face otherwise;
    batched, under `jax.jit` and under `jax.vmap` alike."""
    import jax

    from jaxgeo.locate import EDGE, FACE, VERTEX

    edges = np.asarray(MESH.edges)
    es = np.array([5, 17, 17, 40, len(edges) - 1])
    ts = np.array([0.25, 0.0, 1.0, 1e-13, 0.7])
    on_edges = jax.vmap(lambda e, t: jg.SurfacePoint.on_edge(MESH, e, t))(es, ts)
    vertices = jax.vmap(lambda i: jg.SurfacePoint.vertex(MESH, i))(np.arange(4))
    inside = jg.SurfacePoint(jnp.array([7, 30]), jnp.array([[0.2, 0.3, 0.5]] * 2))
    # one batch of all three (one compile each under jit and vmap)
    groups = (on_edges, vertices, inside)
    sp = jg.SurfacePoint(
        jnp.concatenate([jnp.asarray(g.face, jnp.int32) for g in groups]),
        jnp.concatenate([jnp.asarray(g.bary) for g in groups]),
    )
    want_kind = [EDGE, VERTEX, VERTEX, EDGE, EDGE] + [VERTEX] * 4 + [FACE] * 2
    want_index = [5, edges[17, 0], edges[17, 1], 40, len(edges) - 1, 0, 1, 2, 3, 7, 30]
    # exact: on_edge stores t and 1 - t, and (1 - t) + t is 1 in floats
    want_t = [0.25, 0, 0, 1e-13, 0.7] + [0] * 6
    readings = [
        sp.element(MESH),  # batched as it is
        jax.jit(lambda p: p.element(MESH))(sp),
        jax.vmap(lambda p: p.element(MESH))(sp),
    ]
    for kind, index, t in readings:
        assert np.asarray(kind).tolist() == want_kind
        assert np.asarray(index).tolist() == want_index
        assert np.asarray(t).tolist() == want_t
    # a tolerance: a point a hair off an edge reads as the edge, its t the share
    bary = on_edges.bary[0]
    off = jg.SurfacePoint(on_edges.face[0], bary * (1 - 1e-10) + 1e-10 * (bary == 0))
    kind, index, t = off.element(MESH, tol=1e-9)
    assert (int(kind), int(index)) == (EDGE, 5) and abs(float(t) - 0.25) < 1e-15
    assert int(off.element(MESH)[0]) == FACE


@pytest.mark.slow  # 22 + 9 s cold on 2 cores (README tests <= 5 min)
@pytest.mark.parametrize("method", ["exact", "laser"])
def test_path_nodes_as_surface_points(method):
    """`Path.surface_points`: every node as a `SurfacePoint` at `points` (past
    `count`, the last node, as `points`); its `element` reading gives back the
    crossings' and vertices' `(kinds, elements, params)` exactly, and the
    endpoints' elements; under `jax.jit` and on a batch of rows alike."""
    import jax

    from jaxgeo.locate import FACE

    v, f = np.asarray(MESH.vertices), np.asarray(MESH.faces)
    b = 0.5 * (v[f[200, 1]] + v[f[200, 2]])
    p1 = jg.shortest_path(MESH, v[f[0, 0]], b, method=method)
    p2 = jg.shortest_path(MESH, 3, 150, method=method)
    for path in (p1, p2):
        assert path.outcome == jg.Status.SUCCESS
        sp = path.surface_points(MESH)
        assert np.shape(sp.face) == np.shape(path.kinds)
        np.testing.assert_allclose(sp.position(MESH), path.points, rtol=0, atol=1e-14)
        kind, index, t = sp.element(MESH)
        inner = np.asarray(path.kinds) != FACE
        inner[int(path.count) :] = False
        assert (np.asarray(kind)[inner] == np.asarray(path.kinds)[inner]).all()
        assert (np.asarray(index)[inner] == np.asarray(path.elements)[inner]).all()
        assert (np.asarray(t)[inner] == np.asarray(path.params)[inner]).all()
        ends = [path.start, path.end]
        assert path.start is not None and path.end is not None
        want = [snap(MESH, e, 0.0) for e in ends]
        got = np.asarray(jnp.stack([kind, index]))[:, [0, int(path.count) - 1]]
        assert got.T.tolist() == [[int(k), int(i)] for k, i in want]
        jitted = jax.jit(lambda p: p.surface_points(MESH))(path)
        assert (np.asarray(jitted.face) == np.asarray(sp.face)).all()
        np.testing.assert_array_equal(jitted.bary, sp.bary)
    batch = jax.tree.map(lambda *x: jnp.stack(x), p1, p2)
    rows = batch.surface_points(MESH)
    for r, path in enumerate((p1, p2)):
        one = path.surface_points(MESH)
        np.testing.assert_array_equal(rows.face[r], one.face)
        np.testing.assert_array_equal(rows.bary[r], one.bary)


def test_a_vertex_index_endpoint_is_its_vertex_surface_point():
    """`shortest_path` turns a concrete vertex index into a point in numpy
    (`_checks.as_endpoint`, no dispatch): the face, coordinates and dtype of
    `SurfacePoint.vertex`, for every vertex, in float64 and float32."""
    import jax

    from jaxgeo._checks import as_endpoint

    for mesh in (MESH, jg.Mesh(np.asarray(MESH.vertices, np.float32), MESH.faces)):
        ids = np.arange(mesh.n_vertices)
        want = jax.vmap(lambda i, m=mesh: jg.SurfacePoint.vertex(m, i))(ids)
        got = [as_endpoint(int(i), mesh) for i in ids]
        assert [int(p.face) for p in got] == np.asarray(want.face).tolist()
        bary = np.stack([p.bary for p in got])
        assert bary.dtype == mesh.vertices.dtype
        np.testing.assert_array_equal(bary, want.bary)
