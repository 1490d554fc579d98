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
        + β mean_c (1 − w_c/W_t)²                         (fill the roll)
        + γ Σ_{c: |S_c|=2} ((L_i − L_j)/L̄)²               (equal seam lengths)

  A cloth with a single seam (between it and the boundary) has no width
  measure and is left out of the fit and fill terms (and of the mean).
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
from .geodesic import shortest_path
from .mesh import Mesh
from .methods import Method
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
    "parallel_layout",
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
    options: TraceOptions = TraceOptions(candidates="local", max_points=160)


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
    mesh: Mesh,
    n_per_ring: int,
    n_valley: int,
    valley_halfwidth: float,
    sector: float = 160.0,
    shift: float = 0.02,
) -> Layout:
    """Seams of a tent with two peak rings side by side along x (the twin-peak
    tent, Fig. 13), plan view, z up:

    - `n_valley` valley seams across the outer loop (loop 0), from its top side
      to its bottom side at x uniformly spaced in [−h, h] + `shift`
      (`h = valley_halfwidth`; the shift keeps them off the mesh's line x = 0);
    - from each peak ring (loops 1, 2), `n_per_ring` seams leaving the ring at
      uniform plan angles in [−sector, sector] degrees from the direction away
      from the valley, ending at uniformly spaced points of the outer loop's arc
      beyond the valley band (|x| ≥ h + spacing), matched in angular order.

    Uniform spacing on both ends: the cloths at the corners of the outer loop
    come out wider than the others.
    """
    loops = boundary_loops(mesh)
    if len(loops) != 3:
        raise JaxgeoError("peaks_layout needs three boundary loops (twin peaks)")
    outer = loops[0]
    op = outer.polyline(mesh)
    top, bottom = op[:, 1].max(), op[:, 1].min()
    gap = 2 * valley_halfwidth / max(n_valley - 1, 1)
    xs = np.linspace(-valley_halfwidth, valley_halfwidth, n_valley) + shift
    la, lb, sa, sb = [], [], [], []
    for x in xs:
        sa.append(loop_parameter(mesh, outer, [x, top, 0.0]))
        sb.append(loop_parameter(mesh, outer, [x, bottom, 0.0]))
        la.append(0)
        lb.append(0)
    cum = np.asarray(outer.cumulative(mesh))
    cum = cum / cum[-1]
    for ring in (1, 2):
        rp = loops[ring].polyline(mesh)
        centre = rp[:-1].mean(axis=0)
        side = 1.0 if centre[0] > 0 else -1.0
        ang = np.deg2rad(np.linspace(-sector, sector, n_per_ring))
        ang = ang if side > 0 else np.pi - ang[::-1]
        for th in ang:
            hit = _ray_hit(rp, centre[:2], np.array([math.cos(th), math.sin(th)]))
            assert hit is not None  # a ray from the ring's centre meets the ring
            sa.append(loop_parameter(mesh, loops[ring], hit))
        # outer arc beyond the valley band, through the far side of the loop
        x_cut = side * (valley_halfwidth + gap + shift * side)
        s0 = loop_parameter(mesh, outer, [x_cut, bottom, 0.0])
        s1 = loop_parameter(mesh, outer, [x_cut, top, 0.0])
        s_far = loop_parameter(mesh, outer, [side * op[:, 0].max() * 2, 0.0, 0.0])
        span = np.mod(s1 - s0, 1.0)
        if np.mod(s_far - s0, 1.0) > span:  # the arc s0 -> s1 misses the far side
            s0, s1, span = s1, s0, 1.0 - span
        ends = np.mod(s0 + span * np.linspace(0.0, 1.0, n_per_ring + 2)[1:-1], 1.0)
        # match ring angles to outer points by plan angle around the ring centre
        pts = np.array([_point_on(op, cum, e) for e in ends])
        order_o = np.argsort(_unwrap(pts, centre, side))
        ring_pts = np.array([_point_on(rp, _cum(rp), s) for s in sa[-n_per_ring:]])
        order_r = np.argsort(_unwrap(ring_pts, centre, side))
        matched = np.empty(n_per_ring)
        matched[order_r] = ends[order_o]
        sb += matched.tolist()
        la += [ring] * n_per_ring
        lb += [0] * n_per_ring
    return _layout(loops, la, lb, sa, sb)


def parallel_layout(mesh: Mesh, n: int, angle: float = 0.0) -> Layout:
    """`n` seams across a mesh with one boundary loop (a four-point sail), along
    parallel plan lines at `angle` degrees from the x axis (z up), spaced
    uniformly across the loop through its centroid: line `k` at `(k + 1)/(n +
    1)` of the loop's plan width there, measured across the lines (the width
    between the sagging edge cables, not between the corners), so the `n + 1`
    cloths are bands of equal plan width at the middle. Both ends of every seam
    lie on loop 0."""
    loops = boundary_loops(mesh)
    if len(loops) != 1:
        raise JaxgeoError(
            f"parallel_layout needs one boundary loop, the mesh has {len(loops)}"
        )
    if n < 1:
        raise JaxgeoError("parallel_layout needs n >= 1 seams")
    op = loops[0].polyline(mesh)
    th = math.radians(angle)
    d = np.array([math.cos(th), math.sin(th)])
    across = np.array([-d[1], d[0]])
    centre = op[:-1, :2].mean(axis=0)
    lo, hi = _ray_hit(op, centre, -across), _ray_hit(op, centre, across)
    if lo is None or hi is None:
        raise JaxgeoError("parallel_layout: the loop's centroid lies outside it")
    t0, t1 = lo[:2] @ across, hi[:2] @ across
    sa, sb = [], []
    for k in range(n):
        off = t0 + (k + 1) / (n + 1) * (t1 - t0)
        c = centre + (off - centre @ across) * across
        a, b = _ray_hit(op, c, -d), _ray_hit(op, c, d)
        if a is None or b is None:
            raise JaxgeoError("parallel_layout: a seam line misses the boundary")
        sa.append(loop_parameter(mesh, loops[0], a))
        sb.append(loop_parameter(mesh, loops[0], b))
    return _layout(loops, [0] * n, [0] * n, sa, sb)


def _cum(poly: np.ndarray) -> np.ndarray:
    c = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))]
    )
    return c / c[-1]


def _point_on(poly: np.ndarray, cum: np.ndarray, s: float) -> np.ndarray:
    return np.array([np.interp(s, cum, poly[:, k]) for k in range(3)])


def _unwrap(pts: np.ndarray, centre: np.ndarray, side: float) -> np.ndarray:
    """Plan angles around `centre`, measured from the valley direction (−side·x)
    so they increase without a jump across the far side."""
    d = pts[:, :2] - centre[:2]
    return np.mod(np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(0.0, -side), 2 * np.pi)


# ----------------------------------------------------------------------- tracing


@eqx.filter_jit
def _trace_batch(
    mesh, packed, loop_a, loop_b, s_a, s_b, options, method: Method = "exact"
):
    def one(la, lb, a, b):
        p1 = packed_point(mesh, packed, la, a, INSET)
        p2 = packed_point(mesh, packed, lb, b, INSET)
        return shortest_path(
            mesh,
            p1,
            p2,
            method=method,
            candidates=options.candidates,
            max_points=options.max_points,
            throw=False,
        )

    return jax.vmap(one)(loop_a, loop_b, s_a, s_b)


def trace_seams(
    mesh: Mesh,
    layout: Layout,
    options: TraceOptions | None = None,
    method: Method = "exact",
) -> Path:
    """Trace every seam of `layout` (one vmapped, jitted call of
    `jaxgeo.shortest_path` with `method`: the exact geodesic by default, as
    everywhere in jaxgeo; `options.candidates` acts on the laser method only).

    **Returns:** a batched `Path` (leading axis N, one row per seam); its
    `start` and `end` are the seam ends on the boundary (`packed_point`).
    """
    options = options or Weights().options
    return _trace_batch(
        mesh,
        layout.packed,
        jnp.asarray(layout.loop_a),
        jnp.asarray(layout.loop_b),
        jnp.asarray(layout.s_a),
        jnp.asarray(layout.s_b),
        options,
        method,
    )


def unbatch(paths: Path, i: int) -> Path:
    """Seam `i` of a batched `Path`."""
    return jax.tree.map(lambda x: x[i], paths)


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


def cut(
    mesh: Mesh,
    layout: Layout,
    options: TraceOptions | None = None,
    method: Method = "exact",
):
    """Trace the seams of `layout` with `method` (exact by default) and cut
    `mesh` along them (`jaxgeo.pattern.cut_mesh`). Returns `(cut_mesh, paths)`."""
    from .pattern import cut_mesh

    paths = trace_seams(mesh, layout, options, method)
    bad = np.flatnonzero(np.asarray(paths.status) != Status.SUCCESS)
    if bad.size:
        raise JaxgeoError(f"seams {bad.tolist()} could not be traced")
    return cut_mesh(mesh, paths), paths


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
    (`jaxgeo.pattern.make_pattern`) and rescales each cloth's width measure by
    flattened/measured width (the 3-D distance between seams misses the bend a
    cloth takes when flattened), then optimises again from there.

    **Returns:** `(result_of_first_round, layout, pattern, history)` where
    `history` lists `(J, max flattened width)` per round.
    """
    from .pattern import make_pattern

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
