"""The cut's snapping of seam points near vertices, and the flattening's report
of folds (issue 15: a pattern a fabricator can cut)."""

import numpy as np
import pytest
import trimesh

from jaxgeo import JaxgeoError, Mesh, shortest_path
from jaxgeo.pattern import SNAP, CutMesh, cut_mesh, make_pattern
from jaxgeo.surfaces import grid_faces


def _flat_grid(n=4):
    """The unit square, `n` × `n` squares split in two."""
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    v = np.column_stack([x.T.ravel(), y.T.ravel(), np.zeros((n + 1) ** 2)])
    return Mesh(v, grid_faces(n, n))


@pytest.mark.slow  # 16 s cold on 2 cores (README tests <= 5 min)
@pytest.mark.parametrize("offset", [0.3 * SNAP, 3 * SNAP])
def test_a_seam_near_vertices_is_snapped_onto_them(offset):
    """A straight seam at height 1/4 + offset·h (h = 1/4, the grid's edge)
    passes the vertices of the row y = 1/4 at `offset` of an edge: below SNAP it
    runs through them (no cut triangle has a side below SNAP of an edge); above
    it, it does not, and the thinnest triangles are of that size."""
    mesh, h = _flat_grid(), 0.25
    y = h + offset * h
    seam = shortest_path(mesh, np.array([0.0, y, 0.0]), np.array([1.0, y, 0.0]))
    cut = cut_mesh(mesh, [seam])
    row = {5 * k + 1 for k in (1, 2, 3)}  # vertex i is (i // 5, i % 5) · h
    on_seam = set(cut.seam_points[0].tolist())
    F = cut.faces
    sides = np.linalg.norm(cut.vertices[F[:, [1, 2, 0]]] - cut.vertices[F], axis=-1)
    if offset < SNAP:
        assert row <= on_seam
        assert sides.min() >= SNAP * h
    else:
        assert not row & on_seam
        # the seam crosses the diagonals next to those vertices at ~offset·h
        assert offset * h / 2 < sides.min() < 2 * offset * h


def _cap(z0, subdivisions=2):
    """The part of the unit icosphere above z = z0, as one cloth."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    keep = np.flatnonzero(m.triangles_center[:, 2] > z0)
    cap = m.submesh([keep], append=True)
    v, f = np.asarray(cap.vertices), np.asarray(cap.faces)
    empty = np.zeros((0, 2), int)
    return CutMesh(v, f, empty, np.zeros(0, int), np.zeros(len(f), int), [])


def test_a_cloth_too_curved_to_lie_flat_keeps_every_triangle_unfolded():
    """A hemisphere flattens with 28 % edge strain at most; a cap reaching 0.6
    below the equator is far from developable (its boundary circle, 2π·0.8, is
    64 % shorter than a flat circle of its geodesic radius arccos(−0.6), against
    36 % for the hemisphere). Least edge-length strain alone folded it (its
    flattening had inverted triangles); the one-sided area term
    (`_least_strain.AREA_FLOOR`) keeps every triangle the right way round, and
    the cloth and its summary count none."""
    from jaxgeo.cutting._least_strain import AREA_FLOOR

    hemi = make_pattern(_cap(0.0)).cloths[0]
    assert hemi.converged and hemi.inverted == 0
    big = make_pattern(_cap(-0.6)).cloths[0]
    a, b, c = (big.uv[big.faces[:, k]] for k in range(3))
    flat = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    p = big.vertices3d[big.faces]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    assert big.converged and big.inverted == int(np.sum(flat < 0)) == 0
    assert big.summary()["inverted_triangles"] == 0
    # a penalty, not a constraint: faces may go below the floor, not far
    # (measured 0.864 at least here)
    assert np.min(flat / area) > 0.5 * AREA_FLOOR


def test_a_closed_cloth_is_refused():
    """A cloth without boundary cannot be flattened (LSCM pins two boundary
    vertices): a `JaxgeoError` that says so, not an IndexError."""
    from jaxgeo.cutting.flatten import flatten_cloth

    m = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(JaxgeoError, match="closed cloth"):
        flatten_cloth(np.asarray(m.vertices), np.asarray(m.faces))
