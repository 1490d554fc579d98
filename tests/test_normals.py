"""Phong normals: eq. (8)–(9) by hand, the area and angle options, accuracy on a
sphere, the second-order fit at boundary vertices, finite gradients, and eq. (10)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

from jaxgeo import validation
from jaxgeo._errors import JaxgeoError
from jaxgeo.mesh import Mesh
from jaxgeo.normals import (
    edge_normal,
    face_normals,
    fit_boundary_normals,
    vertex_normals,
)
from jaxgeo.surfaces import catenoid_parameter

WEIGHTINGS = ["uniform", "area", "angle"]


@jax.jit
def all_normals(v, f):
    """The three weightings in one compiled call: (3, V, 3), in WEIGHTINGS order."""
    return jnp.stack([vertex_normals(v, f, w) for w in WEIGHTINGS])


# The corner of a box with edges a, b, c along the axes: three right triangles
# around vertex 0, oriented so that their normals are −z, −x, −y.
A, B, C = 1.0, 2.0, 3.0
CORNER_V = np.array([[0.0, 0, 0], [A, 0, 0], [0, B, 0], [0, 0, C]])
CORNER_F = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 3]])


def unit(x):
    x = np.asarray(x, dtype=float)
    return x / np.linalg.norm(x)


def test_face_normals_of_the_corner():
    n = np.asarray(face_normals(CORNER_V, CORNER_F))
    np.testing.assert_allclose(n, [[0, 0, -1], [-1, 0, 0], [0, -1, 0]], atol=1e-15)
    # unit=False: length is twice the area
    raw = np.asarray(face_normals(CORNER_V, CORNER_F, unit=False))
    np.testing.assert_allclose(
        np.linalg.norm(raw, axis=1), [A * B, B * C, C * A], rtol=1e-15
    )


def test_uniform_is_eq_8_9_by_hand():
    """Eq. (8): a = Σ n_f over the faces at the vertex (unit normals, no weights);
    eq. (9): n = a / |a|. At the box corner the three unit normals are −x, −y, −z
    whatever a, b, c are; at vertex 1 = (a, 0, 0) two faces meet, −z and −y."""
    n = np.asarray(all_normals(CORNER_V, CORNER_F)[0])
    np.testing.assert_allclose(n[0], -np.ones(3) / np.sqrt(3), atol=1e-15)
    np.testing.assert_allclose(n[1], [0, -1 / np.sqrt(2), -1 / np.sqrt(2)], atol=1e-15)
    np.testing.assert_allclose(n[2], [-1 / np.sqrt(2), 0, -1 / np.sqrt(2)], atol=1e-15)
    np.testing.assert_allclose(n[3], [-1 / np.sqrt(2), -1 / np.sqrt(2), 0], atol=1e-15)


def test_area_weighting_by_hand():
    """Weights = face areas ab/2, bc/2, ca/2 on −z, −x, −y: at the corner
    −(bc, ca, ab) / |·| = −(6, 3, 2) / 7 for (a, b, c) = (1, 2, 3)."""
    n = np.asarray(all_normals(CORNER_V, CORNER_F)[1])
    np.testing.assert_allclose(n[0], -np.array([6.0, 3.0, 2.0]) / 7.0, atol=1e-15)
    # vertex 1: face (0, 2, 1) (area ab/2 = 1, −z) and face (0, 1, 3) (ca/2 = 1.5, −y)
    np.testing.assert_allclose(n[1], -unit([0.0, 1.5, 1.0]), atol=1e-15)


def test_angle_weighting_by_hand():
    """Weights = corner angles. At the corner all three are π/2 (same as uniform);
    at vertex 1 = (a, 0, 0) the angles are atan(b/a) in the −z face and atan(c/a)
    in the −y face."""
    n = np.asarray(all_normals(CORNER_V, CORNER_F)[2])
    np.testing.assert_allclose(n[0], -np.ones(3) / np.sqrt(3), atol=1e-15)
    expected = -unit([0.0, np.arctan(C / A), np.arctan(B / A)])
    np.testing.assert_allclose(n[1], expected, atol=1e-15)


def loop_normals(v, f, weighting):
    """Reference: a plain loop over the faces, one corner at a time."""
    out = np.zeros_like(v)
    for face in f:
        for i in range(3):
            p, q, r = v[face[i]], v[face[(i + 1) % 3]], v[face[(i + 2) % 3]]
            cross = np.cross(v[face[1]] - v[face[0]], v[face[2]] - v[face[0]])
            if weighting == "uniform":
                w = unit(cross)
            elif weighting == "area":
                w = 0.5 * cross
            else:
                cos = np.dot(unit(q - p), unit(r - p))
                w = np.arccos(np.clip(cos, -1, 1)) * unit(cross)
            out[face[i]] += w
    return out / np.linalg.norm(out, axis=1, keepdims=True)


@pytest.mark.parametrize("weighting", WEIGHTINGS)
def test_weightings_match_a_loop_on_a_random_pyramid(weighting):
    """An irregular fan (apex over a random star-shaped base) where the three
    weightings all differ."""
    rng = np.random.default_rng(1)
    k = 7
    angles = np.sort(rng.uniform(0, 2 * np.pi, k))
    base = np.stack(
        [
            rng.uniform(0.5, 2, k) * np.cos(angles),
            rng.uniform(0.5, 2, k) * np.sin(angles),
            rng.uniform(-0.3, 0.3, k),
        ],
        1,
    )
    v = np.concatenate([[[0.1, -0.2, 1.0]], base])
    f = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    every = np.asarray(all_normals(v, f))
    i = WEIGHTINGS.index(weighting)
    got = every[i]
    np.testing.assert_allclose(got, loop_normals(v, f, weighting), atol=1e-14)
    # and the three options really are different at the apex
    others = np.delete(every, i, axis=0)
    assert (np.linalg.norm(others[:, 0] - got[0], axis=1) > 1e-3).all()


@pytest.mark.mistyped
@pytest.mark.parametrize(
    "vertices, faces, pattern",
    [
        (CORNER_V[:, :2], CORNER_F, r"vertices must have shape \(V, 3\), got \(4, 2\)"),
        (CORNER_V.astype(int), CORNER_F, "vertices must be floating point"),
        (CORNER_V, CORNER_F[:, :2], r"faces must have shape \(F, 3\)"),
        (CORNER_V, CORNER_F.astype(float), "faces must be an integer array"),
    ],
)
def test_bad_arguments(vertices, faces, pattern):
    with pytest.raises(JaxgeoError, match=pattern):
        vertex_normals(vertices, faces)
    with pytest.raises(JaxgeoError, match=pattern):
        face_normals(vertices, faces)


@pytest.mark.mistyped
def test_unknown_weighting():
    with pytest.raises(JaxgeoError, match="unknown normal weighting 'mean'"):
        vertex_normals(CORNER_V, CORNER_F, "mean")


# ------------------------------------------------------------------- on a sphere
#
# Where the error comes from: the plane of a face inscribed in a sphere is at
# distance d from the centre, and its normal points at the centre of the face's
# circumcircle, i.e. along the radius through the circumcentre c_f, an O(h) step
# from the vertex p. So every face normal deviates from p's radial direction by
# (c_f − p)_tangential / R + O(h²), and their (weighted) mean deviates by the mean
# tangential offset of the circumcentres, which is O(h) in general and cancels to
# O(h²) only when the fan is point-symmetric about p (Meek & Walton, CAGD 17
# (2000), for the same statement about averaged normals on sampled surfaces).
#
# trimesh's icosphere is built by recursive midpoint subdivision and projection:
# its fans never become symmetric (the worst are the six-valent neighbours of the
# twelve five-valent vertices), so the maximal error is O(h) there, not O(h²).
# Measured max |n − r̂| / (h / R), h the longest edge, subdivisions 3…5:
#   uniform 0.050, 0.053, 0.053;  area 0.072, 0.072, 0.071;  angle 0.032, 0.032, 0.032
# The twelve five-valent vertices themselves are exactly radial (5-fold symmetry).
ICOSPHERE_C = {"uniform": 0.06, "area": 0.08, "angle": 0.04}


def icosphere(subdivisions, radius=1.0):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    v = np.asarray(s.vertices)
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return v, np.asarray(s.faces)


@functools.lru_cache
def icosphere_normals(subdivisions, radius):
    v, f = icosphere(subdivisions, radius)
    return v, f, np.asarray(all_normals(v, f))


def longest_edge(v, f):
    return max(
        np.linalg.norm(v[f[:, i]] - v[f[:, i - 1]], axis=1).max() for i in range(3)
    )


@pytest.mark.parametrize("weighting", WEIGHTINGS)
def test_icosphere_normals_are_radial_to_first_order(weighting):
    radius = 2.5
    errors = []
    for k in (3, 4):
        v, f, every = icosphere_normals(k, radius)
        n = every[WEIGHTINGS.index(weighting)]
        err = np.linalg.norm(n - v / radius, axis=1)
        h = longest_edge(v, f)
        assert err.max() <= ICOSPHERE_C[weighting] * h / radius
        assert err[:12].max() < 1e-14  # the icosahedron's own vertices
        errors.append(err.max())
    # first order: halving h halves the worst error (a rate near 2, not 4)
    assert 1.7 < errors[0] / errors[1] < 2.3


@functools.lru_cache
def spherical_cap(n, radius=1.0, half=0.4):
    """The unit sphere's cap over [−half, half]² as a height field sampled on a
    regular grid of split squares: every interior fan is point-symmetric in (x, y)."""
    xs = np.linspace(-half, half, n + 1)
    x, y = (g.ravel() for g in np.meshgrid(xs, xs, indexing="ij"))
    v = np.stack([x, y, np.sqrt(radius**2 - x**2 - y**2)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    interior = idx[1:-1, 1:-1].ravel()
    return v, f, interior, 2 * half / n, np.asarray(all_normals(v, f))


@pytest.mark.parametrize("weighting", WEIGHTINGS)
def test_symmetric_fans_are_second_order(weighting):
    """On point-symmetric fans the first-order terms cancel: the error is O(h²).
    Measured max |n − r̂| / h² (h the grid step, R = 1) for n = 16 … 64:
    uniform 0.36–0.44, area 0.62–0.76, angle 0.25–0.30; all below 1 · h² / R²."""
    errors = []
    for n in (16, 32):
        v, f, interior, h, every = spherical_cap(n)
        normals = every[WEIGHTINGS.index(weighting)]
        err = np.linalg.norm(normals - v, axis=1)[interior].max()
        assert err <= 1.0 * h**2
        errors.append(err)
    assert errors[0] / errors[1] > 3.2  # → 4 as h → 0; measured 3.5 here


# ------------------------------------------------------------ boundary vertices
#
# At a boundary vertex the fan is one-sided: nothing cancels and eq. (8)–(9) is
# O(h) off on any mesh. `fit_boundary_normals` fits a quadratic height function to
# the vertex's two-ring instead, which recovers the tangent plane to O(h²).


def _valence(f, n):
    return np.bincount(np.asarray(f).ravel(), minlength=n)


def _on_boundary(v, f):
    m = Mesh(v, f)
    ef, e = np.asarray(m.edge_faces), np.asarray(m.edges)
    b = np.zeros(len(v), bool)
    b[e[ef[:, 1] < 0].ravel()] = True
    return m, b


def test_boundary_fit_is_exact_on_a_quadratic():
    """A quadratic height field z = q(x, y), fitted in the frame of the given normal
    e_z, is reproduced exactly: the fitted normals at the boundary (the two corners
    with a single face included: their two-ring holds 7 points) are the surface's
    to rounding; interior vertices are untouched."""
    v, f, *_ = spherical_cap(8)
    x, y = v[:, 0], v[:, 1]
    v = np.stack([x, y, 0.3 * x * x - 0.5 * x * y + 0.2 * y * y + 0.1 * x], 1)
    m, b = _on_boundary(v, f)
    assert (_valence(f, len(v))[b] == 1).sum() == 2
    given = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    got = np.asarray(fit_boundary_normals(m, jnp.asarray(given)))
    exact = np.stack([-(0.6 * x - 0.5 * y + 0.1), -(-0.5 * x + 0.4 * y), 1 + 0 * x], 1)
    exact /= np.linalg.norm(exact, axis=1, keepdims=True)
    np.testing.assert_allclose(got[b], exact[b], atol=1e-13)
    np.testing.assert_array_equal(got[~b], given[~b])


def _catenoid_normal(v):
    """The analytic unit normal of validation's catenoid r = c·cosh(z/c)."""
    c = catenoid_parameter()
    th = np.arctan2(v[:, 1], v[:, 0])
    n = np.stack([np.cos(th), np.sin(th), -np.sinh(v[:, 2] / c)], 1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_boundary_normals_are_second_order():
    """On the validation catenoid's rings (levels 4, 5) eq. (8)–(9) is first order,
    measured max |n − n*| = 0.40·h; the fit is second order, 1.16·h² and 1.27·h²
    (h the mean edge length), falling 3.6× per halving of h (→ 4)."""
    err_fit, err_fan = [], []
    for level in (4, 5):
        v, f = validation.catenoid_mesh(level)
        m, b = _on_boundary(v, f)
        h = float(m.mean_edge_length)
        fan = vertex_normals(v, f)
        fit = np.asarray(fit_boundary_normals(m, fan))
        exact = _catenoid_normal(v)
        e_fit = np.linalg.norm(fit - exact, axis=1)[b].max()
        e_fan = np.linalg.norm(np.asarray(fan) - exact, axis=1)[b].max()
        assert e_fan >= 0.3 * h  # first order (the reason for the fit)
        assert e_fit <= 2.0 * h**2
        err_fit.append(e_fit)
        err_fan.append(e_fan)
    assert err_fit[0] / err_fit[1] > 3.2  # second order: → 4
    assert 1.8 < err_fan[0] / err_fan[1] < 2.2  # first order: → 2


def test_boundary_fit_on_a_spherical_cap():
    """All boundary vertices of the cap (n = 16) are within 0.1·h² of the radial
    normal after the fit (measured 0.059·h²; 0.107·h² at n = 8, 0.032·h² at
    n = 32); eq. (8)–(9) there is at least 0.53·h off."""
    v, f, interior, h, every = spherical_cap(16)
    m, b = _on_boundary(v, f)
    got = np.asarray(fit_boundary_normals(m, jnp.asarray(every[0])))
    assert np.linalg.norm(got - v, axis=1)[b].max() <= 0.1 * h**2
    assert np.linalg.norm(every[0] - v, axis=1)[b].min() >= 0.4 * h


def test_boundary_fit_leaves_closed_and_small_fans_alone():
    """A closed mesh has no boundary: the normals come back unchanged. At the box
    corner each boundary vertex's two-ring holds 3 points for 5 unknowns: the fit
    is ill-posed and eq. (8)–(9) stays."""
    v, f = icosphere(2)
    m = Mesh(v, f)
    n = vertex_normals(v, f)
    np.testing.assert_array_equal(fit_boundary_normals(m, n), n)
    corner = Mesh(CORNER_V, CORNER_F)
    n = vertex_normals(CORNER_V, CORNER_F)
    np.testing.assert_array_equal(fit_boundary_normals(corner, n), n)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_boundary_fit_gradient():
    """d(Σ target · n)/d(vertices) of the fitted normals (the fit depends on the
    stencil's positions and, through the frame, on eq. (8)–(9)) vs a central
    difference along a random direction; 1e-6 relative as for the fan normals."""
    v, f = validation.catenoid_mesh(2)
    m = Mesh(v, f)
    target = jnp.asarray(np.random.default_rng(5).normal(size=v.shape))

    @jax.jit
    def loss(x):
        n = fit_boundary_normals(m.with_vertices(x), vertex_normals(x, m.faces))
        return jnp.sum(n * target)

    g = np.asarray(jax.grad(loss)(jnp.asarray(v)))
    assert np.isfinite(g).all()
    d = np.random.default_rng(6).normal(size=v.shape)
    eps = 1e-6
    fd = (float(loss(v + eps * d)) - float(loss(v - eps * d))) / (2 * eps)
    np.testing.assert_allclose(np.sum(g * d), fd, rtol=1e-6)


# ---------------------------------------------------------------- differentiability


@functools.lru_cache
def gradient_case():
    """Gradients of Σ target · n for the three weightings, compiled once, and the
    same losses on both sides of a central difference along a random direction."""
    v, f = icosphere(1)
    # an extra vertex in no face: its summed normal is 0, its gradient must not be NaN
    v = np.concatenate([v, [[3.0, 3.0, 3.0]]])
    target = jnp.asarray(np.random.default_rng(2).normal(size=v.shape))

    @jax.jit
    def losses(verts):
        return jnp.sum(all_normals(verts, f) * target, axis=(1, 2))

    grads = np.asarray(jax.jit(jax.jacrev(losses))(jnp.asarray(v)))  # (3, V, 3)
    d = np.random.default_rng(3).normal(size=v.shape)
    eps = 1e-6
    fd = (np.asarray(losses(v + eps * d)) - np.asarray(losses(v - eps * d))) / (2 * eps)
    return grads, d, fd


@pytest.mark.parametrize("weighting", WEIGHTINGS)
def test_gradient_is_finite_and_correct(weighting):
    grads, d, fd = gradient_case()
    i = WEIGHTINGS.index(weighting)
    g = grads[i]
    assert np.isfinite(g).all()
    assert np.abs(g[-1]).max() == 0.0
    np.testing.assert_allclose(np.sum(g * d), fd[i], rtol=1e-6)


@pytest.mark.slow  # 12 s niced beside CI: among the fast set's longest (12-08)
def test_gradient_under_jit():
    v, f = icosphere(1)
    g = jax.jit(jax.grad(lambda x: vertex_normals(x, f)[0, 2]))(jnp.asarray(v))
    assert bool(jnp.isfinite(g).all())
    # only vertex 0 and its neighbours influence vertex 0's normal
    touched = np.unique(f[(f == 0).any(1)])
    assert set(np.flatnonzero(np.abs(np.asarray(g)).sum(1) > 0)) <= set(touched)


# -------------------------------------------------------------------- eq. (10)


def test_edge_normal_is_eq_10():
    """Eq. (10): n_k = (n_2 − n_1) t_1k + n_1, linear and not renormalised."""
    n1 = jnp.array([0.0, 0.0, 1.0])
    n2 = jnp.array([1.0, 0.0, 0.0])
    np.testing.assert_array_equal(edge_normal(n1, n2, 0.0), n1)
    np.testing.assert_array_equal(edge_normal(n1, n2, 1.0), n2)
    np.testing.assert_allclose(edge_normal(n1, n2, 0.25), [0.25, 0.0, 0.75])
    # not unit in between: |n(½)| = 1/√2 for perpendicular unit normals
    assert np.isclose(float(jnp.linalg.norm(edge_normal(n1, n2, 0.5))), 2**-0.5)
    # batched over edges and parameters, and its t-derivative is n2 − n1
    rng = np.random.default_rng(4)
    N1, N2, t = rng.normal(size=(5, 3)), rng.normal(size=(5, 3)), rng.uniform(size=5)
    got = jax.vmap(edge_normal)(N1, N2, t)
    np.testing.assert_allclose(got, (N2 - N1) * t[:, None] + N1, rtol=1e-15)
    dt = jax.jacfwd(edge_normal, argnums=2)(N1[0], N2[0], 0.3)
    np.testing.assert_allclose(dt, N2[0] - N1[0], rtol=1e-15)
