"""Analytic geodesics for validation, lengths and curves (numpy/scipy, float64).

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

import math
from collections.abc import Sequence
from functools import cache
from typing import NamedTuple

import numpy as np
import scipy.integrate
import scipy.optimize
from jaxtyping import ArrayLike, Float

from .._errors import JaxgeoError

#: A point as these functions take it: an array, or a list or tuple of floats
#: (jaxtyping's `ArrayLike`, JAX's, has no lists or tuples).
_Point = ArrayLike | Sequence[float]

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
def default_c() -> float:
    """The waist radius c ≈ 0.848338 of the catenoid spanning rings of radius 1 at
    distance 1: the default `c` here and the catenoid of the suites."""
    from ..surfaces import catenoid_parameter

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
    c = default_c() if c is None else c
    return c * abs(delta_theta)


def catenoid_meridian_length(z1: float, z2: float, c: float | None = None) -> float:
    """Meridian arc (θ fixed, a geodesic): c·|sinh(z₂/c) − sinh(z₁/c)|."""
    c = default_c() if c is None else c
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
    c = default_c() if c is None else float(c)
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
    c = default_c() if c is None else float(c)
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
    c = default_c() if c is None else float(c)
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
    c = default_c() if c is None else float(c)
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
