"""Geodesics on the Phong tessellation (`jaxgeo.smooth`, `jaxgeo._phong`).

The surface's formulas run in the fast set (eager, small arrays); every smooth
path compiles the exact and the smooth solvers (about a minute), so those tests
are slow.

Acceptance (issue 9): on the validation suites' vertex pairs the smooth geodesic's
median |relative error| against the analytic length is ≤ 1e-5 on the 5,120-face
icosphere (and ≥ 50× below the exact polyhedral geodesic's) and ≤ 1e-6 on the
catenoid (default options, through `shortest_path`); the length's gradient matches
central differences.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo
import jaxgeo as jg
from jaxgeo import validation
from jaxgeo._errors import JaxgeoError
from jaxgeo._phong import phong_point, segment_length
from jaxgeo.locate import SurfacePoint
from jaxgeo.mesh import Mesh
from jaxgeo.normals import vertex_normals
from jaxgeo.smooth import (
    phong_normals,
    smooth_geodesic,
    smooth_path,
    smooth_shortest_path,
)
from jaxgeo.surfaces import icosphere

CAPACITY = 256  # one compiled shape for every path of a mesh


def _vertex_point(faces: np.ndarray, i: int) -> SurfacePoint:
    face = int(np.flatnonzero((faces == i).any(1))[0])
    bary = (faces[face] == i).astype(np.float64)
    return SurfacePoint(jnp.asarray(face), jnp.asarray(bary))


def _smooth(mesh: Mesh, start: SurfacePoint, end: SurfacePoint, **options):
    """The exact polyhedral geodesic's strip, then the smooth geodesic with strip
    repair."""
    ex = jg.shortest_path(mesh, start, end, method="exact")
    n = int(ex.count)
    kinds, elements, params = (
        np.asarray(x)[1 : n - 1] for x in (ex.kinds, ex.elements, ex.params)
    )
    return smooth_shortest_path(
        mesh, start, end, elements, params, kinds, capacity=CAPACITY, **options
    )


# --------------------------------------------------------------------------- surface


def test_no_module_holds_a_jax_array():
    """A module first imported inside a jit trace (`methods.Smooth.solve` imports
    `smooth` lazily) must not create jax arrays at import: they would be tracers,
    leaked into every later trace (`_phong._GAUSS` did: UnexpectedTracerError in
    `jit(path_length(method="smooth"))` when nothing had imported it before)."""
    import importlib
    import pkgutil

    # caches filled at run time, from concrete arrays only (`_padding` pads a
    # traced topology without caching it): not import-time constants
    runtime_caches = {"jaxgeo._padding._CACHE", "jaxgeo._padding._PADDED"}
    held = []
    for info in pkgutil.walk_packages(jaxgeo.__path__, "jaxgeo."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if f"{info.name}.{name}" in runtime_caches:
                continue
            if any(isinstance(x, jax.Array) for x in jax.tree.leaves(value)):
                held.append(f"{info.name}.{name}")
    assert not held


def test_phong_edge_curve_depends_on_edge_only():
    """α = ½ (any α): a point on an edge lifts to the same point from either face,
    whatever the third vertices and their normals; corners lift to the vertices."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=3), rng.normal(size=3)
    na, nb = (x / np.linalg.norm(x) for x in rng.normal(size=(2, 3)))
    bary = jnp.asarray([0.3, 0.7, 0.0])
    lifted = []
    for _ in range(3):
        c, nc = rng.normal(size=3), rng.normal(size=3)
        corners = jnp.asarray(np.stack([a, b, c]))
        normals = jnp.asarray(np.stack([na, nb, nc / np.linalg.norm(nc)]))
        lifted.append(np.asarray(phong_point(corners, normals, bary, 0.5)))
        for i in range(3):
            corner = phong_point(corners, normals, jnp.eye(3)[i], 0.5)
            np.testing.assert_allclose(corner, corners[i], atol=1e-15)
    np.testing.assert_allclose(lifted[1], lifted[0], atol=1e-15)
    np.testing.assert_allclose(lifted[2], lifted[0], atol=1e-15)
    # and the formula: (1 − α) p + α Σ b_i π_i(p)
    p = 0.3 * a + 0.7 * b
    proj = [p - ((p - v) @ n) * n for v, n in ((a, na), (b, nb))]
    np.testing.assert_allclose(
        lifted[0], 0.5 * p + 0.5 * (0.3 * proj[0] + 0.7 * proj[1]), atol=1e-14
    )


def test_phong_sphere_triangle_is_closer_than_flat():
    """With exact normals on a small spherical triangle, α = ½ removes the O(h²)
    sagitta: the lifted centre is O(h³)-close to the sphere, ~100× the flat one."""
    h = 0.05
    corners = np.array(
        [[1, 0, 0], [np.cos(h), np.sin(h), 0], [np.cos(h), 0, np.sin(h)]]
    )
    corners /= np.linalg.norm(corners, axis=1, keepdims=True)
    bary = jnp.full(3, 1 / 3)
    flat = np.asarray(bary @ corners)
    lifted = np.asarray(phong_point(jnp.asarray(corners), jnp.asarray(corners), bary))
    assert abs(np.linalg.norm(lifted) - 1) < abs(np.linalg.norm(flat) - 1) / 50


def test_segment_quadrature_converged():
    """4-point Gauss–Legendre on a lifted segment agrees with 8 points to ~1e-12."""
    v, f = icosphere(2)
    corners = jnp.asarray(v[f[0]])
    b0, b1 = jnp.asarray([0.9, 0.1, 0.0]), jnp.asarray([0.0, 0.2, 0.8])
    four = segment_length(corners, corners, b0, b1, 0.5, 4)
    eight = segment_length(corners, corners, b0, b1, 0.5, 8)
    assert abs(four - eight) < 1e-11 * eight


# --------------------------------------------------------------------------- accuracy


@pytest.fixture(scope="module")
def sphere():
    suite = validation.sphere_suite(4)
    return suite, Mesh(suite.vertices, suite.faces)


@pytest.mark.slow
def test_sphere_acceptance(sphere):
    """5,120-face icosphere: median |rel. error| ≤ 1e-5 and ≥ 50× below MMP."""
    pygeodesic = pytest.importorskip("pygeodesic.geodesic")
    suite, mesh = sphere
    faces = np.asarray(mesh.faces)
    exact = pygeodesic.PyGeodesicAlgorithmExact(
        suite.vertices, suite.faces.astype(np.int32)
    )
    err_smooth, err_exact = [], []
    for p in suite.pairs:
        sp = _smooth(mesh, _vertex_point(faces, p.v1), _vertex_point(faces, p.v2))
        assert bool(sp.converged) and bool(sp.valid_strip)
        err_smooth.append(float(sp.length) / p.analytic - 1)
        err_exact.append(exact.geodesicDistance(p.v1, p.v2)[0] / p.analytic - 1)
    med_smooth = np.median(np.abs(err_smooth))
    med_exact = np.median(np.abs(err_exact))
    assert med_smooth <= 1e-5
    assert med_smooth * 50 <= med_exact


@pytest.mark.slow
def test_catenoid_acceptance():
    """Catenoid (6,144 faces, the suite's level 4: the nearest to issue 9's "about
    4,000"), the suite's 13 pairs, through `shortest_path(method="smooth")` with
    default options: median |rel. error| ≤ 1e-6 (issue 9).

    Ten pairs end on the boundary rings. There eq. (8)–(9) averages a one-sided fan
    and is O(h) off, which left the median at 1.2e-6 (C9, along the ring: 6e-6);
    the smooth method fits the boundary normals to second order
    (`fit_boundary_normals`), measured median 3.1e-7, max 9e-7."""
    suite = validation.catenoid_suite(4)
    mesh = Mesh(suite.vertices, suite.faces)
    err = []
    for p in suite.pairs:
        path = jaxgeo.shortest_path(
            mesh, suite.vertices[p.v1], suite.vertices[p.v2], method="smooth"
        )
        assert int(path.status) == 0
        err.append(float(path.length) / p.analytic - 1)
    assert np.median(np.abs(err)) <= 1e-6


@pytest.mark.slow
def test_shortest_path_smooth_repairs_with_the_requested_weighting():
    """`shortest_path(method="smooth", normals="angle")` repairs the strip and
    solves on the same (angle-weighted, boundary-fitted) surface: its length is the
    strip repair's with those normals, to the solver's convergence (gradient
    ~1e-12, so lengths agree far below 1e-10)."""
    suite = validation.catenoid_suite(3)
    mesh = Mesh(suite.vertices, suite.faces)
    faces = np.asarray(mesh.faces)
    for p in suite.pairs[:4]:
        s, e = _vertex_point(faces, p.v1), _vertex_point(faces, p.v2)
        path = jaxgeo.shortest_path(mesh, s, e, method="smooth", normals="angle")
        assert int(path.status) == 0
        want = _smooth(mesh, s, e, normals="angle")
        np.testing.assert_allclose(float(path.length), float(want.length), rtol=1e-10)
        # the smooth solve's diagnostics reach the result, beside the exact's
        st = path.stats or {}
        assert bool(st["converged"]) and int(st["newton_iterations"]) >= 1
        assert 0.0 <= float(st["grad_norm"]) <= 1e-9
        assert int(st["starts"]) >= 1 and int(st["repair_rounds"]) >= 0
        # vertex endpoints: the Phong surface meets the mesh there
        assert path.start is not None and path.end is not None
        n = int(path.count)
        ends = [path.start.position(mesh), path.end.position(mesh)]
        np.testing.assert_allclose(
            ends, np.asarray(path.points)[[0, n - 1]], atol=1e-12
        )


@pytest.mark.slow
def test_converges_when_the_path_grazes_vertices():
    """Sphere suite level 6 (81,920 faces), pair S3: a great circle along mesh
    edges, whose smooth geodesic passes ~1e-8 from vertices. There the Hessian is
    ~3e6 and the gradient cannot fall below its rounding (~1e-10, the Newton step
    below one ulp of u); the solver used to stop unconverged (REFINE_FAILED in the
    convergence study). Converged, and the length within the level's smooth error
    (median 5e-8 over the suite; 1.4e-7 measured here)."""
    suite = validation.sphere_suite(6)
    mesh = Mesh(suite.vertices, suite.faces)
    faces = np.asarray(mesh.faces)
    p = next(q for q in suite.pairs if q.pair == "S3")
    sp = _smooth(mesh, _vertex_point(faces, p.v1), _vertex_point(faces, p.v2))
    assert bool(sp.converged) and bool(sp.valid_strip)
    assert abs(float(sp.length) / p.analytic - 1) < 1e-6


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_phong_normals_boundary_option():
    """`boundary="keep"` is the weighting itself; `"fit"` (default) changes the
    boundary vertices only."""
    v, f = validation.catenoid_mesh(2)
    mesh = Mesh(v, f)
    fan = np.asarray(vertex_normals(mesh.vertices, mesh.faces))
    # compiled vs eager: equal to rounding
    np.testing.assert_allclose(phong_normals(mesh, "uniform", "keep"), fan, atol=1e-15)
    fit = np.asarray(phong_normals(mesh))
    ring = np.isclose(np.abs(v[:, 2]), 0.5)
    assert (np.linalg.norm(fit - fan, axis=1)[ring] > 1e-3).all()
    np.testing.assert_allclose(fit[~ring], fan[~ring], atol=1e-15)
    # an array is refitted at the boundary too, unless kept
    np.testing.assert_allclose(phong_normals(mesh, jnp.asarray(fan)), fit, atol=1e-15)


@pytest.mark.mistyped  # "mirror" is no `boundary` option: the error is the test
def test_phong_normals_rejects_an_unknown_boundary_option():
    v, f = validation.catenoid_mesh(2)
    with pytest.raises(JaxgeoError, match="boundary must be"):
        phong_normals(Mesh(v, f), "uniform", "mirror")


# --------------------------------------------------------------------------- gradients


@pytest.mark.slow
def test_gradient_matches_central_differences(sphere):
    """dL/d(vertices) and dL/d(endpoint barycentrics) by the envelope theorem vs
    central differences (step 1e-6) on a fixed strip, path away from vertices."""
    _, mesh = sphere
    faces = np.asarray(mesh.faces)
    bary = jnp.asarray([0.2, 0.3, 0.5])
    start, end = (
        SurfacePoint(jnp.asarray(0), bary),
        SurfacePoint(jnp.asarray(700), bary),
    )
    sp = _smooth(mesh, start, end)
    assert bool(sp.converged) and not bool(sp.hit_vertex)
    n = int(sp.count) - 2
    kinds = np.asarray(sp.kinds[1 : n + 1])
    assert (kinds == 1).all()
    elements, params = sp.elements[1 : n + 1], sp.params[1 : n + 1]
    pad = CAPACITY - n
    elements = jnp.pad(elements, (0, pad))
    params = jnp.pad(params, (0, pad))

    def length(vertices, b1):
        s = SurfacePoint(start.face, b1)
        m = mesh.with_vertices(vertices)
        return smooth_geodesic(m, s, end, elements, params, count=n).length

    g_v, g_b = jax.grad(length, argnums=(0, 1))(mesh.vertices, start.bary)
    # the vertices of crossed edges, and the start face's corners
    used = np.unique(np.asarray(mesh.edges)[np.asarray(elements[:n])])
    rng = np.random.default_rng(0)
    checks = [
        (int(i), int(k)) for i in rng.choice(used, 6, replace=False) for k in (0, 2)
    ]
    checks += [(int(i), 1) for i in faces[0]]
    step = 1e-6
    for i, k in checks:
        e = jnp.zeros_like(mesh.vertices).at[i, k].set(step)
        fd = (
            length(mesh.vertices + e, start.bary)
            - length(mesh.vertices - e, start.bary)
        ) / (2 * step)
        assert abs(fd - g_v[i, k]) <= 1e-6 * max(1.0, abs(fd)), (i, k, fd, g_v[i, k])
    # endpoint: move along the face (barycentric direction summing to zero)
    d = jnp.asarray([1.0, -0.5, -0.5])
    fd = (
        length(mesh.vertices, bary + step * d) - length(mesh.vertices, bary - step * d)
    ) / (2 * step)
    assert abs(fd - g_b @ d) <= 1e-6 * max(1.0, abs(fd))


# --------------------------------------------------------------------- smooth_path

SMALL = 64  # the buffer of every smooth_path test: one compiled shape


def _exact_buffers(mesh: Mesh, start: SurfacePoint, end: SurfacePoint):
    """The exact polyhedral geodesic as `Path`-format buffers of size SMALL."""
    ex = jg.shortest_path(mesh, start, end, method="exact", max_points=SMALL)
    n = int(ex.count)

    def pad(x):
        x = np.asarray(x)[:n]
        return jnp.asarray(np.concatenate([x, np.zeros(SMALL - n, x.dtype)]))

    return pad(ex.kinds), pad(ex.elements), pad(ex.params), jnp.asarray(n)


@pytest.fixture(scope="module")
def catenoid3():
    suite = validation.catenoid_suite(3)
    mesh = Mesh(suite.vertices, suite.faces)
    faces = np.asarray(mesh.faces)
    pairs = {
        p.pair: (_vertex_point(faces, p.v1), _vertex_point(faces, p.v2))
        for p in suite.pairs
    }
    return suite, mesh, pairs


@pytest.mark.slow
def test_smooth_path_repairs_as_the_eager_repair(catenoid3):
    """`smooth_path` (the repair in JAX) gives `smooth_shortest_path`'s (eager)
    length on catenoid level 3 pairs: C10, whose strip is released round a vertex
    (one round), C1, which keeps its 7 vertex contacts (a meridian through
    vertices), and C8, which touches none. Both repairs take the same candidates
    and the same Newton solver, so the lengths agree to the solver's convergence
    (gradient ~1e-12·h: lengths far below 1e-12 relative; measured 3e-16)."""
    _, mesh, pairs = catenoid3
    rounds = {}
    for name in ("C10", "C1", "C8"):
        s, e = pairs[name]
        res = smooth_path(mesh, s, e, *_exact_buffers(mesh, s, e))
        assert bool(res.ok)
        want = _smooth(mesh, s, e)
        np.testing.assert_allclose(
            float(res.path.length), float(want.length), rtol=1e-12
        )
        rounds[name] = int(res.rounds)
    assert rounds == {"C10": 1, "C1": 0, "C8": 0}


@pytest.mark.slow
def test_smooth_path_under_jit_vmap_grad(catenoid3):
    """No host callback in the compiled program; `jit(vmap(...))` over pairs gives
    the single calls' lengths (to rounding); `grad` of the length in the vertices
    matches central differences (step 1e-6: error ~1e-10 relative; bound 1e-6, as
    `test_gradient_matches_central_differences`)."""
    _, mesh, pairs = catenoid3
    names = ("C10", "C3", "C8")
    bufs = [(*pairs[n], *_exact_buffers(mesh, *pairs[n])) for n in names]
    stacked = jax.tree.map(lambda *x: jnp.stack(x), *bufs)

    def length(m, s, e, k, el, u, c):
        return smooth_path(m, s, e, k, el, u, c).path.length

    jaxpr = str(jax.make_jaxpr(length)(mesh, *bufs[0]))
    assert "callback" not in jaxpr
    batch = jax.jit(jax.vmap(length, in_axes=(None, 0, 0, 0, 0, 0, 0)))(mesh, *stacked)
    single = [float(length(mesh, *b)) for b in bufs]
    np.testing.assert_allclose(np.asarray(batch), single, rtol=1e-13)

    s, e, k, el, u, c = bufs[0]

    def of_vertices(x):
        return length(mesh.with_vertices(x), s, e, k, el, u, c)

    g = jax.grad(of_vertices)(mesh.vertices)
    assert np.isfinite(np.asarray(g)).all()
    used = np.unique(np.asarray(mesh.edges)[np.asarray(el[1 : int(c) - 1])])
    step = 1e-6
    for i in used[:: max(1, len(used) // 4)][:4]:
        for axis in (0, 2):
            d = jnp.zeros_like(mesh.vertices).at[i, axis].set(step)
            fd = (of_vertices(mesh.vertices + d) - of_vertices(mesh.vertices - d)) / (
                2 * step
            )
            assert abs(fd - g[i, axis]) <= 1e-6 * max(1.0, abs(fd)), (i, axis)
