"""`shortest_path(method=...)`: the exact and smooth methods wired through the
public API (jit, vmap, grad), against the laser ray, MMP and the analytic catenoid."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import surfaces
from jaxgeo.validation import catenoid_geodesic_length


@functools.cache
def catenoid():
    return jg.Mesh(*surfaces.catenoid())  # the built-in example, 3,888 faces


def _vertex_pairs(v, n, seed):
    """Pairs of vertices, lower half to upper half (across the neck)."""
    rng = np.random.default_rng(seed)
    low, high = np.flatnonzero(v[:, 2] < -0.1), np.flatnonzero(v[:, 2] > 0.1)
    return [(int(rng.choice(low)), int(rng.choice(high))) for _ in range(n)]


def _exact_never_longer_than_laser_and_matches_mmp(n_pairs: int):
    geodesic = pytest.importorskip("pygeodesic.geodesic")
    mesh = catenoid()
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    mmp = geodesic.PyGeodesicAlgorithmExact(v, f)
    for i, j in _vertex_pairs(v, n_pairs, seed=0):
        laser = jg.shortest_path(mesh, v[i], v[j], method="laser")
        exact = jg.shortest_path(mesh, v[i], v[j], method="exact")
        d = mmp.geodesicDistance(i, j)[0]
        # The exact path starts from the laser corridor (which holds the laser path)
        # and only ever shortens: never longer, up to rounding.
        assert float(exact.length) <= float(laser.length) * (1 + 1e-12)
        # MMP and the funnel are both exact: agreement to rounding; 1e-9 is the
        # bound of the refinement's acceptance (issue 5).
        assert float(exact.length) >= d * (1 - 1e-9)
        assert abs(float(exact.length) - d) <= 1e-6 * d
        pts = exact.polyline()
        np.testing.assert_allclose([pts[0], pts[-1]], [v[i], v[j]], atol=1e-12)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
        assert abs(seg - float(exact.length)) <= 1e-12 * seg


def test_exact_is_never_longer_than_laser_and_matches_mmp_one_pair():
    """The fast set's part: one pair, with the default options on the built-in
    catenoid, which tests/test_cli.py's `jaxgeo path` runs with both methods (the
    compiled solvers are shared)."""
    _exact_never_longer_than_laser_and_matches_mmp(1)


@pytest.mark.slow
def test_exact_is_never_longer_than_laser_and_matches_mmp():
    _exact_never_longer_than_laser_and_matches_mmp(6)


@pytest.mark.slow
def test_exact_and_smooth_under_jit_vmap_and_grad():
    mesh = catenoid()
    f0, f1 = 100, 3000
    sa = jg.SurfacePoint(jnp.asarray(f0), jnp.array([0.2, 0.3, 0.5]))
    sb = jg.SurfacePoint(jnp.asarray(f1), jnp.array([0.3, 0.3, 0.4]))
    for method in ("exact", "smooth"):
        eager = float(jg.path_length(mesh, sa, sb, method=method))
        jitted = jax.jit(lambda m, a, b, me=method: jg.path_length(m, a, b, method=me))
        assert abs(float(jitted(mesh, sa, sb)) - eager) <= 1e-12 * eager
        batch = jax.vmap(lambda a, b, me=method: jg.path_length(mesh, a, b, method=me))(
            jax.tree.map(lambda x: jnp.stack([x, x]), sa),
            jax.tree.map(lambda x: jnp.stack([x, x]), sb),
        )
        np.testing.assert_allclose(batch, [eager, eager], rtol=1e-12)

        def length(v, me=method):
            return jg.path_length(mesh.with_vertices(v), sa, sb, method=me)

        g = jax.grad(length)(mesh.vertices)
        rng = np.random.default_rng(1)
        h = 1e-6
        for _ in range(3):
            d = jnp.asarray(rng.normal(size=g.shape))
            fd = (length(mesh.vertices + h * d) - length(mesh.vertices - h * d)) / (
                2 * h
            )
            # central differences: O(h²) truncation + O(eps/h) rounding ≈ 1e-10
            # absolute on O(1) derivatives; 1e-6 relative as in issues 4, 5, 9.
            assert abs(float(jnp.sum(g * d)) - float(fd)) <= 1e-6 * max(
                1.0, abs(float(fd))
            )


@pytest.mark.slow
def test_smooth_is_closer_to_the_analytic_catenoid_than_exact():
    """Interior endpoints of the catenoid (mesh vertices lie on the surface, so the
    analytic geodesic applies): the Phong-surface geodesic beats the flat one."""
    mesh = catenoid()
    v = np.asarray(mesh.vertices)
    inner = np.flatnonzero(np.abs(v[:, 2]) < 0.4)
    rng = np.random.default_rng(3)
    errs = {"exact": [], "smooth": []}
    for _ in range(4):
        i, j = rng.choice(inner, 2, replace=False)
        ref = catenoid_geodesic_length(v[i], v[j])
        for method in errs:
            length = float(jg.path_length(mesh, v[i], v[j], method=method))
            errs[method].append(abs(length - ref) / ref)
    assert np.median(errs["smooth"]) < np.median(errs["exact"]) / 10


def test_for_mesh_runs_one_lane_on_a_mesh_with_no_cone_vertex():
    """On a concrete cone-free mesh the exact engine's flip loop runs one lane
    (its first converged start settles the others of its class); elsewhere, on
    a traced mesh, and where the caller chose, the options stay."""
    from jaxgeo.exact import POOL_MIN_CONE_FREE
    from jaxgeo.methods import for_mesh

    cone_free = catenoid()
    with_cones = jg.Mesh(*surfaces.icosphere(2))
    assert for_mesh(jg.Exact(), cone_free).min_lanes == POOL_MIN_CONE_FREE == 1
    assert for_mesh(jg.Smooth(), cone_free).exact.min_lanes == 1
    assert for_mesh(jg.Exact(), with_cones).min_lanes is None
    assert for_mesh(jg.Exact(min_lanes=3), cone_free).min_lanes == 3
    assert for_mesh(jg.Laser(), cone_free) == jg.Laser()
    seen = []

    @jax.jit
    def traced(v):
        seen.append(for_mesh(jg.Exact(), cone_free.with_vertices(v)).min_lanes)
        return v

    traced(cone_free.vertices)
    assert seen == [None]


@pytest.mark.slow  # four compiles of the exact path (~50 s)
def test_one_lane_and_four_give_the_same_paths():
    """`min_lanes` changes how many starts run at once, not the path: on the
    catenoid (no cone vertex) the lengths at 1 and 4 lanes agree to rounding
    (the same corridor, unfolded in lanes of another width: 1e-12). One lane
    refines every pair's first start alone, and its other starts only where
    that did not settle the pair: on a mesh with cones (an icosphere), always,
    and the detours after them, as four lanes do."""
    for mesh in (catenoid(), jg.Mesh(*surfaces.icosphere(2))):
        pairs = np.random.default_rng(5).integers(0, mesh.n_vertices, (6, 2))
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]

        def lengths(lanes, mesh=mesh, pairs=pairs):
            method = jg.Exact(min_lanes=lanes)
            return [
                float(jg.path_length(mesh, int(a), int(b), method=method))
                for a, b in pairs
            ]

        np.testing.assert_allclose(lengths(1), lengths(4), rtol=1e-12)
