"""A lineax solver for the 3×3 Newton systems of System (16).

`lineax.LU` factors through LAPACK, which on CPU runs one small call per matrix of
a vmapped batch: on the 60,200 lanes of an all-edges solve of a 20k-face mesh the
LU solve alone took about 6× the time of the closed-form adjugate below
(`python benchmarks/bench_paths.py`, section "System (16)"). A 3×3 inverse by its
adjugate is a few dozen fused multiply-adds and vectorises across lanes.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array, Float


def _inverse3(m: Float[Array, "3 3"]) -> Float[Array, "3 3"]:
    """Inverse by the adjugate: rows of the inverse are cross products of columns
    of `m` divided by the determinant (inf/NaN when `m` is singular, as LU gives)."""
    c0, c1, c2 = m[:, 0], m[:, 1], m[:, 2]
    adj = jnp.stack([jnp.cross(c1, c2), jnp.cross(c2, c0), jnp.cross(c0, c1)])
    return adj / jnp.dot(c0, adj[0])


class Inverse3(lx.AbstractLinearSolver):
    """Direct solver for nonsingular 3×3 operators by the closed-form inverse.

    Use as the `linear_solver` of `optimistix.Newton` or of
    `optimistix.ImplicitAdjoint` when the unknown is a length-3 vector.
    """

    def init(self, operator: lx.AbstractLinearOperator, options: dict[str, Any]):
        del options
        for struct in (operator.in_structure(), operator.out_structure()):
            if getattr(struct, "shape", None) != (3,):
                raise ValueError("Inverse3 solves for one array of shape (3,) only")
        return _inverse3(operator.as_matrix())

    def compute(self, state, vector, options: dict[str, Any]):
        del options
        return state @ vector, lx.RESULTS.successful, {}

    def transpose(self, state, options: dict[str, Any]):
        return state.T, options

    def conj(self, state, options: dict[str, Any]):
        return state.conj(), options

    def assume_full_rank(self) -> bool:
        return True
