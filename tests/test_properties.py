"""Property-based tests (hypothesis) of the geodesic solver on generated meshes.

Three mesh families, each with a fixed topology and hypothesis-drawn geometry, so
that every example of a family has the same array shapes and the solver compiles
once per family (a compile costs seconds; an example milliseconds):

- perturbed spheres: an icosphere (2 subdivisions, 162 vertices) with each vertex
  moved radially by a drawn smooth field;
- height-field patches: a 7 × 7 vertex grid over [-1, 1]² with drawn heights
  (open mesh, one boundary loop);
- cone tents: `surfaces.cone_tent(12, 4)` with drawn ring heights and vertical
  noise (open, two boundary loops: a mesh with a hole).

Endpoints are drawn as vertices (so the exact polyhedral geodesic of pygeodesic,
test-only, is a lower bound), points inside faces and points on edges, including
boundary edges.

Every test asserts a success rate besides the invariants of each path (a test
whose paths all failed would otherwise pass: `check_path` checks only the status
of a failed path): the exact default succeeds on every pair; the laser on closed
meshes too, on open ones at a stated rate (`LASER_RATE`).

Profiles (`tests/conftest.py`): `ci` (default) runs 90 examples per family and
method; `HYPOTHESIS_PROFILE=long pytest -m slow tests/test_properties.py` runs
20× more. The fast set runs `test_perturbed_sphere_few_examples` only.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st

import jaxgeo as jg
from jaxgeo import surfaces
from jaxgeo.path import EDGE, FACE, VERTEX
from jaxgeo.projection import param_tolerance

geodesic = pytest.importorskip("pygeodesic.geodesic")

# -------------------------------------------------------------------- generators


@functools.cache
def _sphere_topology():
    return surfaces.icosphere(2)


@functools.cache
def _grid_topology():
    return surfaces.saddle(6)  # 7 × 7 vertices, alternating diagonals


@functools.cache
def _tent_topology():
    return surfaces.cone_tent(n_around=12, n_radial=4)


def _smooth_field(x: np.ndarray, seed: int, n_waves: int = 3) -> np.ndarray:
    """A sum of `n_waves` random plane waves at the points `x` (N, d), values in
    about [-1, 1]: smooth, so the drawn surfaces are meshes of smooth surfaces."""
    rng = np.random.default_rng(seed)
    out = np.zeros(len(x))
    for _ in range(n_waves):
        k = rng.normal(size=x.shape[1]) * 2.0
        out += np.cos(x @ k + rng.uniform(0, 2 * np.pi)) / n_waves
    return out


def perturbed_sphere(seed: int, amplitude: float, noise: float) -> jg.Mesh:
    v, f = _sphere_topology()
    rng = np.random.default_rng(seed)
    r = 1 + amplitude * _smooth_field(v, seed) + noise * rng.uniform(-1, 1, len(v))
    return jg.Mesh(v * r[:, None], f)


def height_patch(seed: int, amplitude: float, noise: float) -> jg.Mesh:
    v, f = _grid_topology()
    rng = np.random.default_rng(seed)
    z = amplitude * _smooth_field(v[:, :2], seed) + noise * rng.uniform(-1, 1, len(v))
    return jg.Mesh(np.column_stack([v[:, :2], z]), f)


def tent(seed: int, amplitude: float, noise: float) -> jg.Mesh:
    v, f = _tent_topology()
    rng = np.random.default_rng(seed)
    z = v[:, 2] * (1 + amplitude) + noise * rng.uniform(-1, 1, len(v))
    return jg.Mesh(np.column_stack([v[:, :2], z]), f)


def height_patch_float32(seed: int, amplitude: float, noise: float) -> jg.Mesh:
    m = height_patch(seed, amplitude, noise)
    return jg.Mesh(np.asarray(m.vertices, np.float32), np.asarray(m.faces))


FAMILIES = {
    "sphere": perturbed_sphere,
    "patch": height_patch,
    "tent": tent,
    "patch32": height_patch_float32,
}


@functools.cache
def exact_solver(mesh_key):
    family, seed, amplitude, noise = mesh_key
    mesh = make_mesh(mesh_key)
    return geodesic.PyGeodesicAlgorithmExact(
        np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)
    )


@functools.lru_cache(maxsize=64)
def make_mesh(mesh_key) -> jg.Mesh:
    family, seed, amplitude, noise = mesh_key
    return FAMILIES[family](seed, amplitude, noise)


def endpoint(mesh: jg.Mesh, kind: str, index: int, w: tuple[float, float]):
    """A drawn endpoint: `("vertex", i)`, `("face", f, weights)`, `("edge", e, s)`
    (edge `e`, parameter `s`), returned as (3-D point, vertex index or None)."""
    v = np.asarray(mesh.vertices, np.float64)
    if kind == "vertex":
        i = index % mesh.n_vertices
        return v[i], i
    if kind == "edge":
        e = np.asarray(mesh.edges)[index % mesh.n_edges]
        s = w[0]
        return (1 - s) * v[e[0]] + s * v[e[1]], None
    f = np.asarray(mesh.faces)[index % mesh.n_faces]
    b = np.array([w[0], w[1], 1.0]) + 1e-3
    return (b / b.sum()) @ v[f], None


# -------------------------------------------------------------------- invariants


def faces_containing(v, faces, p, tol) -> set[int]:
    """The faces whose closure contains the point `p` (to `tol`)."""
    tri = v[faces]  # (F, 3, 3)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = p - tri[:, 0]
    g = np.stack(
        [
            np.stack([np.sum(e1 * e1, 1), np.sum(e1 * e2, 1)], 1),
            np.stack([np.sum(e2 * e1, 1), np.sum(e2 * e2, 1)], 1),
        ],
        1,
    )
    rhs = np.stack([np.sum(e1 * d, 1), np.sum(e2 * d, 1)], 1)
    st_ = np.linalg.solve(g, rhs[..., None])[..., 0]
    bary = np.column_stack([1 - st_.sum(1), st_])
    clipped = np.clip(bary, 0, 1)
    # renormalised: a clipped sum ≠ 1 would scale the foot by the position's size
    foot = np.einsum("fi,fij->fj", clipped / clipped.sum(1, keepdims=True), tri)
    close = np.linalg.norm(foot - p, axis=1) <= tol
    # (the foot is a point of the triangle, so `close` bounds the true distance;
    # no separate test on the signs of `bary`, which would undo the snap slack)
    return set(np.flatnonzero(close).tolist())


def check_path(mesh: jg.Mesh, a, b, path: jg.Path, exact: float | None) -> None:
    """The invariants of a path from `a` to `b` (3-D points on the mesh)."""
    status = int(path.status)
    assert status in {s.value for s in jg.Status}, f"undocumented status {status}"
    for leaf in (path.points, path.params):
        assert np.all(np.isfinite(np.asarray(leaf))), "NaN or inf in the path"
    if status != jg.Status.SUCCESS:
        # a failed path has no length: NaN, never a number
        assert np.isnan(float(path.length)), "a failed path with a length"
        return
    assert np.isfinite(float(path.length)), "NaN or inf length"
    dtype = np.asarray(mesh.vertices).dtype
    # Distances are relative to the mesh scale; float32 keeps ~1e-6 of it.
    scale = float(mesh.mean_edge_length)
    tol = (1e-9 if dtype == np.float64 else 1e-5) * scale
    v = np.asarray(mesh.vertices, np.float64)
    edges = np.asarray(mesh.edges)
    longest = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1).max()
    snap = param_tolerance(dtype) * longest
    edge_faces = np.asarray(mesh.edge_faces)
    vertex_faces = np.asarray(mesh.vertex_faces)
    faces = np.asarray(mesh.faces)
    n = int(path.count)
    assert 2 <= n <= path.points.shape[0]
    pts = np.asarray(path.points, np.float64)[:n]
    kinds = np.asarray(path.kinds)[:n]
    elems = np.asarray(path.elements)[:n]
    params = np.asarray(path.params, np.float64)[:n]
    np.testing.assert_allclose(pts[0], a, atol=tol)
    np.testing.assert_allclose(pts[-1], b, atol=tol)
    assert kinds[0] == FACE and kinds[-1] == FACE
    around = []
    for p, k, el, u in zip(pts, kinds, elems, params):
        if k == EDGE:
            assert 0 <= u <= 1, f"edge parameter {u} outside [0, 1]"
            q = (1 - u) * v[edges[el, 0]] + u * v[edges[el, 1]]
            assert np.linalg.norm(p - q) <= tol, "crossing off its edge"
            around.append(set(edge_faces[el]) - {-1})
        elif k == VERTEX:
            assert np.linalg.norm(p - v[el]) <= tol, "vertex point off its vertex"
            around.append(set(vertex_faces[el]) - {-1})
        else:
            assert k == FACE
            # An endpoint is given by a face but may lie on its boundary: it is in
            # the closure of every face that contains it. The trace snaps an
            # endpoint whose barycentric coordinates are within param_tolerance of
            # an edge or vertex onto it (hypothesis found an endpoint 1e-9 of an
            # edge from a vertex, joined from a face of the vertex's ring), so
            # containment is up to that snap distance.
            inside = faces_containing(v, faces, p, tol + snap)
            assert int(el) in inside, "endpoint off its face"
            around.append(inside)
    for i, (f, g) in enumerate(zip(around[:-1], around[1:])):
        assert f & g, f"points {i} and {i + 1} share no face"
    length = float(path.length)
    rel = 1e-9 if dtype == np.float64 else 1e-5
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    np.testing.assert_allclose(length, seg, rtol=rel, atol=tol)
    assert length >= np.linalg.norm(b - a) * (1 - rel) - tol
    if exact is not None:
        assert length >= exact * (1 - rel) - tol, f"below the exact {exact}"


def solve_and_check(mesh_key, e1, e2, method, max_points=1024):
    mesh = make_mesh(mesh_key)
    a, i = endpoint(mesh, *e1)
    b, j = endpoint(mesh, *e2)
    dtype = np.asarray(mesh.vertices).dtype
    a, b = a.astype(dtype).astype(np.float64), b.astype(dtype).astype(np.float64)
    path = jg.shortest_path(
        mesh, a, b, method=method, throw=False, max_points=max_points
    )
    exact = None
    if i is not None and j is not None:
        exact = float(exact_solver(mesh_key).geodesicDistance(i, j)[0])
    check_path(mesh, a, b, path, exact)
    return path


# -------------------------------------------------------------------- strategies

unit = st.floats(0.0, 1.0)
endpoints = st.tuples(
    st.sampled_from(["vertex", "vertex", "face", "edge"]),
    st.integers(0, 10**6),
    st.tuples(unit, unit),
)


def mesh_keys(family: str, amplitude: float, noise: float):
    return st.tuples(
        st.just(family),
        st.integers(0, 2**16),
        st.floats(0.0, amplitude),
        st.floats(0.0, noise),
    )


SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow])


def success_rate(
    keys, method: str, max_points: int = 1024, **settings_kw
) -> tuple[float, int]:
    """Run hypothesis over (mesh key, endpoint, endpoint) draws from `keys`: every
    path must satisfy `check_path`'s invariants (a failure raises, shrunk), and the
    fraction of them that SUCCEED is returned with the number of examples, for the
    caller to assert: a property test that passed on failed paths alone would say
    nothing (`check_path` checks only the status of a failed path)."""
    outcomes = []

    @settings(**SETTINGS, **settings_kw)
    @given(keys, endpoints, endpoints)
    def run(mesh_key, e1, e2):
        path = solve_and_check(mesh_key, e1, e2, method, max_points)
        outcomes.append(int(path.status) == jg.Status.SUCCESS)

    run()
    return float(np.mean(outcomes)), len(outcomes)


def assert_rate(
    keys, method: str, at_least: float, max_points: int = 1024, **settings_kw
) -> None:
    rate, n = success_rate(keys, method, max_points, **settings_kw)
    print(f"{method}: {rate:.1%} of {n} paths succeeded")  # shown with -s / -rP
    wanted = settings_kw.get("max_examples", settings().max_examples)
    # hypothesis may stop early when it runs out of distinct examples; not here
    assert n >= min(wanted, 10), f"only {n} examples ran"
    assert rate >= at_least, f"{rate:.0%} of {n} paths succeeded, want ≥ {at_least:.0%}"


# Success rates. The exact method succeeds on every pair of a connected mesh,
# closed or open (its corridors come from the mesh graph, not from a ray).
# The laser ray (the paper's method) may stop with NO_CROSSING where the chord's
# projection leaves an open mesh (a concave boundary ahead) and cannot slide on,
# so on patches and tents the rate is stated, not total: measured 100 % of the
# `ci` profile's 90 examples (30 for float32) on every family (`pytest -m slow
# -rP tests/test_properties.py` prints the rates); 95 % leaves room for the
# `long` profile's random draws. On closed meshes it always continues.
LASER_RATE = {"sphere": 1.0, "patch": 0.95, "tent": 0.95, "patch32": 0.95}
EXACT_RATE = {"sphere": 1.0, "patch": 1.0, "tent": 1.0, "patch32": 1.0}
KEYS = {
    "sphere": mesh_keys("sphere", 0.15, 0.02),
    "patch": mesh_keys("patch", 0.6, 0.05),
    "tent": mesh_keys("tent", 0.5, 0.03),
    "patch32": mesh_keys("patch32", 0.6, 0.05),
}


def test_perturbed_sphere_few_examples():
    """The fast set's property test: 8 perturbed spheres and endpoint pairs, the
    default method, all succeed. The 162-vertex icosphere with the default
    `max_points`: the solver tests/test_exact.py and test_locate.py compile (one
    compile shared)."""
    assert_rate(KEYS["sphere"], "exact", 1.0, max_examples=8)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["exact", "laser"])
@pytest.mark.parametrize("family", ["sphere", "patch", "tent"])
def test_family(family, method):
    rates = EXACT_RATE if method == "exact" else LASER_RATE
    assert_rate(KEYS[family], method, rates[family])


@pytest.mark.slow
@pytest.mark.parametrize("method", ["exact", "laser"])
def test_height_patch_float32(method):
    """float32 meshes: the same invariants to float32 tolerances (1e-5 of the
    mesh scale; endpoints snapped within 1e-4)."""
    rates = EXACT_RATE if method == "exact" else LASER_RATE
    n = max(settings().max_examples // 3, 10)
    assert_rate(KEYS["patch32"], method, rates["patch32"], max_examples=n)


@pytest.mark.slow
@settings(**SETTINGS)
@given(
    st.one_of(
        mesh_keys("sphere", 0.15, 0.02),
        mesh_keys("patch", 0.6, 0.05),
        mesh_keys("tent", 0.5, 0.03),
    ),
    endpoints,
    endpoints,
)
# Regression (issue 7): at a vertex endpoint the trace left through another face
# of the vertex's ring than the located one; the laser corridor was dropped and
# both directions ended in a local geodesic 1.4e-3 longer than MMP and the laser.
@example(
    ("sphere", 20993, 0.04798913147553511, 0.004122244557342538),
    ("vertex", 474092, (0.0, 0.0)),
    ("vertex", 485678, (0.0, 0.0)),
)
# an endpoint 1e-10 of an edge from a vertex, snapped onto the vertex by the trace
# (found by the long profile: the laser path was 6e-12 shorter than the exact one)
@example(
    ("sphere", 0, 0.0, 0.0), ("face", 5104, (0.0, 0.0)), ("edge", 46, (1e-10, 0.0))
)
# Two locally shortest paths that differ at two cone vertices (99 and 8), neither of
# whose single detours is shorter: from the vertex the starts and detours ended
# 1.4e-5 above MMP (found by the CI's draw); the second detour round now starts
# from the runner-up when the best path's detours were tried already.
@example(
    ("sphere", 200, 0.06640625, 0.003179673680665665),
    ("vertex", 177, (0.0, 0.0)),
    ("face", 41, (0.125, 0.2578125)),
)
def test_exact_method_is_symmetric(mesh_key, e1, e2):
    forward = solve_and_check(mesh_key, e1, e2, method="exact")
    backward = solve_and_check(mesh_key, e2, e1, method="exact")
    # the success rate: all, on every family (EXACT_RATE)
    assert int(forward.status) == int(backward.status) == jg.Status.SUCCESS
    mesh = make_mesh(mesh_key)
    v = np.asarray(mesh.vertices, np.float64)
    edges = np.asarray(mesh.edges)
    longest = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1).max()
    # the trace snaps an endpoint within param_tolerance of an edge or vertex onto
    # it (see check_path), so the laser path may start and end that much closer
    snap = param_tolerance(v.dtype) * longest
    for path, (p, q) in ((forward, (e1, e2)), (backward, (e2, e1))):
        laser = solve_and_check(mesh_key, p, q, "laser")
        if int(path.status) == int(laser.status) == jg.Status.SUCCESS:
            # the refinement starts from the laser path's corridor and only ever
            # shortens it: never longer, up to rounding and the two snaps
            bound = float(laser.length) * (1 + 1e-12) + 2 * snap
            assert float(path.length) <= bound
    np.testing.assert_allclose(float(forward.length), float(backward.length), rtol=1e-9)
