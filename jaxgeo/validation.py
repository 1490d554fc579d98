"""Analytic geodesic lengths for validation (numpy/scipy, float64).

* Sphere: great-circle arcs.
* Catenoid r(z) = c·cosh(z/c): geodesics by Clairaut's relation and quadrature,
  with an independent cross-check that shoots the geodesic ODE.

Catenoid geometry used below. With w = z/c the surface X(θ, z) = (r cos θ,
r sin θ, z), r = c·cosh w, has the conformal metric

    ds² = r² dθ² + (1 + r'²) dz² = c²·cosh²w·(dθ² + dw²).

Along a geodesic, Clairaut's relation r·sin ψ = h (ψ the angle with the meridian)
holds; with k = h/c,

    dθ/dw = k / sqrt(cosh²w − k²),      ds/dw = c·cosh²w / sqrt(cosh²w − k²).

k < 1: the geodesic crosses every parallel once (it may cross the neck w = 0).
k > 1: it stays on one side and turns back on the parallel cosh w₀ = k.
k = 1: the neck circle w = 0 itself, or curves spiralling onto it.
The substitutions sinh w = ε·sinh t (k < 1, ε² = 1 − k²), sinh w = δ·cosh t
(k > 1, δ² = k² − 1; t = 0 is the turning point) and sinh w = eᵗ (k = 1) turn both
integrands into smooth ones,

    dθ/dt = k / cosh w,      ds/dt = c·cosh w,      cosh w = sqrt(1 + sinh²w),

which `scipy.integrate.quad` integrates to near machine precision.
"""

from __future__ import annotations

import csv
import math
import os
import sys
import time
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import NamedTuple

import numpy as np
import scipy.integrate
import scipy.optimize
from jaxtyping import ArrayLike, Float

from ._errors import JaxgeoError

#: A point as these functions take it: an array, or a list or tuple of floats
#: (jaxtyping's `ArrayLike`, JAX's, has no lists or tuples).
_Point = ArrayLike | Sequence[float]

__all__ = [
    "CatenoidGeodesic",
    "catenoid_geodesic_length",
    "catenoid_geodesics",
    "catenoid_meridian_length",
    "catenoid_neck_arc_length",
    "great_circle_length",
]

# quad: relative tolerance of each integral; the integrands are smooth after the
# substitutions above, so quad reaches it and lengths are good to ~1e-13 relative.
_QUAD_RTOL = 1e-13
_QUAD_LIMIT = 200
# Smallest ε or δ tried when a geodesic winds close to the neck (Θ ~ log(1/ε)).
_E_MIN = 1e-200


# --------------------------------------------------------------------------- sphere


def great_circle_length(
    p: Float[ArrayLike, "*#batch 3"],
    q: Float[ArrayLike, "*#batch 3"],
    radius: float = 1.0,
) -> Float[np.ndarray, " *#batch"] | float:
    """Great-circle distance radius·∠(p, q) = radius·atan2(|p × q|, p·q).

    The atan2 form is accurate for nearly equal and nearly antipodal points (arccos
    of the dot product is not). p and q need not be normalised; only their
    directions are used. Broadcasts over leading axes.
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    cross = np.linalg.norm(np.cross(p, q), axis=-1)
    dot = np.sum(p * q, axis=-1)
    return radius * np.arctan2(cross, dot)


# --------------------------------------------------------------------------- catenoid


@cache
def _default_c() -> float:
    from .surfaces import catenoid_parameter

    return catenoid_parameter(1.0, 1.0)


def _theta_z(p: _Point) -> tuple[float, float]:
    """A point given as 3-D (x, y, z) or as surface coordinates (θ, z)."""
    p = np.asarray(p, dtype=np.float64).ravel()
    if p.shape == (3,):
        return math.atan2(p[1], p[0]), float(p[2])
    if p.shape == (2,):
        return float(p[0]), float(p[1])
    raise JaxgeoError(f"a catenoid point is (x, y, z) or (θ, z), got shape {p.shape}")


def catenoid_neck_arc_length(delta_theta: float, c: float | None = None) -> float:
    """Arc of the neck circle (z = 0, a geodesic): c·|Δθ|."""
    c = _default_c() if c is None else c
    return c * abs(delta_theta)


def catenoid_meridian_length(z1: float, z2: float, c: float | None = None) -> float:
    """Meridian arc (θ fixed, a geodesic): c·|sinh(z₂/c) − sinh(z₁/c)|."""
    c = _default_c() if c is None else c
    return c * abs(math.sinh(z2 / c) - math.sinh(z1 / c))


class CatenoidGeodesic(NamedTuple):
    """One geodesic between two catenoid points.

    **Fields:** `length`; `clairaut` h = r·sin ψ ≥ 0 (c·k); `travel`, the signed
    angle θ(end) − θ(start) it sweeps; `kind`: "meridian", "monotone" (z monotone,
    possibly across the neck), "turning" (turns back at r = h) or "neck".
    """

    length: float
    clairaut: float
    travel: float
    kind: str


class _Branch(NamedTuple):
    """Clairaut constant k = h/c, stored with e = sqrt|1 − k²| to keep precision
    near k = 1: sign −1 (k < 1, e = ε), +1 (k > 1, e = δ), 0 (k = 1)."""

    sign: int
    e: float

    @property
    def k(self) -> float:
        if self.sign < 0:
            return math.sqrt(max(0.0, 1.0 - self.e * self.e))
        return math.sqrt(1.0 + self.e * self.e)

    @staticmethod
    def from_k(k: float) -> _Branch:
        if k < 1.0:
            return _Branch(-1, math.sqrt((1.0 - k) * (1.0 + k)))
        if k > 1.0:
            return _Branch(1, math.sqrt((k - 1.0) * (k + 1.0)))
        return _Branch(0, 0.0)

    def sinh_w(self, t: float) -> float:
        if self.sign < 0:
            return self.e * math.sinh(t)
        if self.sign > 0:
            return self.e * math.cosh(t)
        return math.exp(t)

    def t_of(self, w: float) -> float:
        """Inverse of the substitution; for k > 1 needs sinh w ≥ δ (w ≥ w₀ ≥ 0)."""
        s = math.sinh(w)
        if self.sign < 0:
            return math.asinh(s / self.e)
        if self.sign > 0:
            return math.acosh(max(1.0, s / self.e))
        return math.log(s)


def _theta_length(branch: _Branch, t_pieces: list[tuple[float, float]], c: float):
    """(Θ, L): swept angle ∫k/cosh w dt and length c∫cosh w dt over t-intervals."""
    k = branch.k
    theta = length = 0.0
    for ta, tb in t_pieces:
        if ta == tb:
            continue
        th, _ = scipy.integrate.quad(
            lambda t: k / math.hypot(1.0, branch.sinh_w(t)),
            ta,
            tb,
            epsabs=0.0,
            epsrel=_QUAD_RTOL,
            limit=_QUAD_LIMIT,
        )
        ln, _ = scipy.integrate.quad(
            lambda t: math.hypot(1.0, branch.sinh_w(t)),
            ta,
            tb,
            epsabs=0.0,
            epsrel=_QUAD_RTOL,
            limit=_QUAD_LIMIT,
        )
        theta += th
        length += c * ln
    return theta, length


def _monotone(branch: _Branch, wa: float, wb: float, c: float):
    """Θ, L of the piece with w monotone from wa to wb (wa < wb)."""
    return _theta_length(branch, [(branch.t_of(wa), branch.t_of(wb))], c)


def _turning(delta: float, wa: float, wb: float, c: float):
    """Θ, L of the piece from wa down to the turning parallel (t = 0) and up to wb
    (0 < wa ≤ wb, δ ≤ sinh wa)."""
    br = _Branch(1, delta)
    return _theta_length(br, [(0.0, br.t_of(wa)), (0.0, br.t_of(wb))], c)


def _solve_log_e(theta_of_log_e, alpha: float, log_e_max: float) -> list[float]:
    """Roots in log e ∈ [log E_MIN, log_e_max] of Θ(log e) = α, where Θ grows without
    bound as e → 0. Scans a grid (Θ is monotone in practice; the scan guards against
    several roots) from log_e_max downwards until Θ exceeds α."""
    f = lambda x: theta_of_log_e(x) - alpha  # noqa: E731
    roots = []
    x_prev, f_prev = log_e_max, f(log_e_max)
    if f_prev == 0.0:
        roots.append(x_prev)
    step = 0.5
    x_lo = math.log(_E_MIN)
    while x_prev > x_lo:
        x = max(x_lo, x_prev - step)
        fx = f(x)
        if fx == 0.0:
            roots.append(x)
        elif f_prev * fx < 0.0:
            roots.append(
                scipy.optimize.brentq(f, x, x_prev, xtol=1e-15, rtol=1e-15, maxiter=200)
            )
        if fx > 0.0 and fx > 10.0:  # Θ grows like log(1/e): no more roots below
            break
        x_prev, f_prev = x, fx
        step = min(step * 1.5, 20.0)
    return roots


def _geodesics_with_travel(alpha: float, w1: float, w2: float, c: float):
    """All geodesics (length, k, kind) from w1 to w2 sweeping the angle α ≥ 0."""
    if w1 == 0.0 and w2 == 0.0:
        return [(c * alpha, 1.0, "neck")]
    if alpha == 0.0:
        return [(c * abs(math.sinh(w2) - math.sinh(w1)), 0.0, "meridian")]
    out = []
    if w1 * w2 <= 0.0:
        # opposite sides of the neck (or one point on it): k < 1 only, z monotone;
        # Θ(ε) runs from 0 (ε = 1, meridian) to ∞ (ε → 0, spiralling on the neck).
        wa, wb = min(w1, w2), max(w1, w2)

        def theta(log_e: float) -> float:
            return _monotone(_Branch(-1, math.exp(log_e)), wa, wb, c)[0]

        for x in _solve_log_e(theta, alpha, 0.0):
            br = _Branch(-1, math.exp(x))
            out.append((_monotone(br, wa, wb, c)[1], br.k, "monotone"))
        return out
    # same side: reflect to w > 0
    wa, wb = sorted((abs(w1), abs(w2)))
    # monotone branch, k ∈ [0, cosh wa]: Θ increases with k (dθ/dw does)
    theta_max = _monotone(_Branch(1, math.sinh(wa)), wa, wb, c)[0]
    if alpha <= theta_max:

        def f(k: float) -> float:
            return _monotone(_Branch.from_k(k), wa, wb, c)[0] - alpha

        k = scipy.optimize.brentq(f, 0.0, math.cosh(wa), xtol=1e-15, rtol=1e-15)
        br = _Branch.from_k(k)
        out.append((_monotone(br, wa, wb, c)[1], k, "monotone"))
    # turning branch, δ ∈ (0, sinh wa]: Θ(δ = sinh wa) = theta_max, Θ → ∞ as δ → 0

    def theta_turn(log_e: float) -> float:
        return _turning(math.exp(log_e), wa, wb, c)[0]

    for x in _solve_log_e(theta_turn, alpha, math.log(math.sinh(wa))):
        delta = math.exp(x)
        if abs(delta - math.sinh(wa)) <= 1e-12 * delta and out:
            continue  # turning exactly at the start point: the monotone solution
        out.append((_turning(delta, wa, wb, c)[1], _Branch(1, delta).k, "turning"))
    return out


def catenoid_geodesics(
    p: _Point, q: _Point, c: float | None = None
) -> list[CatenoidGeodesic]:
    """All geodesics from p to q on the catenoid r(z) = c·cosh(z/c) that sweep at
    most one turn in θ, in both directions, sorted by length (shortest first).

    **Arguments:** `p`, `q`: points as (x, y, z) on the surface or as (θ, z); `c`:
    the waist radius (default: rings of radius 1 at distance 1, c ≈ 0.848338).

    **Returns:** a list of `CatenoidGeodesic`. Each one is found by solving
    Θ(h) = Δθ for the Clairaut constant h (brentq) with Θ and the length from the
    quadratures in the module docstring. The geodesics stay between the parallels
    of p and q, or between them and the neck, so inside the catenoid's strip.
    """
    c = _default_c() if c is None else float(c)
    th1, z1 = _theta_z(p)
    th2, z2 = _theta_z(q)
    w1, w2 = z1 / c, z2 / c
    d = (th2 - th1) % (2.0 * math.pi)
    travels = [d] if d == 0.0 else [d, d - 2.0 * math.pi]
    result = []
    for travel in travels:
        for length, k, kind in _geodesics_with_travel(abs(travel), w1, w2, c):
            result.append(CatenoidGeodesic(length, c * k, travel, kind))
    return sorted(result, key=lambda g: g.length)


def catenoid_geodesic_length(p: _Point, q: _Point, c: float | None = None) -> float:
    """Length of the shortest geodesic from p to q on the catenoid r(z) = c·cosh(z/c).

    p, q as (x, y, z) or (θ, z); c defaults to the catenoid spanning rings of radius 1
    at distance 1 (c ≈ 0.848338). Handles meridians, the neck circle, paths across
    the neck and paths with a turning point; of all geodesics sweeping less than one
    turn either way round it returns the shortest (see `catenoid_geodesics`).
    Closed forms: meridian c·|sinh(z₂/c) − sinh(z₁/c)|, neck arc c·|Δθ|.
    """
    return catenoid_geodesics(p, q, c)[0].length


def _catenoid_geodesic_length_shooting(
    p: _Point,
    q: _Point,
    c: float | None = None,
    travel: float | None = None,
    guess: tuple[float, float] | None = None,
) -> tuple[float, float]:
    """Independent cross-check of `catenoid_geodesics`: shoot the geodesic ODE.

    Integrates, in arc length s, the geodesic equations of X(θ, z) = (r cos θ,
    r sin θ, z), r = c·cosh(z/c), whose metric is E = r², G = 1 + r'² = cosh²(z/c):

        θ'' = −2 (tanh(z/c)/c) θ' z',      z'' = c·tanh(z/c) θ'² − (tanh(z/c)/c) z'²,

    from p with unit speed θ' = sin β / r, z' = cos β / cosh(z/c) (β the angle with
    the meridian), using solve_ivp (DOP853, rtol = atol = 1e-12), and solves for
    (β, L) with `scipy.optimize.root` so that (θ, z)(L) = (θ_p + travel, z_q).
    No Clairaut relation is used.

    **Arguments:** `travel`: the signed angle to sweep (default: Δθ wrapped to
    (−π, π]); `guess`: initial (β, L) (default: the straight line in the conformal
    chart (θ, z/c), whose angles are the surface's).

    **Returns:** (L, β).
    """
    c = _default_c() if c is None else float(c)
    th1, z1 = _theta_z(p)
    th2, z2 = _theta_z(q)
    if travel is None:
        travel = (th2 - th1 + math.pi) % (2.0 * math.pi) - math.pi
    if guess is None:
        dw = (z2 - z1) / c
        beta0 = math.atan2(travel, dw)
        wm = 0.5 * (z1 + z2) / c
        guess = (beta0, c * math.cosh(wm) * math.hypot(travel, dw))

    def rhs(s, y):
        _, z, dth, dz = y
        tz = math.tanh(z / c)
        return [
            dth,
            dz,
            -2.0 * tz / c * dth * dz,
            c * tz * dth * dth - tz / c * dz * dz,
        ]

    def endpoint(beta: float, length: float) -> np.ndarray:
        ch = math.cosh(z1 / c)
        y0 = [th1, z1, math.sin(beta) / (c * ch), math.cos(beta) / ch]
        sol = scipy.integrate.solve_ivp(
            rhs, (0.0, length), y0, method="DOP853", rtol=1e-12, atol=1e-12
        )
        return sol.y[:2, -1]

    r2 = c * math.cosh(z2 / c)

    def residual(x: np.ndarray) -> np.ndarray:
        th, z = endpoint(x[0], x[1])
        return np.array([r2 * (th - (th1 + travel)), z - z2])

    sol = scipy.optimize.root(
        residual, np.asarray(guess, float), method="hybr", tol=1e-14
    )
    # hybr may stop with "no further improvement" once the ODE's own error (~1e-12)
    # dominates; accept on the residual, not on `success`
    if sol.x[1] <= 0.0 or np.max(np.abs(residual(sol.x))) > 1e-10:
        raise JaxgeoError(f"shooting did not converge: {sol.message}")
    return float(sol.x[1]), float(sol.x[0])


# --------------------------------------------------------------------------- curves


def great_circle_points(
    p: Float[ArrayLike, "3"], q: Float[ArrayLike, "3"], n: int = 100
) -> Float[np.ndarray, "n 3"]:
    """`n` points of the shorter great-circle arc from p to q (on the sphere through
    p, centred at the origin; slerp of the directions)."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    radius = float(np.linalg.norm(p))
    angle = float(great_circle_length(p, q))
    t = np.linspace(0.0, 1.0, n)[:, None]
    if angle == 0.0:
        return np.repeat(p[None], n, axis=0)
    u, v = p / radius, q / np.linalg.norm(q)
    return (
        radius
        * (np.sin((1.0 - t) * angle) * u + np.sin(t * angle) * v)
        / math.sin(angle)
    )


def catenoid_geodesic_points(
    p: _Point, q: _Point, n: int = 100, c: float | None = None
) -> Float[np.ndarray, "n 3"]:
    """`n` points, equally spaced in arc length, of the shortest catenoid geodesic
    from p to q (given as (x, y, z) or (θ, z)).

    The travel is taken from `catenoid_geodesics`; the initial direction comes from
    shooting the geodesic ODE onto q, and the curve is the ODE's solution sampled at
    `n` arc lengths.
    """
    c = _default_c() if c is None else float(c)
    best = catenoid_geodesics(p, q, c)[0]
    th1, z1 = _theta_z(p)
    if best.kind == "meridian" or best.length == 0.0:
        z = np.linspace(z1, _theta_z(q)[1], n)
        th = np.full(n, th1)
    elif best.kind == "neck":
        th = th1 + np.linspace(0.0, best.travel, n)
        z = np.zeros(n)
    else:
        length, beta = _catenoid_geodesic_length_shooting(p, q, c, travel=best.travel)
        ch = math.cosh(z1 / c)
        y0 = [th1, z1, math.sin(beta) / (c * ch), math.cos(beta) / ch]

        def rhs(s, y):
            _, zz, dth, dz = y
            tz = math.tanh(zz / c)
            return [dth, dz, -2.0 * tz / c * dth * dz, c * tz * dth**2 - tz / c * dz**2]

        sol = scipy.integrate.solve_ivp(
            rhs,
            (0.0, length),
            y0,
            method="DOP853",
            rtol=1e-12,
            atol=1e-12,
            t_eval=np.linspace(0.0, length, n),
        )
        th, z = sol.y[0], sol.y[1]
    r = c * np.cosh(z / c)
    return np.stack([r * np.cos(th), r * np.sin(th), z], axis=-1)


def catenoid_descent_curve(
    p: _Point, q: _Point, n: int = 100, c: float | None = None
) -> tuple[float, Float[np.ndarray, "n 3"]]:
    """The continuous limit of the sliding laser ray on the catenoid: the curve of
    steepest descent of the Euclidean distance to q, from p.

    At a point x of the surface, the laser ray's chord from x to q projects onto
    the surface with initial direction P_T(q − x), the tangential part of q − x,
    which is −∇_S ½|x − q|²: as the mesh is refined, the traced path tends to the
    integral curve of that field, not to the geodesic. On a sphere the two
    coincide (|x − q| is a function of the great-circle distance); on the catenoid
    they do not, and the difference in length is the method's intrinsic error.

    Integrated in arc length in (θ, z) (solve_ivp, DOP853, rtol 1e-11) until
    |x − q| < 1e-7. **Returns:** (length, `n` points equally spaced in arc length).
    """
    c = _default_c() if c is None else float(c)
    th1, z1 = _theta_z(p)
    th2, z2 = _theta_z(q)

    def xyz(th: float, z: float) -> np.ndarray:
        r = c * math.cosh(z / c)
        return np.array([r * math.cos(th), r * math.sin(th), z])

    target = xyz(th2, z2)

    def rhs(s, y):
        th, z = y
        r, rp = c * math.cosh(z / c), math.sinh(z / c)
        d = target - xyz(th, z)
        # components of P_T(d) in the coordinate basis: (d·X_θ)/E, (d·X_z)/G
        a = (d[1] * math.cos(th) - d[0] * math.sin(th)) / r
        b = (rp * (d[0] * math.cos(th) + d[1] * math.sin(th)) + d[2]) / (1 + rp * rp)
        speed = math.sqrt(r * r * a * a + (1 + rp * rp) * b * b)
        return [a / speed, b / speed]

    def arrived(s, y):
        return np.linalg.norm(xyz(*y) - target) - 1e-7

    arrived.terminal = True
    bound = 10.0 * (np.linalg.norm(xyz(th1, z1) - target) + 1.0)
    sol = scipy.integrate.solve_ivp(
        rhs,
        (0.0, bound),
        [th1, z1],
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
        events=arrived,
        dense_output=True,
    )
    if sol.status != 1:
        raise JaxgeoError("the steepest-descent curve did not reach q")
    length = float(sol.t[-1])
    th, z = sol.sol(np.linspace(0.0, length, n))
    r = c * np.cosh(z / c)
    return length, np.stack([r * np.cos(th), r * np.sin(th), z], axis=-1)


# --------------------------------------------------------------------------- suites


class Pair(NamedTuple):
    """An endpoint pair of a validation suite: two mesh vertices on the analytic
    surface, so `analytic` is the exact length between them."""

    pair: str
    kind: str
    v1: int
    v2: int
    analytic: float


@dataclass(frozen=True)
class Suite:
    """A mesh of an analytic surface and its endpoint pairs.

    `resolution` is the refinement level (see `sphere_suite`, `catenoid_suite`);
    `mesh_size` the mean edge length.
    """

    name: str
    resolution: int
    vertices: np.ndarray
    faces: np.ndarray
    pairs: tuple[Pair, ...]

    @property
    def mesh_size(self) -> float:
        e = self.vertices[self.faces] - self.vertices[np.roll(self.faces, 1, axis=1)]
        return float(np.linalg.norm(e, axis=-1).mean())


#: Target arc angles (degrees) of the sphere pairs; 90° is the paper's Fig. 8 arc
#: (a quarter of a great circle on the hemisphere).
SPHERE_ANGLES = (10.0, 20.0, 30.0, 45.0, 60.0, 90.0, 120.0, 160.0)
#: Subdivision level whose vertices are the sphere pairs' endpoints (every finer
#: icosphere contains them), so the pairs are identical at every resolution ≥ 3.
_SPHERE_BASE_LEVEL = 3

#: Catenoid pairs: (id, kind, (θ₁°, z₁), (θ₂°, z₂)). Rings of radius 1 at z = ±0.5.
#: C3 is the paper's arc ABC (1.0876: ring to ring, Δθ ≈ 15.8°), C7 its arc BE
#: (1.332569 = a quarter of the neck circle, c·π/2).
CATENOID_PAIRS = (
    ("C1", "meridian, ring to ring", (0.0, -0.5), (0.0, 0.5)),
    ("C2", "meridian", (30.0, -0.25), (30.0, 0.5)),
    ("C3", "across neck 15° (paper's ABC)", (0.0, -0.5), (15.0, 0.5)),
    ("C4", "across neck 60°", (0.0, -0.5), (60.0, 0.5)),
    ("C5", "across neck 120°", (0.0, -0.5), (120.0, 0.5)),
    ("C6", "across neck 90°", (0.0, -0.25), (90.0, 0.25)),
    ("C7", "neck circle 90° (paper's BE)", (0.0, 0.0), (90.0, 0.0)),
    ("C8", "neck to ring 60°", (0.0, 0.0), (60.0, 0.5)),
    ("C9", "turning point 90°", (0.0, 0.5), (90.0, 0.5)),
    ("C10", "turning point 150°", (0.0, 0.5), (150.0, 0.5)),
    ("C11", "turning point 60°", (0.0, 0.25), (60.0, 0.25)),
    ("C12", "turning point 120°, below", (0.0, -0.5), (120.0, -0.25)),
    ("C13", "across neck 165°", (0.0, -0.5), (165.0, 0.5)),
)


def _check_resolution(resolution: int, minimum: int) -> int:
    if int(resolution) != resolution or resolution < minimum:
        raise JaxgeoError(
            f"resolution must be an integer >= {minimum}, got {resolution}"
        )
    return int(resolution)


def _nearest_vertex(vertices: np.ndarray, x: np.ndarray) -> int:
    d = np.linalg.norm(vertices - x, axis=1)
    i = int(np.argmin(d))
    if d[i] > 1e-9:
        raise JaxgeoError(f"no mesh vertex at {x} (nearest {d[i]:.3g} away)")
    return i


@cache
def _sphere_pair_points() -> tuple[tuple[float, np.ndarray, np.ndarray], ...]:
    """(target angle, p, q) for `SPHERE_ANGLES`, p and q vertices of the level-3
    icosphere. Start vertices are spread over the sphere (the vertices nearest to a
    Fibonacci lattice of directions); each end vertex is the one whose arc angle from
    its start is nearest to the target (ties to the lower index)."""
    from .surfaces import icosphere

    v, _ = icosphere(_SPHERE_BASE_LEVEL)
    n = len(SPHERE_ANGLES)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for k, target in enumerate(SPHERE_ANGLES):
        zk = 1.0 - 2.0 * (k + 0.5) / n
        rk = math.sqrt(1.0 - zk * zk)
        d = np.array([rk * math.cos(golden * k), rk * math.sin(golden * k), zk])
        i = int(np.argmax(v @ d))
        ang = np.degrees(great_circle_length(v[i], v))
        j = int(np.argmin(np.abs(ang - target)))
        out.append((target, v[i], v[j]))
    return tuple(out)


def sphere_suite(resolution: int = 4) -> Suite:
    """Unit icosphere with `resolution` subdivisions (20·4**resolution faces; at
    least 3) and 8 vertex pairs at about 10°–160° of arc (`SPHERE_ANGLES`), the same
    points at every resolution. Analytic length: the great circle."""
    from .surfaces import icosphere

    resolution = _check_resolution(resolution, _SPHERE_BASE_LEVEL)
    v, f = icosphere(resolution)
    pairs = []
    for k, (_, p, q) in enumerate(_sphere_pair_points()):
        i, j = _nearest_vertex(v, p), _nearest_vertex(v, q)
        length = float(great_circle_length(v[i], v[j]))
        kind = f"great circle {math.degrees(length):.0f}°"
        if k == SPHERE_ANGLES.index(90.0):
            kind += " (Fig. 8)"
        pairs.append(Pair(f"S{k + 1}", kind, i, j, length))
    return Suite("sphere", resolution, v, f, tuple(pairs))


def catenoid_mesh(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """The catenoid (rings of radius 1 at distance 1) at a refinement level:
    `6·2**resolution` vertices around, `2**(resolution + 1)` bands in height
    (3 → 48 × 16, 1536 faces; 4 → 96 × 32, 6144 faces), mean edge length close
    to that of the icosphere of the same level."""
    from .surfaces import catenoid

    return catenoid(n_around=6 * 2**resolution, n_height=2 ** (resolution + 1))


def catenoid_suite(resolution: int = 4) -> Suite:
    """The catenoid of `catenoid_mesh(resolution)` (at least 2) and the 13 vertex
    pairs of `CATENOID_PAIRS` (θ multiples of 15°, z ∈ {0, ±0.25, ±0.5}: mesh
    vertices at every level ≥ 2). Analytic length: `catenoid_geodesic_length`."""
    resolution = _check_resolution(resolution, 2)
    v, f = catenoid_mesh(resolution)
    c = _default_c()
    pairs = []
    for pid, kind, a, b in CATENOID_PAIRS:
        idx = []
        for deg, z in (a, b):
            th = math.radians(deg)
            r = c * math.cosh(z / c)
            idx.append(
                _nearest_vertex(v, np.array([r * math.cos(th), r * math.sin(th), z]))
            )
        length = catenoid_geodesic_length(v[idx[0]], v[idx[1]], c)
        pairs.append(Pair(pid, kind, idx[0], idx[1], length))
    return Suite("catenoid", resolution, v, f, tuple(pairs))


SUITES = {"sphere": sphere_suite, "catenoid": catenoid_suite}


# --------------------------------------------------------------------------- comparison


def available_methods() -> tuple[str, ...]:
    """The methods `jaxgeo.shortest_path` accepts: `jaxgeo.geodesic.METHODS` if it
    exists, else the arguments of its `Method` literal type, else ("laser",)."""
    from . import geodesic

    methods = getattr(geodesic, "METHODS", None)
    if methods is None:
        methods = typing.get_args(getattr(geodesic, "Method", None)) or ("laser",)
    return tuple(str(m) for m in methods)


def _pygeodesic(vertices: np.ndarray, faces: np.ndarray):
    import pygeodesic.geodesic as pyg

    alg = pyg.PyGeodesicAlgorithmExact(
        np.ascontiguousarray(vertices, np.float64),
        np.ascontiguousarray(faces, np.int32),
    )
    return lambda i, j: float(alg.geodesicDistance(i, j)[0])


def _potpourri3d(vertices: np.ndarray, faces: np.ndarray):
    import potpourri3d as pp3d

    flip = pp3d.EdgeFlipGeodesicSolver(vertices, faces)

    def dist(i: int, j: int) -> float:
        pts = flip.find_geodesic_path(i, j)
        return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())

    return dist


#: Exact polyhedral solvers, in order of preference: pygeodesic's exact MMP
#: algorithm, then potpourri3d's edge-flip geodesics (started from a Dijkstra path:
#: locally shortest, in practice the shortest on these surfaces).
EXACT_SOLVERS = {"pygeodesic": _pygeodesic, "potpourri3d": _potpourri3d}


def _exact_solver(name: str, vertices: np.ndarray, faces: np.ndarray):
    """(solver name, function (i, j) → exact polyhedral distance between vertices),
    or (None, None). `name`: a key of `EXACT_SOLVERS`, "auto" (the first one
    installed) or "none"."""
    if name == "none":
        return None, None
    if name != "auto" and name not in EXACT_SOLVERS:
        raise JaxgeoError(
            f"unknown exact solver {name!r}; expected auto, none or one of "
            f"{list(EXACT_SOLVERS)}"
        )
    for solver in EXACT_SOLVERS if name == "auto" else [name]:
        try:
            return solver, EXACT_SOLVERS[solver](vertices, faces)
        except ImportError:
            continue
    if name != "auto":
        raise JaxgeoError(f"exact solver {name!r} is not installed")
    return None, None


@dataclass(frozen=True)
class MethodResult:
    """One solver run: `length`, `status` (a `jaxgeo.Status` name) and wall time in
    seconds (after compilation)."""

    length: float
    status: str
    time: float


@dataclass(frozen=True)
class Row:
    """One endpoint pair of a suite, solved by every method.

    Errors are relative to the analytic length L, and signed:
    `error(m)` = (L_m − L)/L (total), `discretisation_error` = (L_exact − L)/L (the
    mesh's own error: the shortest path ON the mesh vs the smooth surface),
    `method_error(m)` = (L_m − L_exact)/L (the solver's error on that mesh). With the
    common denominator L, total = method + discretisation exactly (to rounding).
    """

    suite: str
    resolution: int
    n_faces: int
    mesh_size: float
    pair: str
    kind: str
    v1: int
    v2: int
    analytic: float
    exact: float | None
    results: dict[str, MethodResult] = field(default_factory=dict)

    def error(self, method: str) -> float:
        r = self.results[method]
        return (
            (r.length - self.analytic) / self.analytic
            if r.status == "SUCCESS"
            else math.nan
        )

    def method_error(self, method: str) -> float:
        r = self.results[method]
        if self.exact is None or r.status != "SUCCESS":
            return math.nan
        return (r.length - self.exact) / self.analytic

    @property
    def discretisation_error(self) -> float:
        return (
            math.nan
            if self.exact is None
            else (self.exact - self.analytic) / self.analytic
        )


def _pct(x: float, digits: int = 3) -> str:
    return "—" if x is None or math.isnan(x) else f"{100.0 * x:+.{digits}f} %"


def _num(x: float | None, digits: int = 6) -> str:
    return "—" if x is None or math.isnan(x) else f"{x:.{digits}f}"


@dataclass
class Table:
    """Validation results: one `Row` per (suite, resolution, pair).

    `methods`: the solver methods run; `exact_solver`: the name of the exact
    polyhedral reference (None if none was installed); `compile_time[(suite,
    resolution, method)]`: seconds of the first call (JIT compilation included).
    """

    rows: list[Row]
    methods: tuple[str, ...]
    exact_solver: str | None
    compile_time: dict[tuple[str, int, str], float] = field(default_factory=dict)

    def columns(self) -> dict[str, list]:
        """The table as a dict of equal-length columns (raw numbers, errors as
        relative fractions, NaN where not available)."""
        cols: dict[str, list] = {
            k: []
            for k in (
                "suite",
                "resolution",
                "n_faces",
                "mesh_size",
                "pair",
                "kind",
                "v1",
                "v2",
                "analytic",
                "exact",
                "exact_solver",
                "discretisation_error",
            )
        }
        for m in self.methods:
            for k in ("length", "status", "error", "method_error", "time"):
                cols[f"{m}_{k}"] = []
        for r in self.rows:
            for k in ("suite", "resolution", "n_faces", "mesh_size", "pair", "kind"):
                cols[k].append(getattr(r, k))
            cols["v1"].append(r.v1)
            cols["v2"].append(r.v2)
            cols["analytic"].append(r.analytic)
            cols["exact"].append(math.nan if r.exact is None else r.exact)
            cols["exact_solver"].append(
                self.exact_solver if r.exact is not None else ""
            )
            cols["discretisation_error"].append(r.discretisation_error)
            for m in self.methods:
                res = r.results[m]
                cols[f"{m}_length"].append(res.length)
                cols[f"{m}_status"].append(res.status)
                cols[f"{m}_error"].append(r.error(m))
                cols[f"{m}_method_error"].append(r.method_error(m))
                cols[f"{m}_time"].append(res.time)
        return cols

    def to_csv(self, file: str | os.PathLike | typing.TextIO) -> None:
        """Write `columns()` as CSV (full precision)."""
        cols = self.columns()
        if not hasattr(file, "write"):
            # (hasattr(file, 'write') told a path from a text file)
            with open(file, "w", newline="") as f:  # pyright: ignore[reportCallIssue, reportArgumentType]
                return self.to_csv(f)
        w = csv.writer(file)  # pyright: ignore[reportArgumentType]
        w.writerow(cols)
        for row in zip(*cols.values()):
            w.writerow([repr(x) if isinstance(x, float) else x for x in row])
        return None

    def to_markdown(self) -> str:
        """The table in Markdown, errors in per cent, one section per suite and
        resolution."""
        exact_name = self.exact_solver or "not installed"
        head = [
            "pair",
            "kind",
            "analytic",
            f"exact polyhedral ({exact_name})",
            "discr. err",
        ]
        for m in self.methods:
            head += [m, f"{m} err", f"{m} method err", f"{m} ms"]
        out = []
        for (suite, res), rows in _groups(self.rows).items():
            r0 = rows[0]
            out.append(
                f"**{suite}**, resolution {res}: {r0.n_faces} faces, mean edge "
                f"length {r0.mesh_size:.4f}\n"
            )
            out.append("| " + " | ".join(head) + " |")
            out.append("|" + "|".join(["---"] * 2 + ["---:"] * (len(head) - 2)) + "|")
            for r in rows:
                cells = [r.pair, r.kind, _num(r.analytic), _num(r.exact)]
                cells.append(_pct(r.discretisation_error))
                for m in self.methods:
                    res = r.results[m]
                    length = _num(res.length)
                    if res.status != "SUCCESS":
                        length += f" ({res.status})"
                    cells += [
                        length,
                        _pct(r.error(m)),
                        _pct(r.method_error(m)),
                        f"{1e3 * res.time:.0f}",
                    ]
                out.append("| " + " | ".join(cells) + " |")
            out.append("")
        return "\n".join(out)


def read_csv(file: str | os.PathLike) -> Table:
    """A `Table` from a file written by `Table.to_csv` (`compile_time` is not
    stored, so it comes back empty)."""
    with open(file, newline="") as f:
        records = list(csv.DictReader(f))
    if not records:
        raise JaxgeoError(f"{file}: no rows")
    methods = tuple(k[: -len("_status")] for k in records[0] if k.endswith("_status"))

    def num(x: str) -> float:
        return float(x) if x else math.nan

    rows = []
    for rec in records:
        exact = num(rec["exact"])
        rows.append(
            Row(
                rec["suite"],
                int(rec["resolution"]),
                int(rec["n_faces"]),
                num(rec["mesh_size"]),
                rec["pair"],
                rec["kind"],
                int(rec["v1"]),
                int(rec["v2"]),
                num(rec["analytic"]),
                None if math.isnan(exact) else exact,
                {
                    m: MethodResult(
                        num(rec[f"{m}_length"]),
                        rec[f"{m}_status"],
                        num(rec[f"{m}_time"]),
                    )
                    for m in methods
                },
            )
        )
    names = {rec.get("exact_solver") or "" for rec in records} - {""}
    if not any(r.exact is not None for r in rows):
        return Table(rows, methods, None)
    return Table(rows, methods, names.pop() if len(names) == 1 else "from file")


def _groups(rows: list[Row]) -> dict[tuple[str, int], list[Row]]:
    groups: dict[tuple[str, int], list[Row]] = {}
    for r in rows:
        groups.setdefault((r.suite, r.resolution), []).append(r)
    return groups


def run_suite(
    suite: Suite,
    methods: Sequence[str] | None = None,
    exact_solver: str = "auto",
    progress: Callable[[str], None] | None = None,
    **solver_options: typing.Any,
) -> Table:
    """Solve every pair of `suite` with every method and the exact polyhedral solver.

    **Arguments:** `methods`: `jaxgeo.shortest_path` methods (default
    `available_methods()`); `exact_solver`: see `_exact_solver`; `progress`: called
    with one line of text per step; `solver_options`: passed to `shortest_path`.

    **Returns:** a `Table`. Endpoints are mesh vertices (passed as 3-D points), so
    the analytic length is exact for them. Each method is called once on the first
    pair before timing, so `MethodResult.time` excludes JIT compilation (reported
    in `Table.compile_time`). Failed traces are recorded with their status, not
    raised.
    """
    from .geodesic import shortest_path
    from .mesh import Mesh
    from .path import Status

    methods = tuple(available_methods() if methods is None else methods)
    say = progress or (lambda _: None)
    tag = f"[{suite.name} r{suite.resolution}]"
    mesh = Mesh(suite.vertices, suite.faces)
    mesh_size = float(mesh.mean_edge_length)
    name, exact = _exact_solver(exact_solver, suite.vertices, suite.faces)
    rows = []
    t0 = time.perf_counter()
    for p in suite.pairs:
        d = exact(p.v1, p.v2) if exact else None
        rows.append(
            Row(
                suite.name,
                suite.resolution,
                mesh.n_faces,
                mesh_size,
                p.pair,
                p.kind,
                p.v1,
                p.v2,
                p.analytic,
                d,
            )
        )
    if exact:
        say(f"{tag} exact polyhedral ({name}): {time.perf_counter() - t0:.1f} s")
    table = Table(rows, methods, name)
    v = np.asarray(suite.vertices)
    for m in methods:
        say(f"{tag} {m}: compiling ({mesh.n_faces} faces)")
        t0 = time.perf_counter()
        first = suite.pairs[0]
        # (m: a method's name as given; shortest_path rejects an unknown one)
        path = shortest_path(
            mesh,
            v[first.v1],
            v[first.v2],
            method=m,  # pyright: ignore[reportArgumentType]
            throw=False,
            **solver_options,
        )
        float(path.length)
        table.compile_time[(suite.name, suite.resolution, m)] = time.perf_counter() - t0
        for k, (p, row) in enumerate(zip(suite.pairs, rows)):
            t0 = time.perf_counter()
            path = shortest_path(
                mesh,
                v[p.v1],
                v[p.v2],
                method=m,  # pyright: ignore[reportArgumentType]
                throw=False,
                **solver_options,
            )
            length = float(path.length)
            dt = time.perf_counter() - t0
            status = Status(int(path.status)).name
            row.results[m] = MethodResult(length, status, dt)
            say(
                f"{tag} {m} {k + 1}/{len(suite.pairs)} {p.pair}: {length:.6f} "
                f"({_pct(row.error(m))}, {status.lower()}, {dt:.2f} s)"
            )
    return table


def _merge(tables: list[Table]) -> Table:
    out = Table([], tables[0].methods, tables[0].exact_solver)
    for t in tables:
        out.rows += t.rows
        out.compile_time.update(t.compile_time)
    return out


def validate(
    resolutions: int | Sequence[int] = 4,
    suites: Sequence[str] = ("sphere", "catenoid"),
    methods: Sequence[str] | None = None,
    exact_solver: str = "auto",
    progress: Callable[[str], None] | None = None,
    **solver_options: typing.Any,
) -> Table:
    """Run the named suites (`SUITES`) at one or several resolutions; see
    `run_suite`. Several resolutions make a convergence study
    (`convergence_summary`, `plot_convergence`)."""
    if isinstance(resolutions, int):
        resolutions = [resolutions]
    tables = []
    for res in resolutions:
        for name in suites:
            if name not in SUITES:
                raise JaxgeoError(
                    f"unknown suite {name!r}; expected one of {list(SUITES)}"
                )
            tables.append(
                run_suite(
                    SUITES[name](res), methods, exact_solver, progress, **solver_options
                )
            )
    return _merge(tables)


def convergence_summary(table: Table) -> list[dict[str, typing.Any]]:
    """Per (suite, resolution): `n_faces`, `mesh_size` and the median absolute
    relative errors: `exact` (discretisation error of the exact polyhedral
    geodesic), and per method `m` (total error) and `m_method` (vs exact)."""
    out = []
    for (suite, res), rows in _groups(table.rows).items():
        entry: dict[str, typing.Any] = {
            "suite": suite,
            "resolution": res,
            "n_faces": rows[0].n_faces,
            "mesh_size": rows[0].mesh_size,
            "exact": _median_abs([r.discretisation_error for r in rows]),
        }
        for m in table.methods:
            entry[m] = _median_abs([r.error(m) for r in rows])
            entry[f"{m}_method"] = _median_abs([r.method_error(m) for r in rows])
        out.append(entry)
    return out


def _median_abs(xs: list[float]) -> float:
    a = np.abs(np.asarray(xs, dtype=np.float64))
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else math.nan


def summary_markdown(
    summary: list[dict[str, typing.Any]], methods: Sequence[str]
) -> str:
    """`convergence_summary` as a Markdown table (median |error| in per cent)."""
    head = ["suite", "resolution", "faces", "mean edge", "exact polyhedral"]
    head += [f"{m} {k}" for m in methods for k in ("total", "method")]
    lines = [
        "| " + " | ".join(head) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|",
    ]
    for e in summary:
        cells = [
            e["suite"],
            str(e["resolution"]),
            str(e["n_faces"]),
            f"{e['mesh_size']:.4f}",
        ]
        cells.append(_pct(e["exact"]).lstrip("+"))
        for m in methods:
            cells += [_pct(e[m]).lstrip("+"), _pct(e[f"{m}_method"]).lstrip("+")]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _loglog(ax, entries: list[dict[str, typing.Any]], key: str, **kw) -> None:
    h = np.array([e["mesh_size"] for e in entries])
    y = np.array([e[key] for e in entries], dtype=float)
    ok = np.isfinite(y) & (y > 0)
    if ok.any():
        ax.loglog(h[ok], y[ok], marker="o", **kw)


def plot_convergence(
    summary: list[dict[str, typing.Any]],
    methods: Sequence[str],
    file=None,
    axes=None,
):
    """Log–log plot of the median |relative error| against the mean edge length,
    one panel per suite: each method's total error (solid), its method error
    (dashed) and the exact polyhedral reference (black). With `file`, saves a PNG
    (Agg backend when pyplot is not yet in use). Returns the figure."""
    import matplotlib

    if axes is None and "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    suites = list(dict.fromkeys(e["suite"] for e in summary))
    if axes is None:
        fig, axes = plt.subplots(
            1, len(suites), figsize=(5.5 * len(suites), 4.2), squeeze=False
        )
        axes = axes[0]
    else:
        fig = axes[0].figure
    for ax, suite in zip(axes, suites):
        es = sorted(
            (e for e in summary if e["suite"] == suite), key=lambda e: e["mesh_size"]
        )
        h = np.array([e["mesh_size"] for e in es])

        _loglog(ax, es, "exact", color="k", label="exact polyhedral vs analytic")
        for k, m in enumerate(methods):
            color = f"C{k}"
            _loglog(ax, es, m, color=color, label=f"{m} vs analytic")
            _loglog(
                ax,
                es,
                f"{m}_method",
                color=color,
                ls="--",
                label=f"{m} vs exact polyhedral",
            )
        if len(h) > 1:
            ref = np.array([e["exact"] for e in es], dtype=float)
            if np.isfinite(ref[-1]) and ref[-1] > 0:
                ax.loglog(
                    h, ref[-1] * (h / h[-1]) ** 2, color="0.7", lw=0.8, label="O(h²)"
                )
        ax.set_title(suite)
        ax.set_xlabel("mean edge length h")
        ax.set_ylabel("median |relative length error|")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    if file is not None:
        fig.savefig(file, dpi=120)
    return fig
