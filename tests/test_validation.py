"""The validation tables, suites and `jaxgeo validate` (small meshes: resolution 3,
one JIT compilation per mesh, shared by the tests through the module fixture)."""

import csv
import math

import numpy as np
import pytest

from jaxgeo import cli, validation
from jaxgeo._errors import JaxgeoError
from jaxgeo.surfaces import catenoid_parameter

RES = 3
#: The paper's sphere claim: the traced arc is within 0.5 % of the great circle.
PAPER_SPHERE_TOL = 0.005


@pytest.fixture(scope="module")
def table() -> validation.Table:
    return validation.validate(RES, methods=["laser"])


def test_suites_are_deterministic_vertex_pairs():
    for make in (validation.sphere_suite, validation.catenoid_suite):
        a, b = make(RES), make(RES)
        assert a.pairs == b.pairs and len(a.pairs) >= 8
        for p in a.pairs:
            assert p.v1 != p.v2 and p.analytic > 0
    # the same analytic points at every resolution (convergence studies)
    for make in (validation.sphere_suite, validation.catenoid_suite):
        coarse, fine = make(RES), make(RES + 1)
        for p, q in zip(coarse.pairs, fine.pairs):
            np.testing.assert_allclose(coarse.vertices[p.v1], fine.vertices[q.v1])
            np.testing.assert_allclose(coarse.vertices[p.v2], fine.vertices[q.v2])
            assert p.analytic == pytest.approx(q.analytic, rel=1e-12)
    angles = [math.degrees(p.analytic) for p in validation.sphere_suite(RES).pairs]
    assert min(angles) < 12 and max(angles) > 150


def test_catenoid_suite_has_the_papers_arcs():
    suite = validation.catenoid_suite(RES)
    by_id = {p.pair: p for p in suite.pairs}
    c = catenoid_parameter()
    # arc BE of Fig. 9: a quarter of the neck circle, 1.332569 in the paper
    assert by_id["C7"].analytic == pytest.approx(c * math.pi / 2, rel=1e-12)
    assert by_id["C7"].analytic == pytest.approx(1.332569, abs=5e-6)
    assert by_id["C1"].analytic == pytest.approx(
        validation.catenoid_meridian_length(-0.5, 0.5), rel=1e-12
    )


def test_resolution_checked():
    with pytest.raises(JaxgeoError):
        validation.sphere_suite(2)
    with pytest.raises(JaxgeoError):
        validation.validate(RES, suites=["torus"])
    with pytest.raises(JaxgeoError):
        validation.references.exact_solver("mmp", np.eye(3), np.array([[0, 1, 2]]))


def test_one_suite_row_with_the_default_method():
    """The fast set's part: `run_suite` on the 320-face unit icosphere (two vertex
    pairs, great-circle lengths) with the default method at default options, the
    solver tests/test_cli.py and tests/test_locate.py compile on that shape. The
    exact method is the polyhedral geodesic: its method error against MMP is
    rounding (1e-9: the refinement's acceptance bound, tests/test_methods.py), and
    the columns add up (total = method + discretisation, to rounding)."""
    pytest.importorskip("pygeodesic.geodesic")
    from jaxgeo.surfaces import icosphere

    v, f = icosphere(2)
    pairs = []
    for k, (i, j) in enumerate([(0, 40), (5, 150)]):
        arc = float(validation.great_circle_length(v[i], v[j]))
        pairs.append(validation.Pair(f"S{k + 1}", "great circle", i, j, arc))
    suite = validation.Suite("sphere", 2, v, f, tuple(pairs))
    table = validation.run_suite(suite, ["exact"], exact_solver="pygeodesic")
    assert [r.pair for r in table.rows] == ["S1", "S2"]
    for r in table.rows:
        assert r.results["exact"].status == "SUCCESS"
        assert abs(r.method_error("exact")) <= 1e-9
        total = r.method_error("exact") + r.discretisation_error
        assert r.error("exact") == pytest.approx(total, rel=0, abs=1e-14)
        # the polyhedral geodesic on an inscribed mesh is shorter than the arc
        assert -0.05 < r.discretisation_error < 0


@pytest.mark.slow
def test_columns_are_consistent(table):
    cols = table.columns()
    n = len(table.rows)
    assert n == 8 + len(validation.CATENOID_PAIRS)
    assert all(len(v) == n for v in cols.values())
    assert table.exact_solver in ("pygeodesic", "potpourri3d")
    assert (table.methods) == ("laser",)
    total = np.array(cols["laser_error"])
    method = np.array(cols["laser_method_error"])
    discr = np.array(cols["discretisation_error"])
    # the three errors share the denominator (analytic length): they add exactly
    np.testing.assert_allclose(method + discr, total, rtol=0, atol=1e-14)
    analytic = np.array(cols["analytic"])
    np.testing.assert_allclose(
        np.array(cols["laser_length"]), analytic * (1 + total), rtol=1e-14
    )
    np.testing.assert_allclose(
        np.array(cols["exact"]), analytic * (1 + discr), rtol=1e-14
    )
    assert set(cols["laser_status"]) == {"SUCCESS"}
    # the exact polyhedral geodesic is the shortest path on the mesh: no traced
    # path between the same vertices is shorter (up to the solvers' rounding)
    assert method.min() > -1e-9
    assert all(t > 0 for t in cols["laser_time"])


@pytest.mark.slow
def test_sphere_within_the_papers_half_percent(table):
    rows = [r for r in table.rows if r.suite == "sphere"]
    for r in rows:
        assert abs(r.error("laser")) < PAPER_SPHERE_TOL, r
        # on the sphere the laser ray IS the polyhedral geodesic, nearly
        assert abs(r.method_error("laser")) < 1e-4, r


@pytest.mark.slow
def test_catenoid_method_error_is_the_descent_curve(table):
    # the laser ray tends to the steepest-descent curve of |x − q|, not to the
    # geodesic: on the long arcs its length is far nearer to that curve's
    rows = {r.pair: r for r in table.rows if r.suite == "catenoid"}
    v = validation.catenoid_suite(RES).vertices
    for pid in ("C5", "C13"):
        r = rows[pid]
        descent, _ = validation.catenoid_descent_curve(v[r.v1], v[r.v2])
        laser = r.results["laser"].length
        assert abs(laser - descent) < 0.2 * abs(laser - r.analytic)
    # meridians and the neck circle are traced exactly (on the mesh)
    for pid in ("C1", "C7"):
        assert abs(rows[pid].method_error("laser")) < 1e-6


@pytest.mark.slow
def test_markdown_and_csv(table, tmp_path):
    md = table.to_markdown()
    assert "| S6 | great circle 90° (Fig. 8)" in md
    assert "laser method err" in md and "C7" in md
    path = tmp_path / "t.csv"
    table.to_csv(path)
    with open(path) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(table.rows)
    assert float(rows[0]["analytic"]) == table.rows[0].analytic
    back = validation.read_csv(path)
    assert back.methods == table.methods and back.exact_solver == table.exact_solver
    assert back.rows == table.rows  # floats written with repr: exact round trip


@pytest.mark.slow
def test_convergence_summary_and_plot(table, tmp_path):
    summary = validation.convergence_summary(table)
    assert [e["suite"] for e in summary] == ["sphere", "catenoid"]
    for e in summary:
        assert 0 < e["exact"] < 0.01 and e["laser"] >= 0
    md = validation.summary_markdown(summary, table.methods)
    assert md.count("\n") == 4
    png = tmp_path / "c.png"
    validation.plot_convergence(summary, table.methods, png)
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_curves_end_at_the_points():
    p = np.array([1.0, 0.0, 0.0])
    q = np.array([0.0, 0.6, 0.8])
    arc = validation.great_circle_points(p, q, 50)
    np.testing.assert_allclose(arc[[0, -1]], [p, q], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(arc, axis=1), 1.0, rtol=1e-14)
    a, b = (0.0, -0.5), (2.0, 0.5)
    pts = validation.catenoid_geodesic_points(a, b, 200)
    c = catenoid_parameter()
    np.testing.assert_allclose(
        np.hypot(pts[:, 0], pts[:, 1]), c * np.cosh(pts[:, 2] / c), rtol=1e-12
    )
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert seg == pytest.approx(validation.catenoid_geodesic_length(a, b), rel=1e-4)
    np.testing.assert_allclose(pts[-1, 2], 0.5, atol=1e-9)


@pytest.mark.slow
def test_cli_validate_writes_csv_and_markdown(table, tmp_path, capsys):
    # same meshes as the fixture: the compiled solver is reused
    out_csv, out_md = tmp_path / "v.csv", tmp_path / "v.md"
    argv = ["validate", "--resolution", str(RES), "--csv", str(out_csv)]
    argv += ["--markdown", str(out_md), "--methods", "laser"]
    assert cli.main(argv) == 0
    captured = capsys.readouterr()
    assert "| C13 |" in captured.out
    assert "[sphere r3] laser" in captured.err and "done in" in captured.err
    assert out_md.read_text() == captured.out
    with open(out_csv) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(table.rows)
    assert {r["laser_status"] for r in rows} == {"SUCCESS"}
    # the same numbers as the library call (deterministic)
    lengths = [float(r["laser_length"]) for r in rows]
    ref = [r.results["laser"].length for r in table.rows]
    np.testing.assert_allclose(lengths, ref, rtol=1e-12)


def test_cli_parses_resolution_lists():
    args = cli.build_parser().parse_args(["validate", "--resolution", "3,4,5"])
    assert args.resolution == [3, 4, 5] and args.suite == ["sphere", "catenoid"]
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["validate", "--resolution", "3,x"])
