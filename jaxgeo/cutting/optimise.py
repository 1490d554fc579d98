"""Seam optimisation for the reassembly stress (`objective.evaluate`).

The objective `J(x)` holds while the cut topology of its template holds (every
seam keeps its sequence of mesh elements). So the optimiser runs in **rounds**:

1. cut the mesh along the seams of the current layout, flatten, compensate and
   build the template there (`objective.make_template`; the capacities of the
   first round are kept, so later rounds reuse the compiled solver);
2. minimise `J` over the seam-end parameters with `optimistix.minimise` and
   `optimistix.BFGS` (backtracking Armijo line search), each parameter bounded
   to a box around its value at the start of the round by the change of
   variable `x = x₀ + r ⊙ tanh(z)` (`r` at most `max_move` and less than half
   the gap to the neighbouring seam ends on the same boundary loop, so seams
   never swap order on a loop). Where the template no longer holds, or a solve
   fails, `J` is `+∞`, which the line search rejects: a step stays inside the
   template's cell;
3. repeat from the layout found, until a round makes no step or `rounds` are
   done.

`J` is scaled by the largest `|∂J/∂z|` at the round's start, so BFGS's first
step (its inverse Hessian starts as the identity) moves the farthest seam end
by `r·tanh(1) ≈ 0.76 r`. Each BFGS step is one value and gradient of `J`
(`steps` bounds them, line-search trials included).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._errors import JaxgeoError
from ..mesh import Mesh
from .compensate import compensate_pattern
from .layout import Layout
from .material import Compensation
from .objective import Settings, Template, evaluate, make_template

__all__ = ["StressResult", "optimise_seams", "move_radius"]


@dataclasses.dataclass
class StressResult:
    """Outcome of `optimise_seams`: the start and end layouts, `J` at both
    (each on its own round's template), and per round a dict with `j_start`,
    `j_end`, `rms_start`, `rms_end`, `max_start`, `max_end` (stress deviation
    of the JAX objective, kN/m), `steps` (BFGS steps, line-search trials
    included) and `accepted` (steps taken)."""

    start: Layout
    layout: Layout
    j_start: float
    j_end: float
    rounds: list[dict]


def move_radius(layout, max_move: float) -> np.ndarray:
    """Per seam-end parameter, the box half-width of one round: `max_move`,
    and less than half the gap to the neighbouring ends on the same loop (the
    ends can then never pass each other)."""
    loops = np.concatenate([layout.loop_a, layout.loop_b])
    s = np.mod(layout.x, 1.0)
    r = np.full(len(s), float(max_move))
    for lp in np.unique(loops):
        idx = np.flatnonzero(loops == lp)
        if len(idx) < 2:
            continue
        order = idx[np.argsort(s[idx])]
        ss = s[order]
        gap_next = np.mod(np.roll(ss, -1) - ss, 1.0)
        gap = np.minimum(gap_next, np.roll(gap_next, 1))
        r[order] = np.minimum(r[order], 0.45 * gap)
    return r


@eqx.filter_jit
def _minimise(
    x0: Float[Array, " P"],
    r: Float[Array, " P"],
    mesh: Mesh,
    template: Template,
    settings: Settings,
    steps: int,
):
    def j(z):
        x = x0 + r * jnp.tanh(z)
        val, aux = evaluate(x, mesh, template, settings)
        ok = aux["valid"] & jnp.isfinite(val)
        return jnp.where(ok, val, jnp.inf), (aux["rms"], aux["max"])

    z0 = jnp.zeros_like(x0)
    (j0, aux0), g0 = jax.value_and_grad(j, has_aux=True)(z0)
    scale = 1.0 / jnp.maximum(jnp.max(jnp.abs(g0)), 1e-300)

    def fn(z, args):
        val, aux = j(z)
        return val * scale, aux

    # rtol/atol on z (of order 1) and on the scaled J: the template's cell is
    # left long before a 1e-6 change in z matters
    sol = optx.minimise(
        fn,
        optx.BFGS(rtol=1e-6, atol=1e-9),
        z0,
        has_aux=True,
        max_steps=steps,
        throw=False,
    )
    x = x0 + r * jnp.tanh(sol.value)
    return (
        x,
        (j0, *aux0),
        (sol.state.f_info.f / scale, *sol.state.aux),
        sol.stats["num_steps"],
        sol.state.num_accepted_steps,
    )


def _template(mesh, layout, settings, capacity):
    from ..trace import TraceOptions
    from .cut import cut
    from .flatten import make_pattern

    options = TraceOptions(candidates="local", max_points=settings.max_points)
    c, paths = cut(mesh, layout, options, settings.method)
    cw, cf = settings.compensation
    cloths = compensate_pattern(make_pattern(c), Compensation(100 * cw, 100 * cf))
    try:
        return make_template(mesh, layout, paths, c, cloths, capacity)
    except JaxgeoError:
        if capacity is None:
            raise
        # a cloth outgrew the first round's capacities: a new (compiled) size
        return make_template(mesh, layout, paths, c, cloths, None)


def optimise_seams(
    mesh: Mesh,
    layout,
    settings: Settings,
    *,
    steps: int = 8,
    rounds: int = 2,
    max_move: float = 0.02,
    log: Callable[[str], None] | None = None,
) -> StressResult:
    """Move the seam ends of `layout` (`jaxgeo.seams.Layout`) to lower the
    stress objective `J` of `settings` (`objective`: RMS reassembly stress
    deviation, waste and roll fit), by `optimistix.BFGS` in rounds (module
    docstring).

    **Arguments:**

    - `settings`: material, prestress, uniform compensation (strains), roll
      width, weights, and the geodesic method the seams are traced with (the
      laser method by default: its points are differentiable and it compiles
      fastest).
    - `steps`: BFGS steps per round (value-and-gradient evaluations, line
      search included); `rounds`: re-templating rounds; `max_move`: largest
      change of a seam-end parameter (normalised arc length) per round.
    - `log`: called with a line per round.

    **Returns:** a `StressResult`.
    """
    if steps < 1 or rounds < 1 or not max_move > 0:
        raise JaxgeoError("optimise_seams needs steps >= 1, rounds >= 1, max_move > 0")
    log = log or (lambda msg: None)
    current, capacity, history = layout, None, []
    for k in range(rounds):
        template, capacity = _template(mesh, current, settings, capacity)
        x0 = jnp.asarray(current.x)
        r = jnp.asarray(move_radius(current, max_move))
        x, start, end, n, accepted = _minimise(
            x0, r, mesh, template, settings, int(steps)
        )
        if not np.isfinite(float(start[0])):
            raise JaxgeoError(
                "the stress objective is not finite at the start layout (a seam "
                "or a cloth's flattening failed)"
            )
        rec = {
            "j_start": float(start[0]),
            "j_end": float(end[0]),
            "rms_start": float(start[1]),
            "rms_end": float(end[1]),
            "max_start": float(start[2]),
            "max_end": float(end[2]),
            "steps": int(n),
            # optimistix counts the start point (always accepted) as a step
            "accepted": max(int(accepted) - 1, 0),
        }
        history.append(rec)
        log(
            f"round {k + 1}: J {rec['j_start']:.5g} -> {rec['j_end']:.5g}, RMS "
            f"deviation {rec['rms_start']:.4g} -> {rec['rms_end']:.4g} kN/m "
            f"({rec['accepted']} of {rec['steps']} steps taken)"
        )
        if rec["accepted"] == 0:
            break
        current = current.with_x(np.asarray(x))
    return StressResult(
        layout, current, history[0]["j_start"], history[-1]["j_end"], history
    )
