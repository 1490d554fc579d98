"""Size classes (`jaxgeo._padding`): the solvers take a mesh padded to one of a few
shapes, so a new mesh of a compiled class does not compile again; the padding is
inert (same paths, same element indices, same gradients as the real mesh)."""

from __future__ import annotations

import dataclasses
import functools
import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

import jaxgeo as jg
from jaxgeo._numerics import corner_angles
from jaxgeo._padding import RULES, SizeClass, size_class
from jaxgeo.batch import _solve_chunk
from jaxgeo.geodesic import _solve_one
from jaxgeo.locate import DEFAULT_MAX_DISTANCE
from jaxgeo.methods import as_method

from .helpers import unit_icosphere
from .test_exact import (
    POINTS as EXACT_POINTS,
    holed_plate,  # a wavy plate with a round hole
)

POINTS = 128  # test_batch's capacity: the icosphere class's compile is shared


@functools.cache
def small_torus() -> jg.Mesh:
    """A closed mesh of icosphere(2)'s size class but another shape and genus."""
    tm = trimesh.creation.torus(
        major_radius=1.0, minor_radius=0.4, major_sections=17, minor_sections=10
    )
    return jg.Mesh(tm.vertices, tm.faces)


def test_size_class_grid():
    """The smallest 2^j or 3·2^j at least n: consecutive classes √2 apart on
    average (ratios 4/3 and 3/2)."""
    grid = sorted({2**j for j in range(20)} | {3 * 2**j for j in range(20)})
    for n in range(1, 5000):
        assert size_class(n) == min(g for g in grid if g >= n)
    assert size_class(20_001) == 24_576 and size_class(24_576) == 24_576
    assert size_class(3, least=64) == 64


@pytest.mark.parametrize("make", [holed_plate, lambda: unit_icosphere(2)])
def test_padded_layout(make):
    """Real rows unchanged, padding as documented, counts of the class."""
    mesh = make()
    c = mesh.size_class
    p = mesh.padded()
    n_v, n_f, n_e = mesh.n_vertices, mesh.n_faces, mesh.n_edges
    boundary = 2 * n_e - 3 * n_f
    assert isinstance(c, SizeClass)
    assert (p.n_vertices, p.n_faces, p.n_edges) == (c.vertices, c.faces, c.edges)
    assert c.vertices > n_v and c.faces > n_f and c.edges > n_e
    assert c.boundary >= boundary and (c.boundary == 0) == (boundary == 0)
    # fit_boundary_normals' static boundary count is the class's
    assert 2 * p.n_edges - 3 * p.n_faces == c.boundary
    assert p.vertex_faces.shape[1] == c.fan >= mesh.vertex_faces.shape[1]
    assert {f.name for f in dataclasses.fields(mesh)} == set(RULES) | {"vertices"}
    for f in dataclasses.fields(mesh):
        real, pad = np.asarray(getattr(mesh, f.name)), np.asarray(getattr(p, f.name))
        index = tuple(slice(0, n) for n in real.shape)
        np.testing.assert_array_equal(pad[index], real, err_msg=f.name)
    v = np.asarray(mesh.vertices)
    np.testing.assert_array_equal(
        np.asarray(p.vertices)[n_v:],
        np.broadcast_to((v.min(0) + v.max(0)) / 2, (c.vertices - n_v, 3)),
    )
    assert np.all(np.asarray(p.faces)[n_f:] == n_v)
    assert np.all(np.asarray(p.face_component)[n_f:] == -1)
    assert np.all(np.asarray(p.edge_faces)[n_e:] == -1)
    assert np.all(np.asarray(p.edge_faces)[:n_e, 0] >= 0)  # the real-edge mask
    assert np.all(np.asarray(p.fan_size)[n_v:] == 0)
    assert np.all(np.asarray(p.boundary_next)[n_v:] == -1)  # off the boundary
    assert np.all(np.asarray(p.fan_faces)[:, mesh.fan_faces.shape[1] :] == -1)
    assert np.all(np.isinf(np.asarray(p.landmark_dist)[:, n_v:]))
    assert np.all(np.asarray(p.landmark_pred_vertex)[:, n_v:] == -1)
    assert np.all(np.asarray(p.landmark_pred_edge)[:, n_e:] == -1)
    # the padded topology is cached and shared by with_vertices
    q = mesh.with_vertices(mesh.vertices * 2).padded()
    assert q.faces is p.faces and q.landmark_pred_edge is p.landmark_pred_edge
    assert mesh.padded().vertices is mesh.padded().vertices  # the last one cached
    np.testing.assert_array_equal(np.asarray(q.vertices)[:n_v], 2 * v)
    # but not the geometry that follows the vertices: the corner angles of new
    # positions (a shear changes them) are recomputed, and padded with them
    sheared = v + np.outer(v[:, 0], [0.0, 0.0, 1.0])
    r = mesh.with_vertices(sheared).padded()
    np.testing.assert_allclose(
        np.asarray(r.corner_angles)[:n_f],
        np.asarray(corner_angles(sheared, mesh.faces)),
        rtol=1e-12,
    )
    assert not np.allclose(np.asarray(r.corner_angles), np.asarray(p.corner_angles))


@pytest.mark.parametrize("make", [holed_plate, lambda: unit_icosphere(3)])
@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_points_at_the_sentinel_locate_on_real_faces(make):
    """The padded faces sit at the bounding box's centre (in the plate's hole, at
    the sphere's centre): a point there or near it is located on the nearest
    real face, at the brute-force distance over the real faces (the sphere's
    1,280 faces take the pruned search, the plate's the full one)."""
    mesh = make()
    p = mesh.padded()
    centre = np.asarray(p.vertices)[mesh.n_vertices]
    rng = np.random.default_rng(0)
    pts = centre + np.concatenate(
        [np.zeros((1, 3)), rng.normal(scale=1e-3, size=(3, 3))]
    )
    got, dist = jax.vmap(lambda x: jg.locate(p, x))(jnp.asarray(pts))
    assert np.all(np.asarray(got.face) < mesh.n_faces)
    assert np.all(np.asarray(dist) > 0.1)  # the padding (distance 0) lost
    # the brute-force nearest point over the real faces (trimesh's formula):
    # distances O(1), rounding of either closest-point formula a few 1e-16
    tri = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]
    ref = [
        np.linalg.norm(
            trimesh.triangles.closest_point(tri, np.broadcast_to(x, (len(tri), 3))) - x,
            axis=1,
        ).min()
        for x in pts
    ]
    np.testing.assert_allclose(dist, ref, rtol=0, atol=1e-12)
    on_face = jax.vmap(lambda sp: sp.position(mesh))(got)
    np.testing.assert_allclose(
        np.linalg.norm(np.asarray(on_face) - pts, axis=1), ref, rtol=0, atol=1e-12
    )


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_a_second_mesh_of_a_class_does_not_compile(caplog):
    """icosphere(2) and a torus: other shapes, counts and genus, one size class.
    After the first, the second runs single paths and batches with no compile at
    all (JAX logs every compile; the jitted solvers' caches do not grow)."""
    a, b = unit_icosphere(2), small_torus()
    assert a.size_class == b.size_class
    assert a.n_faces != b.n_faces and a.n_vertices != b.n_vertices

    def run(mesh):
        v = np.asarray(mesh.vertices)
        jg.shortest_path(mesh, v[0], v[40], max_points=POINTS)
        jg.shortest_paths(mesh, v[:5], v[40:45], chunk_size=4, max_points=POINTS)

    run(a)
    sizes = _solve_one._cache_size(), _solve_chunk._cached._cache_size()
    with jax.log_compiles(True), caplog.at_level(logging.WARNING):
        caplog.clear()
        run(b)
    compiles = [
        r.getMessage()[:120] for r in caplog.records if "Compiling" in r.getMessage()
    ]
    assert not compiles, compiles
    assert (
        _solve_one._cache_size(),
        _solve_chunk._cached._cache_size(),
    ) == sizes


def test_a_traced_mesh_is_padded_inside_the_trace():
    """A mesh that is itself an argument of the user's `jax.jit` (as in
    `jaxgeo.seams`) is padded with jnp inside the trace: the solver sees the
    class's shapes. Traced only (no compile)."""
    mesh = small_torus()
    v = np.asarray(mesh.vertices)
    jaxpr = jax.make_jaxpr(lambda m: jg.path_length(m, v[0], v[40], max_points=POINTS))(
        mesh
    )
    c = mesh.size_class
    solver = [e for e in jaxpr.jaxpr.eqns if "_solve_one" in str(e.params.get("name"))]
    assert len(solver) == 1
    shapes = {tuple(x.aval.shape) for x in solver[0].invars}
    assert (c.vertices, 3) in shapes and (c.faces, 3) in shapes
    assert (mesh.n_vertices, 3) not in shapes and (mesh.n_faces, 3) not in shapes


def test_padding_a_concrete_mesh_inside_a_jit_caches_no_tracer():
    """A mesh closed over by a user's jit is concrete, but its padding is traced
    there: caching it leaked a tracer into every later call (UnexpectedTracerError
    in tests/test_throw.py's jitted path_length)."""
    tm = trimesh.creation.icosphere(1)  # a fresh mesh: nothing cached for it yet
    mesh = jg.Mesh(tm.vertices, tm.faces)
    inside = float(jax.jit(lambda: jnp.sum(mesh.padded().faces))())
    outside = mesh.padded()  # would raise if the traced padding had been cached
    assert not any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(outside))
    assert float(jnp.sum(outside.faces)) == inside


def test_the_padded_mesh_is_remembered_while_its_mesh_lives():
    """`shortest_path` pads on every call: the padded mesh of a concrete mesh is
    built once (`_padding._PADDED`) and dropped when the mesh is collected."""
    import gc

    from jaxgeo._padding import _PADDED

    tm = trimesh.creation.icosphere(1)
    mesh = jg.Mesh(tm.vertices, tm.faces)
    first = mesh.padded()
    assert mesh.padded() is first
    key = id(mesh)
    assert _PADDED[key][1] is first
    del mesh, first
    gc.collect()
    assert key not in _PADDED


def _both(mesh, method, pairs):
    """The paths of vertex `pairs` on the padded mesh (the public API) and on the
    real mesh (the jitted solver handed the unpadded arrays). test_exact's
    capacity and default chunk: the padded compile is shared with it."""
    v = np.asarray(mesh.vertices)
    chunk = 256  # shortest_paths' default
    idx = np.resize(np.arange(len(pairs)), chunk)
    p1, p2 = v[pairs[idx, 0]], v[pairs[idx, 1]]
    got = jg.shortest_paths(mesh, p1, p2, method=method, max_points=EXACT_POINTS)
    limit = jnp.asarray(DEFAULT_MAX_DISTANCE, v.dtype)
    points = np.full(chunk, -1, np.int32)  # rows are 3-D points, not vertex indices
    ref = _solve_chunk(
        mesh,
        jnp.asarray(p1),
        jnp.asarray(p2),
        jnp.asarray(points),
        jnp.asarray(points),
        limit,
        as_method(method),
        EXACT_POINTS,
    )
    return got, jax.tree.map(np.asarray, ref)


def _assert_same(got, ref, mesh):
    assert np.all(got.status == jg.Status.SUCCESS)
    np.testing.assert_array_equal(got.status, ref.status)
    np.testing.assert_array_equal(got.count, ref.count)
    for i in range(len(got.count)):
        n = int(got.count[i])
        np.testing.assert_array_equal(got.kinds[i, :n], ref.kinds[i, :n])
        np.testing.assert_array_equal(got.elements[i, :n], ref.elements[i, :n])
    # the same operations on the same real elements; the padding changes array
    # shapes, so XLA may fuse and order sums differently: rounding, a few eps of
    # the mesh's size per point
    scale = float(np.ptp(np.asarray(mesh.vertices), axis=0).max())
    tol = 1e3 * np.finfo(np.float64).eps * scale
    np.testing.assert_allclose(got.length, ref.length, rtol=0, atol=tol)
    np.testing.assert_allclose(got.points, ref.points, rtol=0, atol=tol)


PAIRS = np.array([[3, 140], [20, 131], [0, 100], [60, 7]])


@pytest.mark.slow  # an unpadded compile of its own: ~25 s cold (README tests ≤ 5 min)
def test_exact_paths_padded_equal_unpadded():
    mesh = holed_plate()
    _assert_same(*_both(mesh, "exact", PAIRS), mesh)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["laser", "smooth"])
def test_laser_and_smooth_paths_padded_equal_unpadded(method):
    mesh = holed_plate()
    _assert_same(*_both(mesh, method, PAIRS), mesh)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["exact", "laser"])
def test_gradients_padded_equal_unpadded(method):
    """d length / d vertices through the padded mesh is the real mesh's: (V, 3),
    zero on the padding's side (nothing flows into the real rows from it)."""
    mesh = holed_plate()
    v = np.asarray(mesh.vertices)
    p1, p2 = jnp.asarray(v[3] * 0.7 + v[4] * 0.3), jnp.asarray(v[140])
    m = as_method(method)
    limit = jnp.asarray(0.5, v.dtype)

    def padded(x):
        return jg.path_length(
            mesh.with_vertices(x), p1, p2, method=method, max_points=POINTS
        )

    def real(x):
        path, _ = _solve_one(mesh.with_vertices(x), p1, p2, limit, m, POINTS, True)
        return path.length

    g, ref = jax.grad(padded)(mesh.vertices), jax.grad(real)(mesh.vertices)
    assert g.shape == mesh.vertices.shape and np.all(np.isfinite(g))
    assert np.abs(np.asarray(g)).max() > 0.1  # a real gradient, not zeros
    np.testing.assert_allclose(g, ref, rtol=0, atol=1e-10)
