"""Boundary loops and points on them by arc length."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import surfaces
from jaxgeo._errors import JaxgeoError
from jaxgeo.boundary import (
    boundary_loops,
    loop_parameter,
    loop_point,
    pack_loops,
    packed_point,
)


def _cone():
    return jg.Mesh(*surfaces.cone_tent(24, 6, outer_radius=1.0, inner_radius=0.2))


def test_loops_of_cone_tent():
    mesh = _cone()
    loops = boundary_loops(mesh)
    assert [lp.size for lp in loops] == [24, 24]
    # inscribed 24-gons: perimeter 2·n·r·sin(π/n)
    for lp, r in zip(loops, (1.0, 0.2)):
        assert np.isclose(float(lp.length(mesh)), 48 * r * np.sin(np.pi / 24))


def test_twin_peak_has_three_loops():
    mesh = jg.Mesh(*surfaces.twin_peak_tent(n_side=4, n_radial=4))
    assert len(boundary_loops(mesh)) == 3


def test_loops_follow_the_faces_from_their_lowest_vertex():
    """Each loop starts at its lowest vertex and runs through its edges as their
    faces do (`corners` name them); together the loops hold every boundary edge
    once, longest loop first."""
    mesh = jg.Mesh(*surfaces.twin_peak_tent(n_side=4, n_radial=4))
    faces = np.asarray(mesh.faces)
    walked = []
    loops = boundary_loops(mesh)
    for lp in loops:
        vs, fs, cs = (np.asarray(x) for x in (lp.vertices, lp.faces, lp.corners))
        assert vs[0] == vs.min() and len(set(vs.tolist())) == lp.size
        np.testing.assert_array_equal(faces[fs, cs[:, 0]], vs)
        np.testing.assert_array_equal(faces[fs, cs[:, 1]], np.roll(vs, -1))
        assert np.all((cs[:, 1] - cs[:, 0]) % 3 == 1)  # the face's own order
        walked += [tuple(sorted(e)) for e in zip(vs.tolist(), np.roll(vs, -1))]
    edges = np.asarray(mesh.edges)[np.asarray(mesh.edge_faces)[:, 1] < 0]
    assert sorted(walked) == sorted(map(tuple, edges.tolist()))
    lengths = [float(lp.length(mesh)) for lp in loops]
    assert lengths == sorted(lengths, reverse=True)


def test_a_closed_mesh_has_no_loops():
    with pytest.raises(JaxgeoError, match="closed"):
        boundary_loops(jg.Mesh(*surfaces.icosphere(1)))


def test_point_at_arc_length_and_periodic():
    mesh = _cone()
    lp = boundary_loops(mesh)[0]
    poly = lp.polyline(mesh)
    for s in (0.0, 0.13, 0.5, 0.999):
        p = np.asarray(loop_point(mesh, lp, s).position(mesh))
        assert np.isclose(loop_parameter(mesh, lp, p), s, atol=1e-9)
        assert np.min(np.linalg.norm(poly - p, axis=1)) < 0.3
    a = loop_point(mesh, lp, 0.3).position(mesh)
    b = loop_point(mesh, lp, 1.3).position(mesh)
    assert np.allclose(a, b)


def test_derivative_in_s_is_the_tangent_times_perimeter():
    mesh = _cone()
    lp = boundary_loops(mesh)[0]
    s = 0.21

    def pos(s):
        return loop_point(mesh, lp, s, inset=1e-6).position(mesh)

    d = jax.jacfwd(pos)(jnp.asarray(s))
    assert np.isclose(np.linalg.norm(d), float(lp.length(mesh)), rtol=1e-5)
    h = 1e-6
    fd = (pos(s + h) - pos(s - h)) / (2 * h)
    assert np.allclose(d, fd, rtol=1e-5)


def test_packed_points_match_single_loops():
    mesh = _cone()
    loops = boundary_loops(mesh)
    packed = pack_loops(loops)
    for k, lp in enumerate(loops):
        for s in (0.05, 0.77):
            a = loop_point(mesh, lp, s)
            b = packed_point(mesh, packed, k, s)
            assert int(a.face) == int(b.face)
            assert np.allclose(a.bary, b.bary)
