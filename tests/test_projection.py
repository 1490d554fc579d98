"""System (16): the batched optimistix Newton solve against its residual and the
paper's fixed-point iteration."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgeo.normals import vertex_normals
from jaxgeo.projection import (
    quadratic_coefficients,
    residual,
    solve_crossing,
    solve_edges,
    solve_fixed_point,
)

from .helpers import unit_icosphere


def _random_mesh_and_chords(seed):
    """A perturbed icosphere (so normals are not radial) and random chords between
    points near its surface."""
    rng = np.random.default_rng(seed)
    mesh = unit_icosphere(2)
    v = np.asarray(mesh.vertices) * (
        1 + 0.05 * rng.standard_normal((mesh.n_vertices, 1))
    )
    mesh = mesh.with_vertices(jnp.asarray(v))
    a = rng.standard_normal((4, 3))
    b = rng.standard_normal((4, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    return mesh, a, b


def _edge_arrays(mesh):
    n = vertex_normals(mesh.vertices, mesh.faces)
    e = mesh.edges
    v = mesh.vertices
    return v[e[:, 0]], v[e[:, 1]], n[e[:, 0]], n[e[:, 1]]


solve_all = jax.jit(solve_edges)


def _residuals(cr, a, b, x1, x2, n1, n2):
    """Residual of (16) at both root lanes of every edge: (E, 2, 3)."""
    y = jnp.stack([cr.u, cr.t, cr.zeta], -1)

    def per_edge(yy, x1, x2, n1, n2):
        args = (a, b - a, x1, x2 - x1, n1, n2 - n1)
        return jax.vmap(lambda y1: residual(y1, args))(yy)

    return jax.vmap(per_edge)(y, x1, x2, n1, n2)


@pytest.mark.parametrize("seed", [0, 1])
def test_newton_solutions_have_tiny_residual(seed):
    mesh, a, b = _random_mesh_and_chords(seed)
    x1, x2, n1, n2 = _edge_arrays(mesh)
    for ai, bi in zip(a, b):
        cr = solve_all(jnp.asarray(ai), jnp.asarray(bi), x1, x2, n1, n2)
        assert int(cr.valid.sum()) > 0
        r = _residuals(cr, jnp.asarray(ai), jnp.asarray(bi), x1, x2, n1, n2)
        # Newton stops at 1e-12 (atol/rtol); the residual is a few ulps of the
        # unit-scale coordinates, far below the 1e-10 acceptance bound.
        worst = float(jnp.max(jnp.where(cr.valid[..., None], jnp.abs(r), 0.0)))
        assert worst <= 1e-10
        valid_u = np.asarray(cr.u)[np.asarray(cr.valid)]
        valid_t = np.asarray(cr.t)[np.asarray(cr.valid)]
        assert valid_u.min() >= 0 and valid_u.max() <= 1
        assert valid_t.min() >= -1e-9 and valid_t.max() <= 1 + 1e-9


@pytest.mark.parametrize("seed", [0, 1])
def test_newton_agrees_with_fixed_point(seed):
    mesh, a, b = _random_mesh_and_chords(seed)
    x1, x2, n1, n2 = _edge_arrays(mesh)
    fixed_point = jax.jit(jax.vmap(solve_fixed_point, in_axes=(None, None, 0, 0, 0, 0)))
    compared = 0
    for ai, bi in zip(a, b):
        ai, bi = jnp.asarray(ai), jnp.asarray(bi)
        cr = solve_all(ai, bi, x1, x2, n1, n2)
        yf, conv = fixed_point(ai, bi, x1, x2, n1, n2)
        yn = jnp.stack([cr.u, cr.t, cr.zeta], -1)  # (E, 2, 3)
        # The fixed point converges to one root; compare with the nearer Newton root.
        diff = jnp.max(jnp.abs(yn - yf[:, None, :]), axis=-1)
        diff = jnp.where(cr.found, diff, jnp.inf).min(axis=1)
        inside = (yf[:, 0] >= 0) & (yf[:, 0] <= 1) & (yf[:, 1] >= 0) & (yf[:, 1] <= 1)
        both = conv & inside & jnp.any(cr.valid, axis=1)
        compared += int(both.sum())
        # Both solvers stop at ~1e-13 relative; 1e-8 leaves room for the
        # conditioning of (16) on edges nearly parallel to the chord's plane.
        assert float(jnp.max(jnp.where(both, diff, 0.0))) <= 1e-8
    assert compared >= 20


def test_quadratic_roots_solve_the_system():
    """The closed form: g(u) = 0 at the Newton solutions (coplanarity)."""
    mesh, a, b = _random_mesh_and_chords(3)
    x1, x2, n1, n2 = _edge_arrays(mesh)
    ai, bi = jnp.asarray(a[0]), jnp.asarray(b[0])
    cr = solve_all(ai, bi, x1, x2, n1, n2)
    c0, c1, c2, scale = jax.vmap(
        quadratic_coefficients, in_axes=(None, None, 0, 0, 0, 0)
    )(ai, bi, x1, x2, n1, n2)
    g = c0[:, None] + c1[:, None] * cr.u + c2[:, None] * cr.u**2
    assert float(jnp.max(jnp.where(cr.valid, jnp.abs(g) / scale[:, None], 0))) < 1e-12


def test_edge_along_the_chord_is_degenerate_not_valid():
    """An edge in the plane of the chord and its normals has a one-parameter family
    of solutions: it is flagged degenerate, never valid."""
    x1 = jnp.array([[0.0, 0.0, 0.0]])
    x2 = jnp.array([[1.0, 0.0, 0.0]])
    n = jnp.array([[0.0, 0.0, 1.0]])
    cr = solve_edges(jnp.array([-1.0, 0, 0.5]), jnp.array([2.0, 0, 0.5]), x1, x2, n, n)
    assert bool(cr.degenerate[0]) and not bool(cr.valid.any())


@pytest.mark.slow  # 13 s niced beside CI: among the fast set's longest (12-08)
def test_solve_crossing_gradient_is_finite_and_matches_fd():
    mesh, a, b = _random_mesh_and_chords(4)
    x1, x2, n1, n2 = _edge_arrays(mesh)
    ai, bi = jnp.asarray(a[0]), jnp.asarray(b[0])
    cr = solve_all(ai, bi, x1, x2, n1, n2)
    e, r = np.argwhere(np.asarray(cr.valid))[0]
    y0 = jnp.array([cr.u[e, r], cr.t[e, r], cr.zeta[e, r]])

    def u_of(a_):
        return solve_crossing(a_, bi, x1[e], x2[e], n1[e], n2[e], y0)[0][0]

    g = jax.grad(u_of)(ai)
    d = jnp.array([0.3, -0.2, 0.5])
    h = 1e-6
    fd = (u_of(ai + h * d) - u_of(ai - h * d)) / (2 * h)
    assert jnp.all(jnp.isfinite(g))
    # Central differences: O(h²) truncation plus O(eps/h) roundoff ≈ 1e-10.
    assert abs(float(g @ d - fd)) <= 1e-7 * max(1.0, abs(float(fd)))
