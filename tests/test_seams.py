"""Seam layouts; their optimisation on the twin-peak tent (no rotational
symmetry)."""

import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import seams, surfaces


@pytest.mark.slow  # a new mesh shape: ~14 s of compiles on the shared machine
def test_parallel_layout_spans_the_sail_in_equal_bands():
    from jaxgeo.formfinding import four_point_sail

    sail = four_point_sail(8)
    mesh = jg.Mesh(sail.vertices, sail.faces)
    layout = seams.parallel_layout(mesh, 3)
    assert layout.n_seams == 3 and (layout.loop_a == 0).all()
    ends = layout.end_points(mesh)
    # seams parallel to x: both ends of a seam at one y, the lines at 1/4, 2/4,
    # 3/4 of the sail's plan width at x = 3 (the centroid), between the sagging
    # south and north cables; loop_parameter's projection onto the boundary
    # polyline is exact to rounding (1e-9 of the 6 m span)
    south = sail.cable_polyline("south")  # x increasing from corner to corner
    lo = np.interp(3.0, south[:, 0], south[:, 1])
    hi = 6.0 - lo  # the plan net is symmetric (FDM solves x, y apart from z)
    assert lo > 0.1  # the cable sags: a band from the corners' extent would be off
    assert np.allclose(ends[:, 0, 1], ends[:, 1, 1], atol=1e-9 * 6)
    expected = lo + (hi - lo) * np.array([1, 2, 3]) / 4
    assert np.allclose(ends[:, 0, 1], expected, atol=1e-9 * 6)
    assert (ends[:, 0, 0] < ends[:, 1, 0]).all()  # from the west cable to the east
    with pytest.raises(jg.JaxgeoError, match="one boundary loop"):
        seams.parallel_layout(jg.Mesh(*surfaces.cone_tent(12, 3)), 3)


@pytest.mark.slow  # compiles several solvers, 3 rounds of 20 BFGS steps
def test_twin_peak_optimisation_fits_the_roll():
    mesh = jg.Mesh(*surfaces.twin_peak_tent(n_side=8, n_radial=10))
    layout = seams.peaks_layout(mesh, 7, 3, 0.4, sector=172)
    roll = 0.75
    cut0, _ = seams.cut(mesh, layout)
    from jaxgeo.pattern import make_pattern

    start = make_pattern(cut0)
    assert (start.widths > roll).any()  # the uniform start leaves cloths too wide
    first, layout2, pat, history = seams.fit_roll(
        mesh, layout, roll, rounds=3, steps=20
    )
    print("start widths", start.widths.round(3), "J", first.j_start)
    print("end widths", pat.widths.round(3), "J per round", history)
    assert (pat.widths <= roll).all()
    assert first.j_end < first.j_start  # same objective (round 1, unscaled)
    assert np.all(np.isfinite(pat.widths))


def test_old_modules_re_export_the_cutting_modules_names():
    """`jaxgeo.seams` and `jaxgeo.pattern` are re-export modules: every public
    name they list is the very object of its `jaxgeo.cutting` module."""
    from jaxgeo import boundary, pattern
    from jaxgeo.cutting import cut, flatten, layout, seam_width

    homes = (layout, cut, flatten, seam_width, boundary)
    for old in (seams, pattern):
        for name in old.__all__:
            obj = getattr(old, name)
            owner = [m for m in homes if getattr(m, name, None) is obj]
            assert owner, f"{old.__name__}.{name} is not a cutting module's"
    assert seams.Layout is layout.Layout and pattern.Cloth is flatten.Cloth
    assert seams.cut is cut.cut and pattern.cut_mesh is cut.cut_mesh
    assert seams.Weights().options == layout.TRACE_OPTIONS


def test_old_module_imports_first_in_a_fresh_interpreter():
    """`cutting/__init__` imports modules that import `seams` and `pattern`,
    which re-export `cutting`'s names: importing `seams` (or `pattern`) first
    must not meet it half-initialised (jaxgeo/__init__ imports `cutting` first).
    One interpreter start, ~3 s."""
    module = "jaxgeo.seams"
    import subprocess
    import sys

    code = f"import {module} as m; print(sorted(m.__all__)[0])"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]


@pytest.mark.slow  # 13 s niced beside CI: among the fast set's longest (12-08)
def test_bridged_layout_leaves_every_seam_from_a_ring():
    mesh = jg.Mesh(*surfaces.twin_peak_tent(n_side=4, n_radial=4))
    n, b, sector, shift = 5, 3, 130.0, 1.0
    layout = seams.bridged_layout(mesh, n, b, sector, shift)
    assert layout.n_seams == 2 * n + b
    assert (layout.loop_a == np.repeat([1, 2, 1], [n, n, b])).all()
    assert (layout.loop_b == np.repeat([0, 0, 2], [n, n, b])).all()
    ends = layout.end_points(mesh)  # (N, 2, 3)
    # the ring ends at the stated plan angles round each ring's centre,
    # measured from the direction away from the other ring (+x for the right
    # ring, loop 1 here); the angles are of points on the ring polyline, so
    # they hold to the rounding of loop_parameter's projection (1e-9)
    centres = {1: np.array([1.0, 0.0]), 2: np.array([-1.0, 0.0])}
    mirror = {1: 1.0, 2: -1.0}

    def angle(p, ring):
        d = p[:2] - centres[ring]
        return np.degrees(np.arctan2(d[1], mirror[ring] * d[0]))

    out = np.linspace(-sector, sector, n) + shift
    bridges = sector + (360 - 2 * sector) * np.arange(1, b + 1) / (b + 1) + shift
    for ring, rows in ((1, slice(0, n)), (2, slice(n, 2 * n))):
        got = [angle(p, ring) for p in ends[rows, 0]]
        assert np.allclose(got, out, atol=1e-6)
    wrap = (bridges + 180) % 360 - 180
    assert np.allclose([angle(p, 1) for p in ends[2 * n :, 0]], wrap, atol=1e-6)
    assert np.allclose([angle(p, 2) for p in ends[2 * n :, 1]], wrap, atol=1e-6)
    # the outer ends lie where the plan rays meet the outer loop: on the
    # rectangle's sides x = ±2 or y = ±1 (the tent's plan), in the ray's direction
    for ring, rows in ((1, slice(0, n)), (2, slice(n, 2 * n))):
        for p_ring, p_out in ends[rows]:
            a, c = p_ring[:2] - centres[ring], p_out[:2] - centres[ring]
            assert abs(a[0] * c[1] - a[1] * c[0]) < 1e-9 * np.linalg.norm(c)
            assert a @ c > 0
            assert np.isclose(abs(p_out[0]), 2) or np.isclose(abs(p_out[1]), 1)
    with pytest.raises(jg.JaxgeoError, match="three boundary loops"):
        seams.bridged_layout(jg.Mesh(*surfaces.cone_tent(12, 3)), 5, 3)
    with pytest.raises(jg.JaxgeoError, match="sector"):
        seams.bridged_layout(mesh, 5, 3, sector=190.0)
    with pytest.raises(jg.JaxgeoError, match="at least one seam"):
        seams.bridged_layout(mesh, 5, [])
    # angles given instead of counts
    given = seams.bridged_layout(mesh, [-40.0, 0.0, 40.0], [170.0, 190.0], shift=2.0)
    assert given.n_seams == 8
    ends = given.end_points(mesh)
    assert np.allclose([angle(p, 2) for p in ends[3:6, 0]], [-38, 2, 42], atol=1e-6)
    assert np.allclose([angle(p, 1) for p in ends[6:, 0]], [172, -168], atol=1e-6)
