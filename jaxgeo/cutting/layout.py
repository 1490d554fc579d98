"""Seam layouts on tent surfaces and their tracing.

A layout is `N` geodesic seams, seam `i` from loop `loop_a[i]` at normalised arc
length `s_a[i]` to loop `loop_b[i]` at `s_b[i]` (see `jaxgeo.boundary`); the
parameters `x = (s_a, s_b)` are what `jaxgeo.cutting.seam_width.optimise` and
`jaxgeo.cutting.optimise_seams` move. The constructors place seams for the
tents of the paper (`radial_layout`; `peaks_layout` and `bridged_layout` for
twin peaks) and for a four-point sail (`parallel_layout`); `trace_seams`
traces them all in one vmapped, jitted `shortest_path`.

(Moved here from `jaxgeo.seams`, which still re-exports the public names.)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import JaxgeoError
from ..boundary import (
    BoundaryLoop,
    PackedLoops,
    boundary_loops,
    loop_parameter,
    pack_loops,
    packed_point,
)
from ..geodesic import shortest_path
from ..mesh import Mesh
from ..methods import Method
from ..path import Path
from ..trace import TraceOptions

__all__ = [
    "INSET",
    "TRACE_OPTIONS",
    "Layout",
    "bridged_layout",
    "parallel_layout",
    "peaks_layout",
    "radial_layout",
    "trace_seams",
    "unbatch",
]

#: Seam ends are moved this fraction into their boundary face, off the boundary
#: edge itself, where the laser ray's chord projection could leave the mesh.
INSET = 1e-6
#: How seams are traced unless told otherwise (the laser method's options; the
#: exact method ignores `candidates`): also `seam_width.Weights().options`.
TRACE_OPTIONS = TraceOptions(candidates="local", max_points=160)


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


def _ring_point(mesh, loop, poly: np.ndarray, centre: np.ndarray, th: float) -> float:
    """The parameter on the ring `loop` (its polyline `poly`) where the plan ray
    from the ring's `centre` at angle `th` (radians) meets it."""
    hit = _ray_hit(poly, centre[:2], np.array([math.cos(th), math.sin(th)]))
    assert hit is not None  # a ray from the ring's centre meets the ring
    return loop_parameter(mesh, loop, hit)


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
        sa += [_ring_point(mesh, loops[ring], rp, centre, th) for th in ang]
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


def _angles(n_or_angles, uniform) -> np.ndarray:
    """`uniform(n)` for a count `n`, else the given angles (degrees)."""
    if np.ndim(n_or_angles) == 0:
        n_or_angles = uniform(max(int(n_or_angles), 0))
    a = np.asarray(n_or_angles, float)
    if a.size == 0:
        raise JaxgeoError("bridged_layout needs at least one seam of each kind")
    return a


def bridged_layout(
    mesh: Mesh,
    n_per_ring: int | Sequence[float],
    n_bridges: int | Sequence[float],
    sector: float = 130.0,
    shift: float = 1.0,
) -> Layout:
    """Seams of a tent with two peak rings side by side along x (the twin-peak
    tent), without seams across the valley: every seam leaves a ring. Plan
    view, z up; angles in degrees round each ring's centre, measured from the
    direction away from the other ring (mirrored between the two rings):

    - from each ring, `n_per_ring` seams at angles uniform in [−sector,
      sector] + `shift`, each to the outer loop (loop 0) where the plan ray
      from the ring's centre at that angle meets it;
    - `n_bridges` seams from ring to ring across the valley (loop 1 to loop
      2), at angles uniform in the gap (sector, 360° − sector) + `shift`.

    A sequence instead of a count gives the angles themselves (degrees, before
    `shift`); `sector` then plays no part in them.

    So every cloth touches a peak ring and none wraps round one, as the
    valley-side cloths of `peaks_layout` do (their flattening is not unique:
    the reassembly RMS moves by 1.7 % with one-ulp changes of the cut,
    docs/cutting.md). The `shift` keeps seams off the mesh's lines y = 0 and
    x = 0, along which a seam would change its sequence of mesh elements at
    any move of its ends. On the built-in tent, `bridged_layout(tent, 9, 3)`
    and four variants 1°–5° apart give a uniform RMS stress deviation of
    7.2–8.2 kN/m, each steady to 1e-5 relative under one-ulp changes
    (docs/cutting.md, "Session 18"); the CLI lays it for a mesh with three
    boundary loops.
    """
    loops = boundary_loops(mesh)
    if len(loops) != 3:
        raise JaxgeoError(
            f"bridged_layout needs three boundary loops (twin peaks), the mesh "
            f"has {len(loops)}"
        )
    if not 0.0 < sector < 180.0:
        raise JaxgeoError("bridged_layout needs 0 < sector < 180 degrees")
    gap = 360.0 - 2.0 * sector
    out = _angles(n_per_ring, lambda n: np.linspace(-sector, sector, n)) + shift
    bridges = (
        _angles(n_bridges, lambda n: sector + gap * np.arange(1, n + 1) / (n + 1))
        + shift
    )
    rings = {}
    for ring in (1, 2):
        rp = loops[ring].polyline(mesh)
        rings[ring] = (rp, rp[:-1, :2].mean(axis=0))

    def plan(ring: int, deg: float) -> float:
        """The plan angle (radians) of `deg` from the direction away from the
        other ring: mirrored on the left ring."""
        th = math.radians(deg)
        return th if rings[ring][1][0] > 0 else math.pi - th

    la, lb, sa, sb = [], [], [], []
    for ring in (1, 2):
        a, b = _ring_seams(mesh, loops, ring, [plan(ring, deg) for deg in out])
        if len(a) != len(out):
            raise JaxgeoError("bridged_layout: a ray from a ring misses loop 0")
        la += [ring] * len(a)
        lb += [0] * len(a)
        sa += a
        sb += b

    def on_ring(ring: int, deg: float) -> float:
        poly, centre = rings[ring]
        return _ring_point(mesh, loops[ring], poly, centre, plan(ring, deg))

    la += [1] * len(bridges)
    lb += [2] * len(bridges)
    sa += [on_ring(1, deg) for deg in bridges]
    sb += [on_ring(2, deg) for deg in bridges]
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
    options = options or TRACE_OPTIONS
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
