"""Force density form finding (Schek 1974) and the four-point sail."""

import numpy as np
import pytest

from jaxgeo import JaxgeoError, surfaces
from jaxgeo.formfinding import force_density, four_point_sail


def test_a_cable_of_equal_force_densities_is_straight_and_evenly_divided():
    n = 6
    edges = np.stack([np.arange(n), np.arange(1, n + 1)], 1)
    ends = np.array([[0.0, 0.0, 0.0], [3.0, 1.0, 2.0]])
    x = force_density(edges, np.full(n, 2.5), np.array([0, n]), ends, n + 1)
    expected = ends[0] + np.linspace(0, 1, n + 1)[:, None] * (ends[1] - ends[0])
    assert np.allclose(x, expected, rtol=0, atol=1e-12 * 3.0)


@pytest.mark.parametrize("q_cable", [2.0, 6.0])
def test_sail_is_in_equilibrium(q_cable):
    n = 8
    sail = four_point_sail(n, q_cable=q_cable)
    v = sail.vertices
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    res = np.zeros_like(v)
    for e in (np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1),
              np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1)):  # fmt: skip
        a, b = e[:, 0], e[:, 1]
        cable = np.isin(e, np.concatenate(list(sail.cables.values()))).all(1) & (
            (a // (n + 1) == b // (n + 1)) | (a % (n + 1) == b % (n + 1))
        )
        on_side = ((a // (n + 1) == b // (n + 1)) & np.isin(a // (n + 1), [0, n])) | (
            (a % (n + 1) == b % (n + 1)) & np.isin(a % (n + 1), [0, n])
        )
        q = np.where(cable & on_side, q_cable, 1.0)[:, None]
        f = q * (v[b] - v[a])
        np.add.at(res, a, f)
        np.add.at(res, b, -f)
    corners = [idx[0, 0], idx[n, 0], idx[n, n], idx[0, n]]
    res[corners] = 0
    # residual of a direct sparse solve: rounding, relative to q·span
    assert np.abs(res).max() <= 1e-10 * q_cable * 6.0
    assert np.allclose(v[corners], [[0, 0, 0], [6, 0, 2], [6, 6, 0], [0, 6, 2]])


def test_stiffer_cables_sag_less():
    sag = []
    for q in (2.0, 6.0, 20.0):
        south = four_point_sail(8, q_cable=q).cable_polyline("south")
        sag.append(south[:, 1].max())  # inward (plan) sag of the south cable
    assert sag[0] > sag[1] > sag[2] > 0


def test_sail_surface_is_a_builtin():
    v, f = surfaces.four_point_sail(6)
    assert v.shape == (49, 3) and f.shape == (72, 3)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert (n[:, 2] > 0).all()
    with pytest.raises(JaxgeoError, match="force densities"):
        four_point_sail(6, q_cable=-1.0)


def test_old_import_path_reexports_the_form_finder():
    import jaxgeo.cutting.formfinding as old
    import jaxgeo.formfinding as new

    assert old.four_point_sail is new.four_point_sail
    assert old.force_density is new.force_density and old.Sail is new.Sail
