"""Material law, compensation and the reassembly stress check (issue 15, items 1
and 3). The acceptance case: a developable cylinder patch, whose flattening is an
isometry, so the reassembled cloth's strain is exactly the compensation."""

import numpy as np
import pytest

from jaxgeo import JaxgeoError
from jaxgeo.cutting import (
    BoundaryCompensation,
    Compensation,
    Material,
    Prestress,
    compensate_pattern,
    reassemble,
)
from jaxgeo.cutting.compensate import principal_angle
from jaxgeo.pattern import CutMesh, make_pattern
from jaxgeo.surfaces import grid_faces

MATERIAL = Material(e_warp=600.0, e_weft=400.0, nu=0.3, g=30.0)
PRESTRESS = Prestress(warp=2.0, weft=1.5)


def cylinder_patch(n=10, radius=0.7, angle=1.2, height=0.8):
    """A cylinder patch meshed by planar rectangles split in two: a polyhedral
    surface that develops exactly (every interior vertex has angle sum 2π)."""
    a, z = np.meshgrid(np.linspace(0, angle, n + 1), np.linspace(0, height, n + 1))
    a, z = a.T.ravel(), z.T.ravel()
    v = np.column_stack([radius * np.cos(a), radius * np.sin(a), z])
    return v, grid_faces(n, n)


@pytest.fixture(scope="module")
def cylinder_pattern():
    v, f = cylinder_patch()
    empty = np.zeros((0, 2), int)
    cut = CutMesh(v, f, empty, np.zeros(0, int), np.zeros(len(f), int), [])
    return make_pattern(cut)


def test_stiffness_inverts_the_compliance():
    q, s = np.asarray(MATERIAL.stiffness()), np.asarray(MATERIAL.compliance())
    assert np.allclose(q @ s, np.eye(3), rtol=0, atol=1e-14)
    assert np.allclose(q, q.T)


@pytest.mark.parametrize(
    "warp", ["principal", "strip", [0.3], np.array([0.0, 1.0, 1.0])]
)
def test_cylinder_reassembly_equals_closed_form(cylinder_pattern, warp):
    cw, cf = 1.5, 3.0
    cut = compensate_pattern(cylinder_pattern, Compensation(cw, cf), warp=warp)
    stress = reassemble(cut, MATERIAL, PRESTRESS).stress[0]
    # closed form: ε = (c_w, c_f, 0) in the warp frame, σ = Q ε
    e = np.array([cw, cf, 0.0]) / 100
    d = 1 - MATERIAL.nu**2 * MATERIAL.e_weft / MATERIAL.e_warp
    closed = np.array(
        [
            (MATERIAL.e_warp * e[0] + MATERIAL.nu * MATERIAL.e_weft * e[1]) / d,
            (MATERIAL.nu * MATERIAL.e_weft * e[0] + MATERIAL.e_weft * e[1]) / d,
            0.0,
        ]
    )
    # the flattening of an exactly developable mesh is an isometry up to the
    # least-squares tolerance (1e-10), far inside the 1e-6 asked
    assert np.abs(stress - closed).max() <= 1e-6 * np.abs(closed).max()


def test_deviation_vanishes_at_the_prestress_strain(cylinder_pattern):
    eps = np.asarray(PRESTRESS.strain(MATERIAL))
    comp = Compensation(100 * eps[0], 100 * eps[1])
    r = reassemble(compensate_pattern(cylinder_pattern, comp), MATERIAL, PRESTRESS)
    s = r.total_stats()
    assert s["max"] <= 1e-6 * PRESTRESS.warp
    # and a compensation 10% off leaves a deviation of 10% of the prestress
    comp = Compensation(110 * eps[0], 110 * eps[1])
    r = reassemble(compensate_pattern(cylinder_pattern, comp), MATERIAL, PRESTRESS)
    expected = 0.1 * np.hypot(PRESTRESS.warp, PRESTRESS.weft)
    assert np.isclose(r.total_stats()["rms"], expected, rtol=1e-6)


def test_compensation_varies_towards_a_boundary_line(cylinder_pattern):
    v, _ = cylinder_patch()
    bottom = v[np.isclose(v[:, 2], 0.0)]
    comp = Compensation(1.0, 2.0, (BoundaryCompensation(bottom, 3.0, 0.5, 0.4),))
    at = comp.at(np.array([[0.7, 0.0, 0.0], [0.7, 0.0, 0.2], [0.7, 0.0, 0.6]]))
    assert np.allclose(at, [[0.03, 0.005], [0.02, 0.0125], [0.01, 0.02]])
    cut = compensate_pattern(cylinder_pattern, comp)
    strain = (
        reassemble(cut, MATERIAL, PRESTRESS).stress[0]
        @ np.asarray(MATERIAL.compliance()).T
    )
    # met in the least-squares sense: the strain follows the field on average
    c = cut[0].compensation
    assert np.corrcoef(strain[:, 0], c[:, 0])[0, 1] > 0.9
    assert abs(strain[:, 0].mean() - c[:, 0].mean()) < 0.1 * c[:, 0].mean()


def test_principal_angle_of_a_turned_rectangle():
    r = np.array([[0, 0], [3, 0], [3, 1], [0, 1]], float)
    t = 0.4
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    ang = principal_angle(r @ rot.T, np.array([[0, 1, 2], [0, 2, 3]]))
    assert np.isclose(np.mod(ang, np.pi), t)


def test_bad_material_and_compensation_are_named():
    with pytest.raises(JaxgeoError, match="e_weft"):
        Material(600.0, -1.0, 0.3, 30.0)
    with pytest.raises(JaxgeoError, match="Poisson"):
        Material(100.0, 400.0, 0.6, 30.0)
    with pytest.raises(JaxgeoError, match="compensation"):
        Compensation(70.0, 1.0)
