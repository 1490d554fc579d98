"""Seam layouts on tent surfaces, differentiable seam measures, and their optimisation.

A layout is `N` geodesic seams, seam `i` from loop `loop_a[i]` at normalised arc
length `s_a[i]` to loop `loop_b[i]` at `s_b[i]` (see `jaxgeo.boundary`). The
parameters `x = (s_a, s_b)` are optimised.

**Measures** (differentiable in `x` through the replayed geodesics):

- seam lengths `L_i`;
- the width of cloth `c` bounded by seams `S_c`: the largest distance from a point
  of one of its seams to the other seams of the cloth,
  `w_c = max_{i∈S_c} max_{p∈seam i} min_{j∈S_c, j≠i} dist(p, seam j)` — for a
  cloth between two seams, the largest distance between them;
- the objective, with roll width `W` and target `W_t = (1 − margin)·W`:

      J = α Σ_c relu(w_c/W_t − 1)²                        (fit the roll)
        + β (1/C) Σ_c (1 − w_c/W_t)²                      (fill the roll)
        + γ Σ_{c: |S_c|=2} ((L_i − L_j)/L̄)²               (equal seam lengths)

  The geodesic seams flatten to their own length within the flattening strain
  (`jaxgeo.pattern` fits seam edges 10× harder), so the 3-D lengths stand for the
  flattened ones.

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

from ._errors import JaxgeoError
from .boundary import (
    BoundaryLoop,
    PackedLoops,
    boundary_loops,
    loop_parameter,
    pack_loops,
    packed_point,
)
from .geodesic import _solve
from .locate import DEFAULT_MAX_DISTANCE
from .mesh import Mesh
from .normals import vertex_normals
from .path import Path, Status
from .replay import replay
from .trace import TraceOptions

__all__ = [
    "Layout",
    "Weights",
    "cloth_widths",
    "objective",
    "optimise",
    "peaks_layout",
    "radial_layout",
    "trace_seams",
]

#: Seam ends are moved this fraction into their boundary face, off the boundary
#: edge itself, where the laser ray's chord projection could leave the mesh.
INSET = 1e-6


@dataclasses.dataclass
class Layout:
    """Seams between boundary loops.

    - `loops`: the mesh's boundary loops (`boundary_loops`), `packed` the same
      padded for vmapping.
    - `loop_a`, `loop_b`: `(N,)` loop index of each seam's two ends.
    - `s_a`, `s_b`: `(N,)` their normalised arc-length parameters.
    """

    loops: list[BoundaryLoop]
    packed: PackedLoops
    loop_a: np.ndarray
    loop_b: np.ndarray
    s_a: np.ndarray
    s_b: np.ndarray

    @property
    def n_seams(self) -> int:
        return len(self.s_a)

    @property
    def x(self) -> np.ndarray:
        return np.concatenate([self.s_a, self.s_b])

    def with_x(self, x: np.ndarray) -> Layout:
        n = self.n_seams
        return dataclasses.replace(self, s_a=np.mod(x[:n], 1.0), s_b=np.mod(x[n:], 1.0))

    def end_points(self, mesh: Mesh) -> np.ndarray:
        """`(N, 2, 3)` the seam ends in 3-D."""
        out = []
        for la, lb, a, b in zip(self.loop_a, self.loop_b, self.s_a, self.s_b):
            pa = packed_point(mesh, self.packed, int(la), float(a))
            pb = packed_point(mesh, self.packed, int(lb), float(b))
            out.append([np.asarray(pa.position(mesh)), np.asarray(pb.position(mesh))])
        return np.asarray(out)


@dataclasses.dataclass(frozen=True)
class Weights:
    """Weights of the objective's three terms and the safety margin under the
    roll width (the measured width is a proxy of the flattened one)."""

    fit: float = 100.0
    fill: float = 1.0
    equal: float = 1.0
    margin: float = 0.05
    options: TraceOptions = TraceOptions(candidates="local", max_points=256)


# ----------------------------------------------------------------------- layouts


def _plan_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _ray_hit(poly: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray | None:
    """First point where the plan ray c + t·d (t > 0) meets the closed polyline."""
    a, b = poly[:-1, :2], poly[1:, :2]
    e = b - a
    den = d[0] * e[:, 1] - d[1] * e[:, 0]
    ok = np.abs(den) > 1e-14
    den = np.where(ok, den, 1.0)
    w = a - c
    t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / den
    u = (w[:, 0] * d[1] - w[:, 1] * d[0]) / den
    good = ok & (t > 0) & (u >= 0) & (u <= 1)
    if not good.any():
        return None
    k = np.flatnonzero(good)[np.argmin(t[good])]
    return poly[k] + u[k] * (poly[k + 1] - poly[k])


def _ring_seams(mesh, loops, ring: int, angles, keep=None):
    """Seams from `ring` at plan angles `angles` (around the ring's centre) to the
    outer loop (0) where the ray from the centre meets it (plan view, z up)."""
    rp = loops[ring].polyline(mesh)
    op = loops[0].polyline(mesh)
    centre = rp[:-1].mean(axis=0)
    sa, sb = [], []
    for th in angles:
        d = np.array([math.cos(th), math.sin(th)])
        hit_r = _ray_hit(rp, centre[:2], d)
        hit_o = _ray_hit(op, centre[:2], d)
        if hit_r is None or hit_o is None or (keep is not None and not keep(hit_o)):
            continue
        sa.append(loop_parameter(mesh, loops[ring], hit_r))
        sb.append(loop_parameter(mesh, loops[0], hit_o))
    return sa, sb


def _layout(loops, la, lb, sa, sb) -> Layout:
    return Layout(
        loops,
        pack_loops(loops),
        np.asarray(la, np.int32),
        np.asarray(lb, np.int32),
        np.asarray(sa, float),
        np.asarray(sb, float),
    )


def radial_layout(mesh: Mesh, n: int, offset: float = 0.0) -> Layout:
    """`n` radial seams from the inner ring (loop 1) to the outer ring (loop 0)
    at uniformly spaced plan angles `offset + 2πk/n` around the inner ring's
    centre (a cone tent, Fig. 14 of the paper)."""
    loops = boundary_loops(mesh)
    if len(loops) < 2:
        raise JaxgeoError("radial_layout needs a mesh with two boundary loops")
    angles = offset + 2 * np.pi * np.arange(n) / n
    sa, sb = _ring_seams(mesh, loops, 1, angles)
    if len(sa) != n:
        raise JaxgeoError("radial_layout: some rays miss a loop (not a ring tent?)")
    return _layout(loops, [1] * n, [0] * n, sa, sb)


def peaks_layout(
    mesh: Mesh, n_around: int, n_valley: int, valley_halfwidth: float
) -> Layout:
    """Seams of a tent with several peak rings (the twin-peak tent, Fig. 13):

    - `n_valley` valley seams across the outer loop, from its top side to its
      bottom side at plan x uniformly spaced in [−h, h] (`h = valley_halfwidth`);
    - from each peak ring (loops 1, 2, …), seams at plan angles `2πk/n_around`
      around its centre to where the ray meets the outer loop, keeping the rays
      that land beyond the valley band (|x| > h + spacing).

    Uniform angles: cloths near the corners of the outer loop come out wider.
    """
    loops = boundary_loops(mesh)
    op = loops[0].polyline(mesh)
    top, bottom = op[:, 1].max(), op[:, 1].min()
    xs = np.linspace(-valley_halfwidth, valley_halfwidth, n_valley)
    gap = 2 * valley_halfwidth / max(n_valley - 1, 1)
    la, lb, sa, sb = [], [], [], []
    for x in xs:
        sa.append(loop_parameter(mesh, loops[0], [x, top, 0.0]))
        sb.append(loop_parameter(mesh, loops[0], [x, bottom, 0.0]))
        la.append(0)
        lb.append(0)
    angles = 2 * np.pi * np.arange(n_around) / n_around
    for ring in range(1, len(loops)):
        side = np.sign(loops[ring].polyline(mesh)[:, 0].mean())
        ra, rb = _ring_seams(
            mesh,
            loops,
            ring,
            angles,
            keep=lambda p, s=side: s * p[0] > valley_halfwidth + gap,
        )
        la += [ring] * len(ra)
        lb += [0] * len(ra)
        sa += ra
        sb += rb
    return _layout(loops, la, lb, sa, sb)


# ----------------------------------------------------------------------- tracing


@eqx.filter_jit
def _trace_batch(mesh, packed, loop_a, loop_b, s_a, s_b, options):
    def one(la, lb, a, b):
        p1 = packed_point(mesh, packed, la, a, INSET)
        p2 = packed_point(mesh, packed, lb, b, INSET)
        path = _solve(mesh, p1, p2, DEFAULT_MAX_DISTANCE, "uniform", options)[0]
        return path, p1.bary, p2.bary

    return jax.vmap(one)(loop_a, loop_b, s_a, s_b)


def trace_seams(
    mesh: Mesh, layout: Layout, options: TraceOptions | None = None
) -> tuple[Path, np.ndarray]:
    """Trace every seam of `layout` (one vmapped, jitted call).

    **Returns:** `(paths, end_bary)`: a batched `Path` (leading axis N) and the
    endpoints' barycentric coordinates `(N, 2, 3)`.
    """
    options = options or Weights().options
    paths, b1, b2 = _trace_batch(
        mesh,
        layout.packed,
        jnp.asarray(layout.loop_a),
        jnp.asarray(layout.loop_b),
        jnp.asarray(layout.s_a),
        jnp.asarray(layout.s_b),
        options,
    )
    return paths, np.stack([np.asarray(b1), np.asarray(b2)], axis=1)


def unbatch(paths: Path, i: int) -> Path:
    """Seam `i` of a batched `Path`."""
    return jax.tree.map(lambda x: x[i], paths)


def _replay_batch(mesh, packed, loop_a, loop_b, x, traced) -> Path:
    n = loop_a.shape[0]
    normals = vertex_normals(mesh.vertices, mesh.faces, "uniform")

    def one(la, lb, a, b, p):
        p1 = packed_point(mesh, packed, la, a, INSET)
        p2 = packed_point(mesh, packed, lb, b, INSET)
        return replay(mesh, normals, p1, p2, p)

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
    points: Float[Array, "N M 3"], cloth_seams: Int[Array, "C S"]
) -> Float[Array, " C"]:
    """Width of each cloth: the largest distance from a point of one of its
    seams to the nearest of its other seams (`cloth_seams` padded with −1)."""

    def one(ids):
        valid = ids >= 0
        pts = points[jnp.maximum(ids, 0)]  # (S, M, 3)

        def row(i):
            def col(j):
                d = _point_segment(pts[i], pts[j, :-1], pts[j, 1:]).min(axis=1)
                ok = valid[j] & (i != j)
                return jnp.where(ok, d, jnp.inf)

            return jax.vmap(col)(jnp.arange(ids.shape[0])).min(axis=0).max()

        w = jax.vmap(row)(jnp.arange(ids.shape[0]))
        return jnp.max(jnp.where(valid, w, -jnp.inf))

    return jax.vmap(one)(cloth_seams)


def _pairs(cloth_seams: list[list[int]]) -> np.ndarray:
    pairs = [c for c in cloth_seams if len(c) == 2]
    return np.asarray(pairs, np.int32).reshape(-1, 2)


def _pad(cloth_seams: list[list[int]]) -> np.ndarray:
    s = max(len(c) for c in cloth_seams)
    return np.asarray([c + [-1] * (s - len(c)) for c in cloth_seams], np.int32)


def objective(
    lengths: Float[Array, " N"],
    widths: Float[Array, " C"],
    pairs: Int[Array, "P 2"],
    roll_width: float,
    weights: Weights,
) -> tuple[Float[Array, ""], dict]:
    """The layout objective J (module docstring) and its three terms."""
    wt = (1.0 - weights.margin) * roll_width
    r = widths / wt
    fit = jnp.sum(jax.nn.relu(r - 1.0) ** 2)
    fill = jnp.mean((1.0 - r) ** 2)
    if pairs.shape[0]:
        dl = (lengths[pairs[:, 0]] - lengths[pairs[:, 1]]) / jnp.mean(lengths)
        equal = jnp.sum(dl**2)
    else:
        equal = jnp.zeros(())
    j = weights.fit * fit + weights.fill * fill + weights.equal * equal
    return j, {"fit": fit, "fill": fill, "equal": equal}


@eqx.filter_jit
def _value_and_grad(
    mesh, packed, loop_a, loop_b, x, traced, cloths, pairs, scale, rw, w
):
    def f(x):
        q = _replay_batch(mesh, packed, loop_a, loop_b, x, traced)
        widths = cloth_widths(q.points, cloths) * scale
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
        self.cloths = jnp.asarray(_pad(cloth_seams))
        self.pairs = jnp.asarray(_pairs(cloth_seams))
        self.scale = jnp.asarray(scale, float)
        self.order = _cyclic_orders(layout, layout.x)

    def __call__(self, x):
        lay = self.layout.with_x(x)
        if _cyclic_orders(lay, x) != self.order:
            return math.inf, None, None
        paths, _ = trace_seams(self.mesh, lay, self.w.options)
        if np.any(np.asarray(paths.status) != Status.SUCCESS):
            return math.inf, None, None
        (j, aux), g = _value_and_grad(
            self.mesh,
            lay.packed,
            jnp.asarray(lay.loop_a),
            jnp.asarray(lay.loop_b),
            jnp.asarray(x),
            paths,
            self.cloths,
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

    - `cloth_seams`: per cloth, its seam ids (`pattern.CutMesh.cloth_seams()` of
      the cut at the start layout; the topology does not change).
    - `steps`: BFGS iterations; `max_move`: largest change of any parameter per
      step (normalised arc length).
    - `width_scale`: per-cloth factors applied to the width measure (calibration
      of the proxy against the flattened width, see `jaxgeo.pattern`).
    - `progress`: called as `progress(step, J)`.
    """
    scale = np.ones(len(cloth_seams)) if width_scale is None else width_scale
    ev = _Evaluator(mesh, layout, cloth_seams, roll_width, weights, scale)
    x = layout.x.copy()
    f, g, aux = ev(x)
    if not math.isfinite(f):
        raise JaxgeoError("the start layout cannot be traced")
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


def _stderr_progress(step: int, j: float) -> None:  # pragma: no cover
    print(f"  step {step:3d}  J = {j:.6g}", file=sys.stderr)
