"""Seam layouts; their optimisation on the twin-peak tent (no rotational
symmetry)."""

import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import seams, surfaces


@pytest.mark.slow  # a new mesh shape: ~14 s of compiles on the shared machine
def test_parallel_layout_spans_the_sail_in_equal_bands():
    mesh = jg.Mesh(*surfaces.four_point_sail(8))
    layout = seams.parallel_layout(mesh, 3)
    assert layout.n_seams == 3 and (layout.loop_a == 0).all()
    ends = layout.end_points(mesh)
    # seams parallel to x: both ends of a seam at one y, the lines at 1/4, 2/4,
    # 3/4 of the sail's plan extent in y ([0, 6]); loop_parameter's projection
    # onto the boundary polyline is exact to rounding (1e-9 of the 6 m span)
    assert np.allclose(ends[:, 0, 1], ends[:, 1, 1], atol=1e-9 * 6)
    assert np.allclose(ends[:, 0, 1], [1.5, 3.0, 4.5], atol=1e-9 * 6)
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
