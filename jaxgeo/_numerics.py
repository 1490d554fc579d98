"""Small numerical helpers that keep gradients finite."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float


def safe_norm(x: Float[Array, "... 3"], axis: int = -1) -> Float[Array, ...]:
    """Euclidean norm whose gradient is 0 (not NaN) at x = 0."""
    sq = jnp.sum(x * x, axis=axis)
    positive = sq > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)


def safe_normalize(x: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """`x / |x|`, and 0 where `x = 0` (with a finite gradient)."""
    n = safe_norm(x)
    return x / jnp.where(n > 0, n, 1.0)[..., None]


def eps_of(dtype) -> float:
    return float(jnp.finfo(dtype).eps)
