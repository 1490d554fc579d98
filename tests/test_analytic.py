import math

import numpy as np
import pytest

from jaxgeo._errors import JaxgeoError
from jaxgeo.surfaces import catenoid_parameter
from jaxgeo.validation import (
    catenoid_geodesic_length,
    catenoid_geodesics,
    catenoid_meridian_length,
    catenoid_neck_arc_length,
    great_circle_length,
)
from jaxgeo.validation.analytic import _catenoid_geodesic_length_shooting

C = catenoid_parameter(1.0, 1.0)  # ≈ 0.848338, rings of radius 1 at z = ±0.5

# Clairaut lengths come from quad at epsrel 1e-13 (smooth integrands) and brentq on
# the Clairaut constant to ~1e-15; the shooting lengths from DOP853 at rtol = atol =
# 1e-12 over arcs of length O(1), whose endpoint error (~1e-12..1e-11) is what the
# root-finder then matches. 1e-9 relative leaves two orders of margin over both.
CROSS_CHECK_RTOL = 1e-9
# Closed forms vs quadrature: quad's epsrel 1e-13, plus rounding.
CLOSED_FORM_RTOL = 1e-12


# --------------------------------------------------------------------------- sphere


def test_great_circle_basic():
    x, y, z = np.eye(3)
    assert great_circle_length(x, y) == pytest.approx(math.pi / 2, rel=1e-15)
    assert great_circle_length(x, -x) == pytest.approx(math.pi, rel=1e-15)
    assert great_circle_length(x, x) == 0.0
    assert great_circle_length(2 * x, 3 * z, radius=2.0) == pytest.approx(math.pi)
    batch = great_circle_length(np.stack([x, y]), np.stack([y, z]))
    np.testing.assert_allclose(batch, [math.pi / 2] * 2, rtol=1e-15)


@pytest.mark.parametrize("eps", [1e-4, 1e-9, 1e-13])
def test_great_circle_near_equal_and_antipodal(eps):
    # arccos(p·q) would lose all digits here; atan2 keeps them (rel ~1e-15)
    p = np.array([1.0, 0.0, 0.0])
    q = np.array([math.cos(eps), math.sin(eps), 0.0])
    assert great_circle_length(p, q) == pytest.approx(eps, rel=1e-12)
    r = np.array([-math.cos(eps), math.sin(eps), 0.0])
    assert great_circle_length(p, r) == pytest.approx(math.pi - eps, rel=1e-15, abs=0)
    assert math.pi - great_circle_length(p, r) == pytest.approx(eps, rel=1e-3)


# --------------------------------------------------------------------------- catenoid


def test_closed_forms():
    for dth in (0.3, 1.0, math.pi):  # the neck circle is a geodesic
        got = catenoid_geodesic_length((0.2, 0.0), (0.2 + dth, 0.0))
        assert got == pytest.approx(C * dth, rel=CLOSED_FORM_RTOL)
        assert catenoid_neck_arc_length(dth) == pytest.approx(C * dth, rel=1e-15)
    for z1, z2 in [(-0.5, 0.5), (0.1, 0.45), (-0.3, -0.05)]:  # meridians
        exact = C * (math.sinh(z2 / C) - math.sinh(z1 / C))
        assert catenoid_geodesic_length((1.0, z1), (1.0, z2)) == pytest.approx(exact)
        assert catenoid_meridian_length(z1, z2) == pytest.approx(exact, rel=1e-15)
    # the paper's catenoid: ring to ring along a meridian, 2c·sinh(1/(2c))
    assert catenoid_meridian_length(-0.5, 0.5) == pytest.approx(1.0589102753, rel=1e-10)


def test_meridian_and_neck_by_quadrature():
    # a near-meridian and a near-neck path: quadrature tends to the closed forms
    g = catenoid_geodesics((0.0, -0.4), (1e-7, 0.3))[0]
    assert g.length == pytest.approx(catenoid_meridian_length(-0.4, 0.3), rel=1e-12)
    g = catenoid_geodesics((0.0, 1e-9), (1.0, -1e-9))[0]
    assert g.length == pytest.approx(C * 1.0, rel=1e-8)


def test_points_as_3d_or_theta_z():
    def xyz(theta, z):
        r = C * math.cosh(z / C)
        return np.array([r * math.cos(theta), r * math.sin(theta), z])

    a, b = (0.4, -0.3), (2.1, 0.45)
    ref = catenoid_geodesic_length(a, b)
    assert catenoid_geodesic_length(xyz(*a), xyz(*b)) == pytest.approx(ref, rel=1e-13)
    # θ is taken modulo 2π and the path may go either way round
    assert catenoid_geodesic_length((a[0] + 2 * math.pi, a[1]), b) == pytest.approx(ref)
    assert catenoid_geodesic_length(b, a) == pytest.approx(ref, rel=1e-13)
    # symmetric under z → −z
    flipped = catenoid_geodesic_length((a[0], -a[1]), (b[0], -b[1]))
    assert flipped == pytest.approx(ref, rel=1e-13)
    with pytest.raises(JaxgeoError):
        catenoid_geodesic_length((1.0, 2.0, 3.0, 4.0), b)


# (θ1, z1), (θ2, z2), kind of the shortest geodesic. Rings at z = ±0.5.
PAIRS = [
    ((0.0, -0.5), (0.0, 0.5), "meridian"),  # ring to ring
    ((1.0, 0.1), (1.0, 0.45), "meridian"),  # same side
    ((0.0, -0.5), (1.0, 0.5), "monotone"),  # ring to ring across the neck
    ((0.0, -0.1), (0.3, 0.2), "monotone"),  # short, across the neck
    ((0.0, -0.2), (3.0, 0.5), "monotone"),  # long, across the neck
    ((0.0, 0.5), (2.8, -0.5), "monotone"),  # long, ring to ring
    ((0.0, 0.1), (0.4, 0.45), "monotone"),  # same side, no turning point
    ((0.0, 0.3), (1.5, 0.4), "turning"),  # turning point, same side
    ((0.0, 0.5), (2.5, 0.5), "turning"),  # both on the ring
    ((0.0, -0.35), (1.2, -0.45), "turning"),  # below the neck
    ((0.0, 0.1), (2.0, 0.3), "turning"),  # turning close to the neck
    ((0.0, 0.5), (3.0, 0.5), "turning"),  # long, nearly opposite on the ring
    ((0.0, 0.01), (1.0, 0.0), "monotone"),  # near the neck circle, one on it
    ((0.0, 0.005), (2.0, -0.003), "monotone"),  # spiralling near the neck
]


@pytest.mark.parametrize("p, q, kind", PAIRS)
def test_catenoid_clairaut_vs_shooting(p, q, kind):
    geos = catenoid_geodesics(p, q)
    assert geos[0].kind == kind
    assert geos[0].length == catenoid_geodesic_length(p, q)
    # every geodesic found (both ways round), each shot from the straight line of
    # the conformal chart: nothing from the Clairaut solution but the travel
    for g in geos:
        L, _ = _catenoid_geodesic_length_shooting(p, q, travel=g.travel)
        assert L == pytest.approx(g.length, rel=CROSS_CHECK_RTOL)


def test_catenoid_random_pairs_vs_shooting():
    rng = np.random.default_rng(0)
    for _ in range(8):
        p = (rng.uniform(-3, 3), rng.uniform(-0.5, 0.5))
        q = (rng.uniform(-3, 3), rng.uniform(-0.5, 0.5))
        g = catenoid_geodesics(p, q)[0]
        L, _ = _catenoid_geodesic_length_shooting(p, q, travel=g.travel)
        assert L == pytest.approx(g.length, rel=CROSS_CHECK_RTOL)


def test_catenoid_other_c_and_the_longer_way_round():
    c = 0.5
    p, q = (0.0, 0.4), (2.0, 0.6)
    geos = catenoid_geodesics(p, q, c)
    assert [g.kind for g in geos] == ["turning", "turning"]
    assert geos[0].travel == pytest.approx(2.0) and geos[1].travel < 0
    for g in geos:
        L, _ = _catenoid_geodesic_length_shooting(p, q, c, travel=g.travel)
        assert L == pytest.approx(g.length, rel=CROSS_CHECK_RTOL)


def test_catenoid_bounds():
    # chord ≤ geodesic ≤ (arc of p's parallel + meridian), for assorted pairs
    def xyz(theta, z):
        r = C * math.cosh(z / C)
        return np.array([r * math.cos(theta), r * math.sin(theta), z])

    for p, q, _ in PAIRS:
        L = catenoid_geodesic_length(p, q)
        dth = abs((q[0] - p[0] + math.pi) % (2 * math.pi) - math.pi)
        detour = C * math.cosh(p[1] / C) * dth + catenoid_meridian_length(p[1], q[1])
        assert np.linalg.norm(xyz(*p) - xyz(*q)) <= L <= detour + 1e-15


def test_catenoid_opposite_points_on_ring():
    # Δθ = π: both ways round are geodesics of equal length
    geos = catenoid_geodesics((0.0, 0.5), (math.pi, 0.5))
    assert geos[0].length == pytest.approx(geos[1].length, rel=1e-13)
    assert geos[0].travel == -geos[1].travel
