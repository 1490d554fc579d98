"""System (16): the normal projection of a point of the chord A→B onto a mesh edge.

A point of the edge `x(u) = x1 + u Δx` (u ∈ [0, 1]) with the interpolated normal of
eq. (10), `n(u) = n1 + u Δn`, lies on the normal projection of the chord
`X(t) = A + t D` (D = B − A, t ∈ [0, 1]) when, for some ζ,

    x1 + u Δx + ζ (n1 + u Δn) = A + t D.                      (16)

Three equations, three unknowns `y = (u, t, ζ)`, bilinear through `ζ u Δn`.

**Closed form.** (16) says `x(u) − A`, `n(u)` and `D` are coplanar:
`g(u) = ((x(u) − A) × n(u)) · D = 0`, a quadratic in u, so an edge has 0, 1 or 2
solutions. Given u, t and ζ follow from a 2×2 least-squares solve. The roots start
`optimistix.Newton`, which polishes them on (16) itself (one or two steps), under
`jax.vmap` over every (edge, root) lane. Lanes without a real root are switched to
a trivial residual so they cost nothing and are reported as not found.

The paper's own solver (Steps 3–4: drop the bilinear term, then iterate with it on
the right-hand side) is `solve_fixed_point`, used to cross-check.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float

from ._linear import Inverse3
from ._numerics import eps_of


class EdgeCrossings(eqx.Module):
    """Solutions of System (16) for a batch of edges, two root lanes per edge.

    Arrays have shape `(N, 2)` (or `(N, 2, 3)` for points): N edges, 2 roots.

    - `u`: parameter on the edge; `t`: parameter on the chord; `zeta`: ζ.
    - `point`: the crossing `x1 + u Δx` on the edge.
    - `found`: the lane had a real root and Newton converged to a finite solution.
    - `valid`: `found` and both parameters in [0, 1] (within `param_tol`).
    - `degenerate`: the edge lies in a plane with the chord's direction and its
      normals (a one-parameter family of solutions: g(u) ≡ 0); never `valid`.
    """

    u: Float[Array, "N 2"]
    t: Float[Array, "N 2"]
    zeta: Float[Array, "N 2"]
    point: Float[Array, "N 2 3"]
    found: Bool[Array, "N 2"]
    valid: Bool[Array, "N 2"]
    degenerate: Bool[Array, " N"]


def residual(y: Float[Array, "3"], args) -> Float[Array, "3"]:
    """The residual of System (16) for `y = (u, t, ζ)`; `args = (A, D, x1, Δx, n1,
    Δn)`."""
    a, d, x1, dx, n1, dn = args
    u, t, zeta = y[0], y[1], y[2]
    return x1 + u * dx + zeta * (n1 + u * dn) - a - t * d


def _masked_residual(y, args):
    inner, active, y0 = args
    return jnp.where(active, residual(y, inner), y - y0)


def quadratic_coefficients(a, b, x1, x2, n1, n2):
    """Coefficients `(c0, c1, c2)` of `g(u) = ((x(u) − A) × n(u)) · D` and the scale
    `|x1 − A| + |Δx|` · `|n1| + |Δn|` · `|D|` that makes them dimensionless."""
    d = b - a
    d0, dx, dn = x1 - a, x2 - x1, n2 - n1
    c0 = jnp.dot(jnp.cross(d0, n1), d)
    c1 = jnp.dot(jnp.cross(d0, dn) + jnp.cross(dx, n1), d)
    c2 = jnp.dot(jnp.cross(dx, dn), d)
    scale = (
        (jnp.linalg.norm(d0) + jnp.linalg.norm(dx))
        * (jnp.linalg.norm(n1) + jnp.linalg.norm(dn))
        * jnp.linalg.norm(d)
    )
    return c0, c1, c2, scale


def _roots(c0, c1, c2, scale):
    """Real roots of c2 u² + c1 u + c0 in the cancellation-free form; NaN where a
    lane has no root. Returns `(roots (2,), degenerate)`."""
    tiny = 64 * eps_of(c0.dtype)
    degenerate = jnp.abs(c0) + jnp.abs(c1) + jnp.abs(c2) <= tiny * scale
    disc = c1 * c1 - 4 * c2 * c0
    sq = jnp.sqrt(jnp.maximum(disc, 0.0))
    q = -0.5 * (c1 + jnp.where(c1 >= 0, sq, -sq))
    safe = lambda x: jnp.where(x == 0, 1.0, x)  # noqa: E731
    r1 = jnp.where((c2 != 0) & (disc >= 0), q / safe(c2), jnp.nan)
    r2 = jnp.where((q != 0) & (disc >= 0), c0 / safe(q), jnp.nan)
    roots = jnp.stack([r1, r2])
    return jnp.where(degenerate, jnp.nan, roots), degenerate


def _t_zeta(u, a, d, x1, dx, n1, dn):
    """Given u, the least-squares (t, ζ) of `x(u) + ζ n(u) = A + t D`."""
    p = x1 + u * dx - a
    n = n1 + u * dn
    dd, dn_, nn = jnp.dot(d, d), jnp.dot(d, n), jnp.dot(n, n)
    det = dd * nn - dn_ * dn_
    rp, rn = jnp.dot(d, p), jnp.dot(n, p)
    det = jnp.where(det == 0, 1.0, det)
    t = (nn * rp - dn_ * rn) / det
    zeta = (dn_ * rp - dd * rn) / det
    return t, zeta


def _newton(dtype) -> optx.Newton:
    tol = 1e-12 if dtype == jnp.float64 else 1e-5
    return optx.Newton(rtol=tol, atol=tol, linear_solver=Inverse3())


def param_tolerance(dtype) -> float:
    """Slack on u, t ∈ [0, 1] (crossings at an edge end must not be lost to
    rounding): about 1e-9 in float64, 1e-4 in float32."""
    return 1e-9 if dtype == jnp.float64 else 1e-4


#: Closed-form roots farther than this outside [0, 1] (in u or t) are not
#: polished. Newton moves a closed-form root by rounding error only, so any
#: margin well above 1e-9 is safe.
_SCREEN = 0.25


def _solve_one_edge(a, b, x1, x2, n1, n2, max_steps: int):
    d, dx, dn = b - a, x2 - x1, n2 - n1
    inner = (a, d, x1, dx, n1, dn)
    c0, c1, c2, scale = quadratic_coefficients(a, b, x1, x2, n1, n2)
    roots, degenerate = _roots(c0, c1, c2, scale)

    def lane(u0):
        # Only roots near the edge and the chord are polished: the others can never
        # be valid, and Newton on them (a root at u = 1e8 when c2 ≈ 0) would make
        # every lane of the vmapped solve wait for them.
        u0 = jnp.where(jnp.isfinite(u0), u0, jnp.inf)
        t0, z0 = _t_zeta(jnp.where(jnp.isfinite(u0), u0, 0.5), a, d, x1, dx, n1, dn)
        near = lambda x: (x > -_SCREEN) & (x < 1 + _SCREEN)  # noqa: E731
        has_root = near(u0) & near(t0) & jnp.isfinite(z0)
        y0 = jnp.stack([u0, t0, z0])
        y0 = jnp.where(has_root, y0, 0.0)
        sol = optx.root_find(
            _masked_residual,
            _newton(a.dtype),
            y0,
            args=(inner, has_root, y0),
            max_steps=max_steps,
            throw=False,
        )
        y = sol.value
        found = (
            has_root
            & (sol.result == optx.RESULTS.successful)
            & jnp.all(jnp.isfinite(y))
        )
        return y, found

    y, found = jax.vmap(lane)(roots)
    found = found & ~degenerate
    u, t, zeta = y[:, 0], y[:, 1], y[:, 2]
    tol = param_tolerance(a.dtype)
    inside = (u >= -tol) & (u <= 1 + tol) & (t >= -tol) & (t <= 1 + tol)
    u = jnp.clip(u, 0.0, 1.0)
    point = x1 + u[:, None] * dx
    return u, t, zeta, point, found, found & inside, degenerate


def solve_edges(
    a: Float[Array, "3"],
    b: Float[Array, "3"],
    x1: Float[Array, "N 3"],
    x2: Float[Array, "N 3"],
    n1: Float[Array, "N 3"],
    n2: Float[Array, "N 3"],
    *,
    max_steps: int = 8,
) -> EdgeCrossings:
    """Solve System (16) for the chord `a → b` on N edges at once.

    Each edge `x1 → x2` carries the vertex normals `n1, n2` (eq. 10 interpolates
    them). The quadratic gives up to two starting points per edge; each is polished
    by `optimistix.root_find(..., optimistix.Newton(...), throw=False)` and the two
    lanes of all edges run together under `jax.vmap`.
    """
    out = jax.vmap(_solve_one_edge, in_axes=(None, None, 0, 0, 0, 0, None))(
        a, b, x1, x2, n1, n2, max_steps
    )
    return EdgeCrossings(*out)


def solve_crossing(
    a: Float[Array, "3"],
    b: Float[Array, "3"],
    x1: Float[Array, "3"],
    x2: Float[Array, "3"],
    n1: Float[Array, "3"],
    n2: Float[Array, "3"],
    y0: Float[Array, "3"],
    active: Bool[Array, ""] | bool = True,
    *,
    max_steps: int = 16,
) -> tuple[Float[Array, "3"], Bool[Array, ""]]:
    """Solve System (16) on one edge from the starting point `y0 = (u, t, ζ)`.

    Differentiable in every argument by the implicit function theorem
    (`optimistix.ImplicitAdjoint`, forward and reverse mode): this is what the
    replay of a traced path uses. Where `active` is False the lane solves the
    trivial system `y = y0` instead (masking without NaN gradients).
    Returns `(y, converged)`.
    """
    inner = (a, b - a, x1, x2 - x1, n1, n2 - n1)
    sol = optx.root_find(
        _masked_residual,
        _newton(a.dtype),
        y0,
        args=(inner, jnp.asarray(active), y0),
        max_steps=max_steps,
        throw=False,
        adjoint=optx.ImplicitAdjoint(linear_solver=Inverse3()),
    )
    return sol.value, sol.result == optx.RESULTS.successful


def initial_guess(a, b, x1, x2, n1, n2, u):
    """`(u, t, ζ)` from an edge parameter u (t and ζ by least squares)."""
    t, zeta = _t_zeta(u, a, b - a, x1, x2 - x1, n1, n2 - n1)
    return jnp.stack([u, t, zeta])


def solve_fixed_point(
    a: Float[Array, "3"],
    b: Float[Array, "3"],
    x1: Float[Array, "3"],
    x2: Float[Array, "3"],
    n1: Float[Array, "3"],
    n2: Float[Array, "3"],
    *,
    rtol: float = 1e-13,
    max_steps: int = 200,
) -> tuple[Float[Array, "3"], Bool[Array, ""]]:
    """The paper's solver (Steps 3–4) for one edge.

    Step 3 solves (16) with the bilinear term `Δn ζ u` dropped; Step 4 moves that
    term, evaluated at the previous iterate, to the right-hand side and solves the
    linear system again until `(u, t, ζ)` stop changing. Returns `(y, converged)`
    with `y = (u, t, ζ)`. Converges only where the bilinear term is a contraction.
    """
    d, dx, dn = b - a, x2 - x1, n2 - n1
    m = jnp.stack([dx, -d, n1], axis=1)  # columns act on (u, t, ζ)
    rhs0 = a - x1

    def step(y):
        return jnp.linalg.solve(m, rhs0 - y[2] * y[0] * dn)

    y_init = jnp.linalg.solve(m, rhs0)

    def cond(state):
        k, _, change = state
        return (k < max_steps) & (change > rtol)

    def body(state):
        k, y, _ = state
        y_new = step(y)
        change = jnp.max(jnp.abs(y_new - y)) / (1 + jnp.max(jnp.abs(y_new)))
        change = jnp.where(jnp.isfinite(change), change, 0.0)
        return k + 1, y_new, change

    k, y, change = jax.lax.while_loop(
        cond, body, (0, y_init, jnp.asarray(jnp.inf, a.dtype))
    )
    converged = (change <= rtol) & jnp.all(jnp.isfinite(y))
    return y, converged
