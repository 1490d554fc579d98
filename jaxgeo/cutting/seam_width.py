"""The seam-width objective of a layout and its optimiser.

The parameters are a `Layout`'s seam ends `x = (s_a, s_b)` (normalised arc lengths
on the boundary loops, `jaxgeo.cutting.layout`).

**Measures** (differentiable in `x` through the replayed geodesics):

- seam lengths `L_i`;
- the width of cloth `c` bounded by seams `S_c`: the largest distance from a point
  of one of its seams to the other seams of the cloth,
  `w_c = max_{i∈S_c} max_{p∈seam i} min_{j∈S_c, j≠i} dist(p, seam j)` — for a
  cloth between two seams, the largest distance between them;
- the objective, with roll width `W` and target `W_t = (1 − margin)·W`:

      J = α Σ_c relu(w_c/W_t − 1)²                        (fit the roll)
        + β mean_c (1 − w_c/W_t)²                         (fill the roll)
        + γ Σ_{c: |S_c|=2} ((L_i − L_j)/L̄)²               (equal seam lengths)

  A cloth with a single seam (between it and the boundary) has no width
  measure and is left out of the fit and fill terms (and of the mean).
  The geodesic seams flatten to their own length within the flattening strain
  (`jaxgeo.cutting.flatten` fits seam edges 10× harder), so the 3-D lengths
  stand for the flattened ones.

**Optimisation and re-tracing.** A geodesic's edge sequence is a discrete choice:
when a seam end moves, the length is continuous but its slope jumps where the
sequence changes. So every objective evaluation re-traces the seams (the jitted
laser ray, `stop_gradient`), then replays them on their fixed edge sequences
(`jaxgeo.replay`, implicit differentiation) to get `J` and `∇J`. The minimiser is
BFGS with Armijo backtracking run as a Python loop (`optimise`), not
`optimistix.BFGS` under `jit`: nesting the trace's while loop inside optimistix's
compiled loop costs another ~40 s of compilation per mesh and its line search
assumes a smooth function; the outer loop reuses the two compiled pieces (trace,
replay-gradient) and rejects steps that cross seams or fail to trace.
Driving `optimistix.BFGS` step by step from Python instead (`init`/`step`, the
evaluator behind `jax.custom_jvp` + `jax.pure_callback`) works, but its `step`
compiles for 15–23 s (jitted or not) where this loop compiles nothing
(`benchmarks/seam_width_bfgs.py`; docs/architecture.md, "Modules with several
jobs").

(Moved here from `jaxgeo.seams`, which still re-exports the public names. The
stress objective and its optimiser are `jaxgeo.cutting.objective` and
`jaxgeo.cutting.optimise`.)
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._errors import JaxgeoError
from ..boundary import packed_point
from ..mesh import Mesh
from ..methods import Method
from ..normals import vertex_normals
from ..path import Path, Status
from ..replay import replay
from ..trace import TraceOptions
from .cut import cut
from .flatten import make_pattern
from .layout import INSET, TRACE_OPTIONS, Layout, trace_seams

__all__ = ["Result", "Weights", "cloth_widths", "fit_roll", "objective", "optimise"]


@dataclasses.dataclass(frozen=True)
class Weights:
    """Weights of the objective's three terms and the safety margin under the
    roll width (the measured width is a proxy of the flattened one)."""

    fit: float = 100.0
    fill: float = 1.0
    equal: float = 1.0
    margin: float = 0.05
    options: TraceOptions = TRACE_OPTIONS


def _replay_batch(mesh, packed, loop_a, loop_b, x, traced) -> Path:
    n = loop_a.shape[0]
    normals = vertex_normals(mesh.vertices, mesh.faces, "uniform")

    def one(la, lb, a, b, p):
        p1 = packed_point(mesh, packed, la, a, INSET)
        p2 = packed_point(mesh, packed, lb, b, INSET)
        return dataclasses.replace(replay(mesh, normals, p1, p2, p), start=p1, end=p2)

    return jax.vmap(one)(loop_a, loop_b, x[:n], x[n:], traced)


# ----------------------------------------------------------------------- measures


def _point_segment(p, a, b):
    """Distances `(P, S)` from points `p (P,3)` to segments `a, b (S,3)`."""
    d = b - a
    dd = jnp.sum(d * d, axis=-1)
    t = jnp.sum((p[:, None, :] - a[None]) * d[None], axis=-1) / jnp.where(
        dd > 0, dd, 1.0
    )
    q = a[None] + jnp.clip(t, 0.0, 1.0)[..., None] * d[None]
    return jnp.sqrt(jnp.sum((p[:, None, :] - q) ** 2, axis=-1) + 1e-30)


def cloth_widths(
    points: Float[Array, "N M 3"],
    pairs: Int[Array, "P 2"],
    group: Int[Array, " P"],
    cloth_of_group: Int[Array, " G"],
    n_cloths: int,
) -> Float[Array, " C"]:
    """Width of each cloth: the largest distance from a point of one of its
    seams to the nearest of its other seams.

    `pairs[k] = (i, j)` are the ordered pairs of distinct seams of a cloth,
    `group[k]` numbers the (cloth, i) they belong to, `cloth_of_group` the cloth
    of each group (see `_width_index`)."""

    def one(ij):
        p, q = points[ij[0]], points[ij[1]]
        return _point_segment(p, q[:-1], q[1:]).min(axis=1)  # (M,)

    d = jax.vmap(one)(pairs)  # (P, M)
    n_groups = cloth_of_group.shape[0]
    near = jax.ops.segment_min(d, group, num_segments=n_groups)  # (G, M)
    w = jax.ops.segment_max(near.max(axis=1), cloth_of_group, num_segments=n_cloths)
    # a cloth with one seam (between a seam and the boundary) has no other seam
    # to measure against: width 0, left out of the objective (`objective`)
    return jnp.where(jnp.isfinite(w), w, 0.0)


def _width_index(cloth_seams: list[list[int]]):
    pairs, group, cloth_of_group = [], [], []
    for c, ids in enumerate(cloth_seams):
        for i in ids:
            g = len(cloth_of_group)
            cloth_of_group.append(c)
            for j in ids:
                if j != i:
                    pairs.append((i, j))
                    group.append(g)
    return (
        np.asarray(pairs, np.int32).reshape(-1, 2),
        np.asarray(group, np.int32),
        np.asarray(cloth_of_group, np.int32),
    )


def _pairs(cloth_seams: list[list[int]]) -> np.ndarray:
    pairs = [c for c in cloth_seams if len(c) == 2]
    return np.asarray(pairs, np.int32).reshape(-1, 2)


def objective(
    lengths: Float[Array, " N"],
    widths: Float[Array, " C"],
    pairs: Int[Array, "P 2"],
    roll_width: float,
    weights: Weights,
) -> tuple[Float[Array, ""], dict]:
    """The layout objective J (module docstring) and its three terms."""
    wt = (1.0 - weights.margin) * roll_width
    measured = widths > 0  # cloths with one seam have no width measure
    r = jnp.where(measured, widths / wt, 1.0)
    fit = jnp.sum(jax.nn.relu(r - 1.0) ** 2)
    fill = jnp.sum((1.0 - r) ** 2) / jnp.maximum(jnp.sum(measured), 1)
    if pairs.shape[0]:
        dl = (lengths[pairs[:, 0]] - lengths[pairs[:, 1]]) / jnp.mean(lengths)
        equal = jnp.sum(dl**2)
    else:
        equal = jnp.zeros(())
    j = weights.fit * fit + weights.fill * fill + weights.equal * equal
    return j, {"fit": fit, "fill": fill, "equal": equal}


@eqx.filter_jit
def _value_and_grad(
    mesh, packed, loop_a, loop_b, x, traced, index, pairs, scale, rw, w
):
    def f(x):
        q = _replay_batch(mesh, packed, loop_a, loop_b, x, traced)
        # (pyright misreads *args of unknown length followed by more arguments)
        widths = cloth_widths(q.points, *index, scale.shape[0]) * scale  # pyright: ignore[reportCallIssue]
        j, terms = objective(q.length, widths, pairs, rw, w)
        return j, (terms, widths, q.length)

    return jax.value_and_grad(f, has_aux=True)(x)


# ----------------------------------------------------------------------- optimiser


@dataclasses.dataclass
class Result:
    """Outcome of `optimise`: the layouts, objective values, widths (proxy), seam
    lengths at the start and the end, and the history of J."""

    start: Layout
    layout: Layout
    j_start: float
    j_end: float
    widths_start: np.ndarray
    widths_end: np.ndarray
    lengths_start: np.ndarray
    lengths_end: np.ndarray
    history: list[float]
    cloth_seams: list[list[int]]


class _Evaluator:
    def __init__(self, mesh, layout, cloth_seams, roll_width, weights, scale):
        self.mesh, self.layout, self.rw, self.w = mesh, layout, roll_width, weights
        self.index = tuple(jnp.asarray(a) for a in _width_index(cloth_seams))
        self.pairs = jnp.asarray(_pairs(cloth_seams))
        self.scale = jnp.asarray(scale, float)
        self.order = _cyclic_orders(layout, layout.x)

    def __call__(self, x):
        lay = self.layout.with_x(x)
        if _cyclic_orders(lay, x) != self.order:
            return math.inf, None, None
        # the replay re-solves the laser ray's crossings (System 16): trace with it
        paths = trace_seams(self.mesh, lay, self.w.options, "laser")
        if np.any(np.asarray(paths.status) != Status.SUCCESS):
            return math.inf, None, None
        (j, aux), g = _value_and_grad(
            self.mesh,
            lay.packed,
            jnp.asarray(lay.loop_a),
            jnp.asarray(lay.loop_b),
            jnp.asarray(x),
            paths,
            self.index,
            self.pairs,
            self.scale,
            self.rw,
            self.w,
        )
        return float(j), np.asarray(g), aux


def _cyclic_orders(layout: Layout, x: np.ndarray) -> list[tuple]:
    """Per loop, the cyclic order of the seam ends on it (to reject crossings)."""
    n = layout.n_seams
    loops = np.concatenate([layout.loop_a, layout.loop_b])
    s = np.mod(x, 1.0)
    out = []
    for lp in np.unique(loops):
        idx = np.flatnonzero(loops == lp)
        rel = np.mod(s[idx] - s[idx[0]], 1.0)
        out.append(tuple(idx[np.argsort(rel)] % (2 * n)))
    return out


def optimise(
    mesh: Mesh,
    layout: Layout,
    roll_width: float,
    cloth_seams: list[list[int]],
    *,
    weights: Weights = Weights(),
    steps: int = 40,
    max_move: float = 0.01,
    width_scale: np.ndarray | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> Result:
    """Minimise the layout objective over the seam-end parameters by BFGS with
    Armijo backtracking, re-tracing the seams at every evaluation (see the
    module docstring).

    **Arguments:**

    - `cloth_seams`: per cloth, its seam ids (`cut.CutMesh.cloth_seams()` of
      the cut at the start layout; the topology does not change).
    - `steps`: BFGS iterations; `max_move`: largest change of any parameter per
      step (normalised arc length).
    - `width_scale`: per-cloth factors applied to the width measure (calibration
      of the proxy against the flattened width, see `jaxgeo.cutting.flatten`).
    - `progress`: called as `progress(step, J)`.
    """
    scale = np.ones(len(cloth_seams)) if width_scale is None else width_scale
    ev = _Evaluator(mesh, layout, cloth_seams, roll_width, weights, scale)
    x = layout.x.copy()
    f, g, aux = ev(x)
    if not math.isfinite(f):
        raise JaxgeoError("the start layout cannot be traced")
    assert g is not None and aux is not None  # (None only with f = inf)
    j0, w0, l0 = f, np.asarray(aux[1]), np.asarray(aux[2])
    h = np.eye(len(x)) * (max_move / max(np.abs(g).max(), 1e-12))
    history = [f]
    for k in range(steps):
        d = -h @ g
        if g @ d >= 0:  # not a descent direction: restart from steepest descent
            h = np.eye(len(x)) * (max_move / max(np.abs(g).max(), 1e-12))
            d = -h @ g
        d *= min(1.0, max_move / max(np.abs(d).max(), 1e-300))
        alpha, accepted = 1.0, False
        for _ in range(10):
            x_new = x + alpha * d
            f_new, g_new, aux_new = ev(x_new)
            if f_new <= f + 1e-4 * alpha * (g @ d):
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            break
        assert g_new is not None and aux_new is not None  # (f_new is finite)
        s, y = x_new - x, g_new - g
        if s @ y > 1e-12:
            rho = 1.0 / (s @ y)
            i = np.eye(len(x))
            h = (i - rho * np.outer(s, y)) @ h @ (i - rho * np.outer(y, s))
            h += rho * np.outer(s, s)
        x, f, g, aux = x_new, f_new, g_new, aux_new
        history.append(f)
        if progress is not None:
            progress(k + 1, f)
        if np.abs(g).max() * max_move < 1e-10:
            break
    return Result(
        layout,
        layout.with_x(x),
        j0,
        f,
        w0,
        np.asarray(aux[1]),
        l0,
        np.asarray(aux[2]),
        history,
        cloth_seams,
    )


def fit_roll(
    mesh: Mesh,
    layout: Layout,
    roll_width: float,
    *,
    rounds: int = 3,
    steps: int = 25,
    weights: Weights = Weights(),
    method: Method = "exact",
    log: Callable[[str], None] | None = None,
):
    """Optimise `layout` until every flattened cloth fits the roll.

    Each round runs `optimise` (laser seams, replayed), cuts along the seams
    traced with `method` (exact by default) and flattens the result
    (`jaxgeo.cutting.flatten.make_pattern`) and rescales each cloth's width measure by
    flattened/measured width (the 3-D distance between seams misses the bend a
    cloth takes when flattened), then optimises again from there.

    **Returns:** `(result_of_first_round, layout, pattern, history)` where
    `history` lists `(J, max flattened width)` per round.
    """
    log = log or (lambda msg: None)
    cut0, _ = cut(mesh, layout, weights.options, method)
    cloth_seams = cut0.cloth_seams()
    pat = make_pattern(cut0)
    log(f"start: {cut0.n_cloths} cloths, widest {pat.widths.max():.4g}")
    scale = np.ones(len(cloth_seams))
    first, current, history = None, layout, []
    for r in range(rounds):
        res = optimise(
            mesh,
            current,
            roll_width,
            cloth_seams,
            weights=weights,
            steps=steps,
            width_scale=scale,
            progress=lambda k, j, r=r: log(f"round {r + 1} step {k}: J = {j:.5g}"),
        )
        first = first or res
        c, _ = cut(mesh, res.layout, weights.options, method)
        if c.cloth_seams() != cloth_seams:
            log("the cloth topology changed; keeping the previous layout")
            break
        current, pat = res.layout, make_pattern(c)
        history.append((res.j_end, float(pat.widths.max())))
        log(f"round {r + 1}: J = {res.j_end:.5g}, widest {pat.widths.max():.4g}")
        if (pat.widths <= roll_width).all():
            break
        # cloths with one seam have no width measure (0): keep their scale
        measured = res.widths_end > 0
        ratio = pat.widths / np.where(measured, res.widths_end, 1.0)
        scale = np.where(measured, scale * ratio, scale)
    return first, current, pat, history


def _stderr_progress(step: int, j: float) -> None:  # pragma: no cover
    print(f"  step {step:3d}  J = {j:.6g}", file=sys.stderr)
