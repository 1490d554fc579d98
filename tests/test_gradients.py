"""Gradients of path lengths and points (issue 4): reverse mode (`jax.grad`,
`jax.jacrev`), forward mode (`jax.jvp`) and `jax.vmap`, against central finite
differences, on a sphere, a catenoid and a cone tent.

Compile time dominates this file, so the three surfaces share one connectivity (the
ring grid of `surfaces.catenoid`/`surfaces.cone_tent`; the sphere is a zone of the
unit sphere on that grid) and every jitted function below compiles once for all of
them.

Tolerance (relative error of a directional derivative ≤ 1e-6). Directions are
unit vectors, the vertex ones supported on the vertices the length depends on. A
central difference with step h = 1e-6 has truncation error h²/6·|f'''| ≈ 2e-11
(|f'''| = O(1/edge²) ≈ 1e2 on these meshes) and roundoff ≈ k·eps·|L|/h ≈ 1e-9
absolute (|L| ≈ 1, k ≈ 10 rounding errors in the replayed polyline). The Newton
solves converge quadratically past their 1e-12 stopping test, so they add only
rounding. The directional derivatives are 1e-2 to 1, hence ≲ 1e-7 relative
(measured: at most 7e-8); 1e-6 keeps a margin and still catches any missing
term of the gradient (those are O(1) relative).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import surfaces
from jaxgeo.path import EDGE, VERTEX
from jaxgeo.replay import replay

N_AROUND, N_RINGS = 24, 10  # 480 faces
MAX_POINTS = 64
H = 1e-6  # finite-difference step
RTOL = 1e-6  # see the module docstring
N_DIRECTIONS = 8
VERTEX_MARGIN = 1e-3  # crossings at least this fraction of an edge from a vertex
CASES = ["sphere", "catenoid", "cone"]


# --------------------------------------------------------------------------- meshes


@functools.cache
def ring_mesh(name: str) -> jg.Mesh:
    v, f = surfaces.catenoid(N_AROUND, N_RINGS)
    if name == "cone":
        v, f_cone = surfaces.cone_tent(N_AROUND, N_RINGS)
        assert (f_cone == f).all()
    elif name == "sphere":
        # the catenoid's rings moved onto the unit sphere, |z| ≤ 0.8
        theta = np.arctan2(v[:, 1], v[:, 0])
        z = 1.6 * v[:, 2]  # catenoid z ∈ [-0.5, 0.5]
        r = np.sqrt(1 - z**2)
        v = np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)
    return jg.Mesh(v, f)


# ------------------------------------------------------------- compiled functions


def _length_points(vertices, mesh, p1, p2):
    path = jg.shortest_path(mesh.with_vertices(vertices), p1, p2, max_points=MAX_POINTS)
    return path.length, path


def _length_bary(vertices, mesh, f1, b1, f2, b2):
    start, end = jg.SurfacePoint(f1, b1), jg.SurfacePoint(f2, b2)
    return _length_points(vertices, mesh, start, end)


def _points_bary(vertices, mesh, f1, b1, f2, b2):
    path = _length_bary(vertices, mesh, f1, b1, f2, b2)[1]
    return {"length": path.length, "points": path.points}, path


@jax.jit
def derivatives_points(vertices, mesh, p1, p2, dv, d1, d2):
    """Value, path, `jax.grad` w.r.t. (vertices, p1, p2) and the `jax.jvp` along
    (dv, d1, d2), in one compiled function (one trace to compile, not two). Also
    the function evaluated for finite differences."""
    (length, path), grads = jax.value_and_grad(
        _length_points, argnums=(0, 2, 3), has_aux=True
    )(vertices, mesh, p1, p2)
    f = lambda v, a, b: _length_points(v, mesh, a, b)[0]  # noqa: E731
    _, tangent = jax.jvp(f, (vertices, p1, p2), (dv, d1, d2))
    return length, path, grads, tangent


def grad_points(vertices, mesh, p1, p2):
    zero = np.zeros(3)
    length, path, grads, _ = derivatives_points(
        vertices, mesh, p1, p2, np.zeros_like(vertices), zero, zero
    )
    return length, path, grads


# `jax.jacrev` w.r.t. (vertices, b1, b2) of the length (its gradient) and of the
# points, and the path (its points are also the value for finite differences)
jacobians_bary = jax.jit(jax.jacrev(_points_bary, argnums=(0, 3, 5), has_aux=True))
batched_grad_points = jax.jit(
    jax.vmap(
        jax.value_and_grad(_length_points, argnums=(0, 2, 3), has_aux=True),
        in_axes=(None, None, 0, 0),
    )
)


# ------------------------------------------------------------------- test cases


def crossings_clear_of_vertices(path: jg.Path) -> bool:
    """All interior points are edge crossings at least VERTEX_MARGIN of the edge
    length from either end (u is the fraction of the edge)."""
    c = int(path.count)
    kinds, u = np.asarray(path.kinds)[1 : c - 1], np.asarray(path.params)[1 : c - 1]
    return bool((kinds == EDGE).all() and (np.minimum(u, 1 - u) >= VERTEX_MARGIN).all())


def face_normal(mesh: jg.Mesh, face: int) -> np.ndarray:
    a, b, c = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[face]]
    n = np.cross(b - a, c - a)
    return n / np.linalg.norm(n)


def bary_jacobians(vertices, mesh, f1, b1, f2, b2):
    """`(length, path, d length, d points)`, derivatives w.r.t. (vertices, b1, b2)."""
    jac, path = jacobians_bary(vertices, mesh, np.int32(f1), b1, np.int32(f2), b2)
    return path.length, path, jac["length"], jac["points"]


@functools.cache
def endpoint_pair(name: str, seed: int = 0):
    """Random endpoints (faces, barycentrics) whose path succeeds, has at least 5
    crossings and keeps them clear of vertices, so that the length is smooth around
    them. Also 3-D versions, lifted off the face by 1 % of an edge so that the
    projection onto the mesh (`jg.locate`) is part of what is differentiated."""
    mesh = ring_mesh(name)
    rng = np.random.default_rng(seed)
    for _ in range(200):
        faces = rng.integers(0, mesh.n_faces, 2)
        bary = 0.1 + 0.8 * rng.dirichlet([2.0, 2.0, 2.0], 2)
        bary /= bary.sum(1, keepdims=True)
        path = bary_jacobians(
            mesh.vertices, mesh, faces[0], bary[0], faces[1], bary[1]
        )[1]
        if int(path.status) == 0 and int(path.count) >= 7:
            if crossings_clear_of_vertices(path):
                break
    else:
        raise AssertionError(f"no suitable endpoint pair on {name}")
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[faces]]
    lift = 0.01 * float(mesh.mean_edge_length)
    points = [
        bary[i] @ corners[i] + lift * face_normal(mesh, faces[i]) for i in range(2)
    ]
    return faces, bary, points


def directions(shape, seed: int, zero_sum: bool = False, support=None):
    """N_DIRECTIONS random unit directions. `support`: a mask of the rows (vertices)
    that may move; elsewhere the derivative is exactly zero and moving them only
    adds roundoff to the finite differences."""
    rng = np.random.default_rng(seed)
    ds = [rng.standard_normal(shape) for _ in range(N_DIRECTIONS)]
    if support is not None:
        ds = [d * np.asarray(support)[:, None] for d in ds]
    if zero_sum:  # stay in the plane of the face: barycentrics keep summing to 1
        ds = [d - d.mean(axis=-1, keepdims=True) for d in ds]
    return [d / np.linalg.norm(d) for d in ds]  # unit steps: see the docstring


def central_difference(f, x, d):
    return (f(x + H * d) - f(x - H * d)) / (2 * H)


def relative_error(approx, exact) -> float:
    approx, exact = np.asarray(approx), np.asarray(exact)
    return float(np.linalg.norm(approx - exact) / np.linalg.norm(exact))


def contract(jacobian, direction):
    """A Jacobian `(..., *x.shape)` applied to a direction of shape `x.shape`."""
    d = np.asarray(direction)
    return np.tensordot(np.asarray(jacobian), d, axes=d.ndim)


# ------------------------------------------------------------------------- tests


@pytest.mark.parametrize("name", ["sphere", "cone"])
@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_grad_of_path_length_on_the_shared_connectivity(name):
    """The fast set's part: `jax.grad` of `path_length` w.r.t. the vertices and
    the start's barycentrics, against central differences, on the sphere zone and
    the cone tent. The same function, connectivity and `max_points` (256) as
    tests/test_exact.py's gradient test on the catenoid, so the compiled
    derivative is shared; tolerance as in the module docstring, plus 1e-9
    absolute for derivatives near zero (roundoff of the differences)."""
    from jaxgeo.locate import SurfacePoint

    mesh = ring_mesh(name)
    faces = np.asarray(mesh.faces)
    end = SurfacePoint(
        jnp.asarray(int(faces.shape[0] * 0.6)), jnp.asarray([0.3, 0.3, 0.4])
    )
    face = jnp.asarray(3)

    def length(vertices, bary):
        m = mesh.with_vertices(vertices)
        return jg.path_length(m, SurfacePoint(face, bary), end, max_points=256)

    v0, b0 = mesh.vertices, jnp.asarray([0.2, 0.5, 0.3])
    gv, gb = jax.grad(length, argnums=(0, 1))(v0, b0)
    moving = np.abs(np.asarray(gv)).sum(1) > 0
    assert moving.sum() >= 6  # the path crosses several faces
    for d in directions(v0.shape, seed=1, support=moving)[:3]:
        fd = float(central_difference(lambda v: length(v, b0), v0, jnp.asarray(d)))
        assert abs(fd - float(jnp.sum(gv * d))) <= RTOL * abs(fd) + 1e-9
    db = jnp.asarray([1.0, -1.0, 0.0]) / np.sqrt(2)
    fd = float(central_difference(lambda b: length(v0, b), b0, db))
    assert abs(fd - float(gb @ db)) <= RTOL * abs(fd) + 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_grad_and_jvp_with_3d_endpoints(name):
    """`jax.grad` w.r.t. the vertices and each 3-D endpoint, and `jax.jvp` along
    all three at once, against central differences."""
    mesh = ring_mesh(name)
    _, _, (p1, p2) = endpoint_pair(name)
    v0 = np.asarray(mesh.vertices)
    _, path, (gv, g1, g2) = grad_points(v0, mesh, p1, p2)
    assert int(path.status) == 0 and crossings_clear_of_vertices(path)

    def length(v, a, b):
        return float(grad_points(v, mesh, a, b)[0])

    errors = {"vertices": [], "p1": [], "p2": [], "jvp": []}
    moving = np.abs(gv).sum(1) > 0  # the vertices the length depends on
    for d in directions(v0.shape, seed=1, support=moving):
        fd = central_difference(lambda v: length(v, p1, p2), v0, d)
        errors["vertices"].append(relative_error(np.vdot(gv, d), fd))
    for d in directions(3, seed=2):
        fd1 = central_difference(lambda a: length(v0, a, p2), p1, d)
        fd2 = central_difference(lambda b: length(v0, p1, b), p2, d)
        errors["p1"].append(relative_error(g1 @ d, fd1))
        errors["p2"].append(relative_error(g2 @ d, fd2))
    for dv, d12 in zip(
        directions(v0.shape, seed=3, support=moving), directions((2, 3), seed=4)
    ):
        *_, tangent = derivatives_points(v0, mesh, p1, p2, dv, d12[0], d12[1])
        fd = (
            length(v0 + H * dv, p1 + H * d12[0], p2 + H * d12[1])
            - length(v0 - H * dv, p1 - H * d12[0], p2 - H * d12[1])
        ) / (2 * H)
        errors["jvp"].append(relative_error(tangent, fd))
    worst = {k: max(e) for k, e in errors.items()}
    assert max(worst.values()) <= RTOL, worst


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_jacrev_with_barycentric_endpoints(name):
    """`jax.jacrev` of the length and of every point of the path w.r.t. the
    vertices and both endpoints' barycentrics (perturbed within the face's plane),
    against central differences."""
    mesh = ring_mesh(name)
    (f1, f2), (b1, b2), _ = endpoint_pair(name)
    v0 = np.asarray(mesh.vertices)
    _, path, dlength, dpoints = bary_jacobians(v0, mesh, f1, b1, f2, b2)
    count = int(path.count)

    def evaluate(x):
        path = bary_jacobians(x[0], mesh, f1, x[1], f2, x[2])[1]
        return np.concatenate([[path.length], np.ravel(path.points[:count])])

    x0 = (v0, b1, b2)
    errors = {"vertices": [], "b1": [], "b2": []}
    dirs = [
        directions(v0.shape, seed=5, support=np.abs(dlength[0]).sum(1) > 0),
        directions(3, seed=6, zero_sum=True),
        directions(3, seed=7, zero_sum=True),
    ]
    for arg, key in enumerate(errors):
        for d in dirs[arg]:
            plus = [x + H * d if i == arg else x for i, x in enumerate(x0)]
            minus = [x - H * d if i == arg else x for i, x in enumerate(x0)]
            fd = (evaluate(plus) - evaluate(minus)) / (2 * H)
            exact = np.concatenate(
                [
                    [contract(dlength[arg], d)],
                    np.ravel(contract(dpoints[arg], d)[:count]),
                ]
            )
            errors[key].append(relative_error(exact[0], fd[0]))
            errors[key].append(relative_error(exact[1:], fd[1:]))
    worst = {k: max(e) for k, e in errors.items()}
    assert max(worst.values()) <= RTOL, worst


@pytest.mark.slow
def test_vmap_of_gradient_equals_single_gradients():
    mesh = ring_mesh("catenoid")
    rng = np.random.default_rng(8)
    faces = rng.integers(0, mesh.n_faces, (16, 2))
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[faces]]  # (16,2,3,3)
    bary = rng.dirichlet([2.0, 2.0, 2.0], (16, 2))
    pts = np.einsum("nki,nkij->nkj", bary, corners)
    v0 = np.asarray(mesh.vertices)
    (lengths, paths), grads = batched_grad_points(v0, mesh, pts[:, 0], pts[:, 1])
    assert (np.asarray(paths.status) == 0).sum() >= 12  # mostly complete paths
    for i in range(16):
        length, _, single = grad_points(v0, mesh, pts[i, 0], pts[i, 1])
        np.testing.assert_allclose(lengths[i], length, rtol=1e-12)
        for batched, one in zip(grads, single):
            assert np.isfinite(batched[i]).all()
            np.testing.assert_allclose(batched[i], one, rtol=1e-10, atol=1e-12)


MERIDIAN = (2 * N_AROUND + 3, 8 * N_AROUND + 3)


@pytest.mark.slow
def test_gradient_finite_through_a_vertex_under_jit():
    """Two vertices on one meridian of the catenoid, six rings apart: by symmetry
    the path alternates between the midpoint of an edge and a mesh vertex, where
    the length is not differentiable. The derivatives (one-sided, for the current
    vertex sequence) must be finite, in reverse and forward mode, with the
    endpoints as 3-D points and as barycentrics (1, 0, 0)."""
    mesh = ring_mesh("catenoid")
    v0 = np.asarray(mesh.vertices)
    p1, p2 = v0[MERIDIAN[0]], v0[MERIDIAN[1]]
    ones = np.ones(3)
    length, path, grads, tangent = derivatives_points(
        v0, mesh, p1, p2, np.ones_like(v0), ones, ones
    )
    c = int(path.count)
    assert int(path.status) == 0
    assert (np.asarray(path.kinds)[1 : c - 1] == VERTEX).sum() >= 2
    assert all(np.isfinite(g).all() for g in grads) and np.isfinite(tangent)
    assert np.abs(grads[0]).max() > 0
    faces = np.asarray(mesh.faces)
    fb = []
    for vertex in MERIDIAN:
        face = int(np.flatnonzero((faces == vertex).any(1))[0])
        fb += [face, (faces[face] == vertex).astype(float)]
    length_b, _, dlength, dpoints = bary_jacobians(v0, mesh, *fb)
    np.testing.assert_allclose(length_b, length, rtol=1e-12)
    assert all(np.isfinite(g).all() for g in (*dlength, *dpoints))


@pytest.mark.slow
def test_gradient_finite_through_a_vertex_eager():
    mesh = ring_mesh("catenoid")
    p1, p2 = np.asarray(mesh.vertices)[list(MERIDIAN)]
    grad = jax.grad(lambda v: jg.path_length(mesh.with_vertices(v), p1, p2))(
        mesh.vertices
    )
    assert jnp.isfinite(grad).all() and jnp.abs(grad).max() > 0


@pytest.mark.slow
def test_incomplete_path_replays_its_last_crossing():
    """A path that stopped early (here a complete one cut to 5 points and marked
    MAX_STEPS) ends at its last crossing, not at point 2: the replay re-solves
    that crossing instead of putting point 2 there.

    `replay` is the laser's (it re-solves each crossing by the ray's equations),
    so the path is the laser's: the exact default's crossings lie on the
    straightened geodesic, not on the ray, and do not replay."""
    mesh = ring_mesh("catenoid")
    (f1, f2), (b1, b2), _ = endpoint_pair("catenoid")
    path = jg.shortest_path(
        mesh,
        jg.SurfacePoint(jnp.asarray(f1), jnp.asarray(b1)),
        jg.SurfacePoint(jnp.asarray(f2), jnp.asarray(b2)),
        method="laser",
        max_points=MAX_POINTS,
    )
    assert int(path.status) == 0 and int(path.count) > 5
    cut = eqx.tree_at(
        lambda p: (p.count, p.status),
        path,
        (jnp.asarray(5, jnp.int32), jnp.asarray(jg.Status.MAX_STEPS, jnp.int32)),
    )
    start = jg.SurfacePoint(jnp.asarray(f1), jnp.asarray(b1))
    end = jg.SurfacePoint(jnp.asarray(f2), jnp.asarray(b2))
    normals = jg.vertex_normals(mesh.vertices, mesh.faces)
    replayed = jax.jit(replay)(mesh, normals, start, end, cut)
    np.testing.assert_allclose(replayed.points[:5], path.points[:5], atol=1e-12)
    segments = np.diff(np.asarray(path.points)[:5], axis=0)
    np.testing.assert_allclose(replayed.length, np.linalg.norm(segments, axis=1).sum())


@pytest.mark.slow
def test_gradient_finite_for_coincident_endpoints():
    """Zero length: the norm of a zero segment must not give a NaN gradient."""
    mesh = ring_mesh("catenoid")
    v0 = np.asarray(mesh.vertices)
    p = v0[np.asarray(mesh.faces)[100]].mean(axis=0)
    length, _, grads = grad_points(v0, mesh, p, p)
    assert float(length) == 0.0
    assert all(np.isfinite(g).all() for g in grads)
