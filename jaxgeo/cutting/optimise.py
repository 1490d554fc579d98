"""Seam optimisation for the reassembly stress (`objective.evaluate`).

The objective `J(x)` holds while the cut topology of its template holds (every
seam keeps its sequence of mesh elements). So the optimiser runs in **rounds**:

1. cut the mesh along the seams of the current layout, flatten, compensate and
   build the template there (`objective.make_template`; the capacities of the
   first round are kept, so later rounds reuse the compiled solver). From the
   second round on, each cloth's flattening starts from the last round's
   flattening at this layout, carried over to the new cut (`_carry_over`), so
   the new template continues the branch of local optima the last round
   tracked and `J` is continuous across rounds (a fresh start from
   `make_pattern`'s flattening can land on another optimum);
2. minimise `J` over the seam-end parameters with `optimistix.minimise` and
   `optimistix.BFGS` (backtracking Armijo line search), each parameter bounded
   to a box around its value at the start of the round by the change of
   variable `x = x₀ + r ⊙ tanh(z)` (`r` at most `max_move` and less than half
   the gap to the neighbouring seam ends on the same boundary loop, so seams
   never swap order on a loop). Where the template no longer holds, or a solve
   fails, `J` is `+∞`, which the line search rejects: a step stays inside the
   template's cell. Two things keep the first step inside it: seams whose
   sequence changes at any move of their ends (`FRAGILE_MOVE`: along mesh
   edges, or grazing a vertex) are held for the round, and the box is halved
   until BFGS's first step keeps every seam's sequence (tracing only);
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
from .objective import Settings, Template, evaluate, make_template, trace_seams

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


#: a seam whose sequence of mesh elements changes when its ends move by this
#: (of the loop) in any of four directions is held fixed for the round
FRAGILE_MOVE = 1e-6
#: the round's box is halved at most this many times to fit the first step
#: into the template's cell
SHRINK_STEPS = 16


def _in_cell(x, mesh: Mesh, template: Template, settings: Settings):
    """`(J, rms, max)` of `evaluate` at `x`, with `J = +∞` and a zero derivative
    outside the template's cell (the template broken, or a solve failed).

    The derivative there is not just masked but never computed: the trial's
    linearisation runs under `lax.cond` only where the trial is valid. Masking
    would send a zero cotangent back through the broken trial, whose partials
    may be infinite or NaN (a cloth's flattening at a saddle of its energy: the
    implicit derivative's banded Cholesky has no factor there); 0·NaN = NaN then
    reaches the replay's implicit System (16) solves, whose lineax solve raises
    (the twin-peak optimiser crashed so) instead of the line search rejecting
    the step."""

    def parts(x):
        val, aux = evaluate(x, mesh, template, settings)
        ok = aux["valid"] & jnp.isfinite(val)
        return (val, aux["rms"], aux["max"]), ok

    @jax.custom_jvp
    def f(x):
        (val, rms, dmax), ok = parts(x)
        return jnp.where(ok, val, jnp.inf), rms, dmax

    @f.defjvp
    def f_jvp(primals, tangents):
        (x,), (tx,) = primals, tangents
        out, lin, ok = jax.linearize(parts, x, has_aux=True)
        zero = jax.tree.map(jnp.zeros_like, out)
        tout = jax.lax.cond(ok, lin, lambda _: zero, tx)
        return (jnp.where(ok, out[0], jnp.inf), *out[1:]), tout

    return f(x)


@eqx.filter_jit
def _minimise(
    x0: Float[Array, " P"],
    r: Float[Array, " P"],
    mesh: Mesh,
    template: Template,
    settings: Settings,
    steps: int,
):
    n = template.loop_a.shape[0]

    def keeps(x):
        return trace_seams(x, mesh, template, settings)[1]

    # seams that change their edge sequence at any move of their ends (along a
    # line of mesh edges, or grazing a vertex): every step that moves them
    # would leave the cell, so they are held (their box is zero)
    probes = FRAGILE_MOVE * jnp.array(
        [[1.0, 1.0], [-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]]
    )
    held = ~jnp.all(jax.vmap(lambda d: keeps(x0 + jnp.repeat(d, n)))(probes), axis=0)
    r = r * jnp.where(jnp.concatenate([held, held]), 0.0, 1.0)

    def j(z, r):
        val, rms, dmax = _in_cell(x0 + r * jnp.tanh(z), mesh, template, settings)
        return val, (rms, dmax)

    z0 = jnp.zeros_like(x0)
    (j0, aux0), g0 = jax.value_and_grad(j, has_aux=True)(z0, r)
    gmax = jnp.maximum(jnp.max(jnp.abs(g0)), 1e-300)
    # BFGS's first step is z1 = -g0/gmax (the scaled J's identity inverse
    # Hessian): halve the box until that step keeps every seam's sequence
    # (tracing only), so the line search starts inside the template's cell
    # (the cell may be far smaller than max_move: twin-peak tent, docs)
    z1 = -g0 / gmax

    def shrink_cond(c):
        k, ok = c
        return ~ok & (k < SHRINK_STEPS)

    def shrink_body(c):
        k = c[0] + 1
        return k, jnp.all(keeps(x0 + r * 0.5**k * jnp.tanh(z1)))

    k, _ = jax.lax.while_loop(
        shrink_cond,
        shrink_body,
        (jnp.asarray(0), jnp.all(keeps(x0 + r * jnp.tanh(z1)))),
    )
    r = r * 0.5**k
    # J is scaled by the largest |dJ/dz| at the start (in the shrunk box)
    scale = 1.0 / (gmax * 0.5**k)

    def fn(z, args):
        val, aux = j(z, r)
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
        (jnp.sum(held), jnp.max(r)),
    )


@eqx.filter_jit
def _flat_at(x, mesh, template, settings):
    """The cloths' design positions and flattenings of `template` at `x`."""
    aux = evaluate(x, mesh, template, settings)[1]
    return aux["x3"], aux["uv"], aux["valid"]


def _carry_over(old, cloths) -> list:
    """Per new cloth a start of its flattening from the previous template's
    flattening at the same layout, `old = (x3, uv, faces, fmask)` (padded
    arrays of the old cloths): each new vertex takes the flat position of its
    place in the nearest old triangle (barycentric, extrapolated a little
    where the seam moved outwards) of the old cloth nearest its centroid."""
    x3, uv, faces, fmask = (np.asarray(a) for a in old)
    centres = [
        np.mean(x3[k][faces[k][fmask[k] > 0]].reshape(-1, 3), 0) for k in range(len(x3))
    ]
    starts = []
    for cc in cloths:
        p = np.asarray(cc.cloth.vertices3d)
        k = int(np.argmin([np.sum((p.mean(0) - c) ** 2) for c in centres]))
        f = faces[k][fmask[k] > 0]
        # (in blocks of vertices: the search is vertices x triangles)
        starts.append(
            np.concatenate(
                [
                    _flat_place(p[i : i + _BLOCK], x3[k], uv[k], f)
                    for i in range(0, len(p), _BLOCK)
                ]
            )
        )
    return starts


#: vertices placed at a time by `_carry_over` (memory: block x old triangles)
_BLOCK = 128


def _flat_place(p, x3, uv, f):
    """The flat positions of 3-D points `p` (n, 3): each takes the barycentric
    place of its nearest triangle `f` of the old cloth (positions `x3`,
    flattening `uv`), extrapolated a little outside it."""
    a, b, c = (x3[f[:, i]] for i in range(3))
    e1, e2 = b - a, c - a  # (F, 3)
    g11, g12, g22 = (np.sum(u * v, 1) for u, v in ((e1, e1), (e1, e2), (e2, e2)))
    det = g11 * g22 - g12**2 + 1e-300
    q = p[:, None, :] - a[None]  # (n, F, 3)
    r1, r2 = np.sum(q * e1, 2), np.sum(q * e2, 2)
    beta = (g22 * r1 - g12 * r2) / det
    gamma = (g11 * r2 - g12 * r1) / det
    alpha = 1.0 - beta - gamma
    off = q - beta[..., None] * e1 - gamma[..., None] * e2
    size = np.sqrt(g11)
    outside = sum(np.maximum(-w, 0.0) for w in (alpha, beta, gamma))
    best = np.argmin(np.sqrt(np.sum(off * off, 2)) + outside * size, axis=1)
    i = np.arange(len(p))
    ua, ub, uc = (uv[f[best, j]] for j in range(3))
    return (
        alpha[i, best, None] * ua + beta[i, best, None] * ub + gamma[i, best, None] * uc
    )


def _template(mesh, layout, settings, capacity, previous=None, report=None):
    """The template at `layout`; `previous`: `(template, x)`, the last round's
    template and the layout it ended at (`layout.x`), whose flattening there
    is carried over as the start of each cloth's (`_carry_over`,
    `make_template`'s `starts`), so that the new template continues the
    flattening branch the last round tracked: the flattening of a cloth far
    from developable has several local optima, and a fresh start from
    `make_pattern`'s can land on another (twin-peak tent: 0.6 % lower
    edge-strain energy, 4.5 times the RMS stress deviation; docs). Returns
    `(template, capacity, cloths whose make_pattern flattening did not
    converge)`."""
    from ..trace import TraceOptions
    from .cut import cut
    from .flatten import make_pattern

    options = TraceOptions(candidates="local", max_points=settings.max_points)
    c, paths = cut(mesh, layout, options, settings.method)
    cw, cf = settings.compensation
    pattern = make_pattern(c)
    cloths = compensate_pattern(pattern, Compensation(100 * cw, 100 * cf))
    starts = None
    if previous is not None:
        old, x = previous
        x3, uv, valid = _flat_at(jnp.asarray(x), mesh, old, settings)
        if bool(valid):
            starts = _carry_over((x3, uv, old.faces, old.fmask), cloths)
    unconverged = [k for k, cl in enumerate(pattern.cloths) if not cl.converged]
    try:
        t, cap = make_template(
            mesh, layout, paths, c, cloths, capacity, starts=starts, report=report
        )
    except JaxgeoError:
        if capacity is None:
            raise
        # a cloth outgrew the first round's capacities: a new (compiled) size
        t, cap = make_template(
            mesh, layout, paths, c, cloths, None, starts=starts, report=report
        )
    return t, cap, unconverged


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
    current, capacity, history, previous = layout, None, [], None
    for k in range(rounds):
        kept: list = []
        template, capacity, unconverged = _template(
            mesh, current, settings, capacity, previous, kept
        )
        x0 = jnp.asarray(current.x)
        r = jnp.asarray(move_radius(current, max_move))
        x, start, end, n, accepted, (n_held, box) = _minimise(
            x0, r, mesh, template, settings, int(steps)
        )
        if not np.isfinite(float(start[0])) and k > 0:
            # a later round's template fails at its own layout (a held seam
            # traced differently, or a flattening not converged in JAX): keep
            # the layout the last round reached
            log(f"round {k + 1}: the objective is not finite at its start; stopped")
            break
        if not np.isfinite(float(start[0])):
            why = (
                f"; the least-strain flattening of cloths {unconverged} did not "
                "converge (e.g. sliver triangles where a seam passes very close "
                "to a mesh vertex)"
                if unconverged
                else ""
            )
            raise JaxgeoError(
                "the stress objective is not finite at the start layout (a seam "
                f"or a cloth's flattening failed){why}"
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
            "held": int(n_held),
            "box": float(box),
            # cloths whose carried-over flattening converged and was kept
            "carried": sum(c[2] for c in kept),
            # per cloth (edge-strain energy from make_pattern's start, from the
            # carried flattening or nan, carried one kept)
            "energies": kept,
        }
        history.append(rec)
        log(
            f"round {k + 1}: J {rec['j_start']:.5g} -> {rec['j_end']:.5g}, RMS "
            f"deviation {rec['rms_start']:.4g} -> {rec['rms_end']:.4g} kN/m "
            f"({rec['accepted']} of {rec['steps']} steps taken; box {rec['box']:.3g}, "
            f"{rec['held']} seams held; {rec['carried']} flattenings carried over)"
        )
        if rec["accepted"] == 0:
            break
        current = current.with_x(np.asarray(x))
        previous = (template, current.x)
    return StressResult(
        layout, current, history[0]["j_start"], history[-1]["j_end"], history
    )
