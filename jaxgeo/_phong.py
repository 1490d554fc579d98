"""Phong tessellation (Boubekeur & Alexa 2008) of a triangle mesh.

On a face with corners v_i and unit vertex normals n_i, the point with barycentric
coordinates b = (b0, b1, b2) is lifted from the flat point p = Σ b_i v_i to

    Φ(b) = (1 − α)·p + α·Σ b_i π_i(p),      π_i(p) = p − ((p − v_i)·n_i)·n_i,

the barycentric blend of the projections of p onto the three vertex tangent planes
(α is the shape factor). Φ is a quadratic polynomial in b. On an edge (b_k = 0) it
depends only on that edge's two vertices and normals, so the surface is C0 across
edges; Φ(corner i) = v_i, so the vertices lie on it.

α = ½ is the consistent choice: on a mesh sampled from a smooth surface with exact
normals the lifted edge curve then matches the surface to O(h³) (the quadratic
term of the sagitta is recovered exactly), while α > ½ overshoots by (2α − 1) times
the flat sagitta and turns every vertex into a small cone.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

#: Gauss–Legendre nodes and weights on [0, 1], by number of points. numpy, not jax
#: arrays: this module is first imported inside a jit trace (`methods.Smooth.solve`
#: imports `smooth` lazily), where a module-level `jnp.asarray` would be a tracer
#: that leaks into every later trace (UnexpectedTracerError).
_GAUSS = {
    n: (
        0.5 * (np.polynomial.legendre.leggauss(n)[0] + 1.0),
        0.5 * np.polynomial.legendre.leggauss(n)[1],
    )
    for n in (2, 3, 4, 5, 6, 8)
}


def phong_point(
    corners: Float[Array, "3 3"],
    normals: Float[Array, "3 3"],
    bary: Float[Array, "3"],
    alpha: float | Float[Array, ""] = 0.5,
) -> Float[Array, "3"]:
    """Φ(b) = p − α·Σ b_i ((p − v_i)·n_i)·n_i, with p = Σ b_i v_i.

    **Arguments:** `corners` (rows v_i), `normals` (rows n_i, unit), `bary` b,
    `alpha` the shape factor (0: the flat triangle).
    """
    p = bary @ corners
    heights = jnp.sum((p[None, :] - corners) * normals, axis=-1)  # (p − v_i)·n_i
    return p - alpha * (bary * heights) @ normals


def phong_velocity(
    corners: Float[Array, "3 3"],
    normals: Float[Array, "3 3"],
    bary: Float[Array, "*Q 3"],
    direction: Float[Array, "3"],
    alpha: float | Float[Array, ""] = 0.5,
) -> Float[Array, "*Q 3"]:
    """dΦ(b + t·d)/dt at t = 0: with h_i = (p − v_i)·n_i,
    dΦ = dp − α·Σ (d_i h_i + b_i dh_i)·n_i, dp = Σ d_i v_i, dh_i = dp·n_i."""
    p = bary @ corners
    dp = direction @ corners
    h = p @ normals.T - jnp.sum(corners * normals, axis=1)
    dh = normals @ dp
    return dp - alpha * (direction * h + bary * dh) @ normals


def segment_length(
    corners: Float[Array, "3 3"],
    normals: Float[Array, "3 3"],
    b0: Float[Array, "3"],
    b1: Float[Array, "3"],
    alpha: float | Float[Array, ""] = 0.5,
    n_quad: int = 4,
) -> Float[Array, ""]:
    """Length ∫₀¹ |dΦ(b(t))/dt| dt of the lifted straight segment
    b(t) = (1 − t)·b0 + t·b1, by `n_quad`-point Gauss–Legendre quadrature.

    Φ is quadratic, so the speed is the square root of a quartic in t: smooth, and
    the quadrature error falls like h^(2·n_quad) relative to the segment's
    curvature scale. Safe (zero, not NaN, gradient) for a segment of zero length.
    """
    nodes, weights = _GAUSS[n_quad]
    nodes = nodes.astype(b0.dtype)
    db = b1 - b0
    b = b0[None, :] + nodes[:, None] * db[None, :]  # (Q, 3)
    d = phong_velocity(corners, normals, b, db, alpha)
    sq = jnp.sum(d * d, axis=1)
    pos = sq > 0
    speed = jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)
    return jnp.sum(weights.astype(b0.dtype) * speed)
