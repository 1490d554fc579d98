"""Cutting the cone tent along radial geodesic seams, flattening, export, CLI."""

import ezdxf
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import seams, surfaces
from jaxgeo._pattern_cli import main as pattern_main
from jaxgeo.export import offset_polygon, write_dxf, write_seams_obj, write_svg
from jaxgeo.pattern import make_pattern, strip_width


def test_strip_width_of_a_rotated_rectangle():
    r = np.array([[0, 0], [3, 0], [3, 1], [0, 1]], float)
    t = 0.4
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    w, _ = strip_width(r @ rot.T)
    assert np.isclose(w, 1.0)


def test_offset_square():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    assert np.allclose(offset_polygon(sq, 0.1), sq + 0.1 * np.sign(sq - 0.5))


@pytest.fixture(scope="module")
def cone_pattern():
    mesh = jg.Mesh(*surfaces.cone_tent(48, 12))
    layout = seams.radial_layout(mesh, 16)
    cut, paths = seams.cut(mesh, layout)
    return mesh, layout, cut, paths, make_pattern(cut)


def test_cone_tent_cloths(cone_pattern):
    _, layout, cut, _, pat = cone_pattern
    assert cut.n_cloths == 16
    assert all(len(s) == 2 for s in cut.cloth_seams())
    strain = max(c.strain_max for c in pat.cloths)
    diff = max(pat.seam_copy_difference().values())
    print(f"cone tent: max strain {strain:.3%}, seam copies differ {diff:.2e}")
    assert strain <= 0.01
    assert diff <= 0.005
    assert len(pat.seam_copy_difference()) == 16
    for c in pat.cloths:  # the flattened seam keeps its 3-D length
        for l3, l2 in c.seam_lengths.values():
            assert abs(l2 - l3) / l3 < 0.005


def test_exports(cone_pattern, tmp_path):
    _, _, cut, paths, pat = cone_pattern
    write_dxf(pat, tmp_path / "p.dxf", seam_allowance=0.02)
    doc = ezdxf.readfile(tmp_path / "p.dxf")
    closed = [e for e in doc.modelspace().query("LWPOLYLINE") if e.closed]
    assert len([e for e in closed if e.dxf.layer == "CUT"]) == len(pat.cloths)
    assert doc.modelspace().query('LWPOLYLINE[layer=="SEAM"]')
    write_svg(pat, tmp_path / "p.svg")
    assert (tmp_path / "p.svg").read_text().count("<polygon") == len(pat.cloths)
    pl = [np.asarray(paths.points[i])[: int(paths.count[i])] for i in range(16)]
    write_seams_obj(pl, tmp_path / "s.obj")
    assert (tmp_path / "s.obj").read_text().count("\nl ") == 16


def test_cli_pattern_writes_a_dxf_that_fits(tmp_path):
    v, f = surfaces.cone_tent(48, 12)
    import trimesh

    trimesh.Trimesh(v, f, process=False).export(tmp_path / "tent.obj")
    roll = 0.4
    code = pattern_main(
        [
            "pattern",
            str(tmp_path / "tent.obj"),
            "--seams",
            "16",
            "--roll-width",
            str(roll),
            "--out",
            str(tmp_path / "out"),
            "--steps",
            "3",
            "--rounds",
            "1",
        ]
    )
    assert code == 0
    doc = ezdxf.readfile(tmp_path / "out" / "pattern.dxf")
    cuts = [e for e in doc.modelspace().query('LWPOLYLINE[layer=="CUT"]')]
    assert len(cuts) == 16 and all(e.closed for e in cuts)
    for e in cuts:
        pts = np.array([p[:2] for p in e.get_points()])
        assert strip_width(pts)[0] <= roll + 1e-9
