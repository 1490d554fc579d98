"""The smooth method's solver (`jaxgeo.smooth`): a projected, damped
(Levenberg–Marquardt) Newton method on the strip's tridiagonal Hessian, in a
`lax.while_loop`, with crossings held at the ends of their edges."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._smooth_strip import derivatives

#: Parameters this close to 0 or 1 are put on the bound: a crossing pulled onto a
#: vertex converges there quadratically, and the segments between crossings at the
#: same vertex have zero length, where the length has a kink (|x| at 0) that a
#: Newton step cannot resolve. On the bound, the projection holds it.
_SNAP = 1e-10


def _snap(u):
    return jnp.where(u < _SNAP, 0.0, jnp.where(u > 1.0 - _SNAP, 1.0, u))


def _tridiagonal_solve(diag, off, rhs):
    """Thomas algorithm for the symmetric tridiagonal system (diag, off)·x = rhs
    (no pivoting: used on damped, held-row-regularised Newton matrices; a
    breakdown gives non-finite entries, which the caller rejects)."""

    def forward(carry, xs):
        c_prev, d_prev = carry
        a, b, c, r = xs  # sub-diagonal, diagonal, super-diagonal, rhs
        m = b - a * c_prev
        c_new = c / m
        d_new = (r - a * d_prev) / m
        return (c_new, d_new), (c_new, d_new)

    zero = jnp.zeros(1, diag.dtype)
    sub = jnp.concatenate([zero, off])
    sup = jnp.concatenate([off, zero])
    init = (jnp.zeros((), diag.dtype), jnp.zeros((), diag.dtype))
    _, (cp, dp) = jax.lax.scan(forward, init, (sub, diag, sup, rhs))

    def backward(x_next, xs):
        c, d = xs
        x = d - c * x_next
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros((), diag.dtype), (cp, dp), reverse=True)
    return x


def minimise(faces, strip, vertices, normals, u0, alpha, n_quad, gtol, max_steps):
    """Projected Levenberg–Marquardt Newton on the tridiagonal Hessian.

    Each iteration evaluates L, g, H at a trial point; the trial is accepted when
    it is shorter (or level within rounding and flatter); then the next trial is
    u + δ with (H + λ·|diag H|)·δ = −g on the free rows, clipped to [0, 1]."""
    dtype = u0.dtype
    eps = jnp.finfo(dtype).eps
    free = strip.free

    def projected(u, g, kink):
        # at a bound, held when the one-sided derivative inwards is ≥ 0
        held = ~free | ((u <= 0) & (g + kink >= 0)) | ((u >= 1) & (kink - g >= 0))
        return held, jnp.where(held, 0.0, g)

    def pg_norm(cur):
        u, _, g, diag, _, kink = cur
        pg = projected(u, g, kink)[1]
        # A crossing whose Newton step |g|/H is below the rounding of u cannot
        # move: the rest of its gradient is rounding (a path 1e-8 from a vertex has
        # H ≈ 3e6, and stalled at |g| = 1e-10 on an 82k-face sphere).
        pg = jnp.where(jnp.abs(pg) <= 4 * eps * jnp.abs(diag), 0.0, pg)
        return jnp.max(jnp.abs(pg), initial=0.0)

    def cond(state):
        cur, _, _, it, n_fail = state
        going = (pg_norm(cur) > gtol) & (it < max_steps) & (n_fail < 40)
        return (it == 0) | going

    def body(state):
        cur, trial, lam, it, n_fail = state
        new = (trial, *derivatives(faces, strip, vertices, normals, trial, alpha,
                                    n_quad))  # fmt: skip
        first = it == 0
        shorter = new[1] < cur[1]
        level = new[1] <= cur[1] + 8 * eps * jnp.abs(cur[1])
        flatter = pg_norm(new) < pg_norm(cur)
        accept = first | (jnp.isfinite(new[1]) & (shorter | (level & flatter)))
        cur = jax.tree.map(lambda a, b: jnp.where(accept, a, b), new, cur)
        lam = jnp.where(
            first, lam, jnp.where(accept, jnp.maximum(lam * 0.25, 1e-12), lam * 8.0)
        )
        u, _, g, diag, off, kink = cur
        held, pg = projected(u, g, kink)
        scale = jnp.maximum(jnp.abs(diag), jnp.finfo(dtype).tiny)
        dd = jnp.where(held, 1.0, diag + lam * scale)
        lo = jnp.where(held[1:] | held[:-1], 0.0, off)
        step = _tridiagonal_solve(dd, lo, -pg)
        step = jnp.where(held | ~jnp.isfinite(step), 0.0, step)
        trial = jnp.where(free, _snap(jnp.clip(u + step, 0.0, 1.0)), u)
        return cur, trial, lam, it + 1, jnp.where(accept, 0, n_fail + 1)

    u0 = jnp.where(free, _snap(u0), u0)
    m = u0.shape[0]
    z = jnp.zeros(m, dtype)
    cur = (u0, jnp.asarray(jnp.inf, dtype), z, z + 1, z[1:], z)
    state = (cur, u0, jnp.asarray(1e-3, dtype), 0, 0)
    cur, _, _, it, _ = jax.lax.while_loop(cond, body, state)
    u = cur[0]
    at_end = free & ((u <= 0) | (u >= 1))
    return u, pg_norm(cur), jnp.any(at_end), it
