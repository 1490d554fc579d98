import math

import numpy as np
import pytest
import scipy.sparse
import trimesh
from scipy.sparse.csgraph import connected_components

from jaxgeo._errors import JaxgeoError
from jaxgeo.surfaces import (
    catenoid,
    catenoid_parameter,
    catenoid_parameter_roots,
    cone_tent,
    icosphere,
    saddle,
    twin_peak_height,
    twin_peak_tent,
    uv_sphere,
)

# Vertices are computed from the surface formulas in float64, so residuals are a few
# ulps of the coordinates (~1e-16); 1e-12 leaves ample room.
ON_SURFACE = 1e-12

C_LARGE = catenoid_parameter(1.0, 1.0)


def _boundary_loops(faces: np.ndarray) -> int:
    """Number of boundary loops; asserts every boundary vertex has boundary degree 2
    (clean loops, no pinches)."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    assert count.max() <= 2, "an edge is shared by more than two faces"
    b = uniq[count == 1]
    if len(b) == 0:
        return 0
    verts, inv = np.unique(b, return_inverse=True)
    inv = inv.reshape(-1, 2)
    assert np.all(np.bincount(inv.ravel()) == 2), "boundary is not a set of loops"
    n = len(verts)
    graph = scipy.sparse.coo_matrix((np.ones(len(b)), (inv[:, 0], inv[:, 1])), (n, n))
    return connected_components(graph, directed=False)[0]


def _check_mesh(v, f, *, n_faces, euler, loops):
    assert v.dtype == np.float64 and v.ndim == 2 and v.shape[1] == 3
    assert np.issubdtype(f.dtype, np.integer) and f.shape == (n_faces, 3)
    assert f.min() == 0 and f.max() == len(v) - 1
    assert len(np.unique(f)) == len(v), "unreferenced vertices"
    assert np.all(np.isfinite(v))
    tm = trimesh.Trimesh(v, f, process=False)
    assert tm.is_winding_consistent
    assert tm.body_count == 1
    area = tm.area_faces
    assert area.min() > 1e-12 * area.mean(), "degenerate face"
    assert tm.euler_number == euler
    assert _boundary_loops(f) == loops
    assert tm.is_watertight == (loops == 0)
    return tm


GENERATORS = [
    (icosphere, {}),
    (uv_sphere, {}),
    (catenoid, {}),
    (cone_tent, {}),
    (twin_peak_tent, {}),
    (saddle, {}),
]


@pytest.mark.parametrize(
    "gen, kwargs", GENERATORS, ids=lambda x: getattr(x, "__name__", "")
)
def test_reproducible(gen, kwargs):
    v1, f1 = gen(**kwargs)
    v2, f2 = gen(**kwargs)
    assert np.array_equal(v1, v2) and np.array_equal(f1, f2)


@pytest.mark.parametrize(
    "subdivisions, n_faces", [(1, 80), (3, 1280), (4, 5120), (5, 20480)]
)
def test_icosphere(subdivisions, n_faces):
    v, f = icosphere(subdivisions=subdivisions, radius=2.5)
    tm = _check_mesh(v, f, n_faces=n_faces, euler=2, loops=0)
    assert np.max(np.abs(np.linalg.norm(v, axis=1) - 2.5)) <= ON_SURFACE * 2.5
    assert tm.volume > 0  # outward normals
    assert np.all(np.einsum("ij,ij->i", tm.face_normals, tm.triangles_center) > 0)


@pytest.mark.parametrize("n_lat, n_lon", [(2, 3), (12, 24), (24, 48)])
def test_uv_sphere(n_lat, n_lon):
    v, f = uv_sphere(n_lat=n_lat, n_lon=n_lon, radius=0.7)
    tm = _check_mesh(v, f, n_faces=2 * n_lon * (n_lat - 1), euler=2, loops=0)
    assert np.max(np.abs(np.linalg.norm(v, axis=1) - 0.7)) <= ON_SURFACE
    assert np.all(np.einsum("ij,ij->i", tm.face_normals, tm.triangles_center) > 0)
    assert np.sum(np.all(v[:, :2] == 0.0, axis=1)) == 2  # single-vertex poles


def test_catenoid_parameter_roots():
    c_small, c_large = catenoid_parameter_roots(1.0, 1.0)
    for c in (c_small, c_large):  # both solve c·cosh(d/(2c)) = R
        assert abs(c * math.cosh(0.5 / c) - 1.0) <= 1e-14
    assert c_small == pytest.approx(0.235095, abs=1e-6)
    assert c_large == pytest.approx(0.848338, abs=1e-6)
    assert catenoid_parameter(1.0, 1.0) == c_large  # the stable, larger root
    # scale invariance: c(λR, λd) = λ·c(R, d)
    assert catenoid_parameter(2.0, 2.0) == pytest.approx(2.0 * c_large, rel=1e-14)
    with pytest.raises(JaxgeoError):
        catenoid_parameter(1.0, 1.4)  # beyond d/R ≈ 1.3255 no catenoid exists


@pytest.mark.parametrize(
    "kwargs, n_faces",
    [
        ({}, 3888),
        (
            {"n_around": 16, "n_height": 5, "ring_radius": 2.0, "ring_distance": 1.5},
            160,
        ),
    ],
)
def test_catenoid(kwargs, n_faces):
    v, f = catenoid(**kwargs)
    tm = _check_mesh(v, f, n_faces=n_faces, euler=0, loops=2)
    big_r = kwargs.get("ring_radius", 1.0)
    d = kwargs.get("ring_distance", 1.0)
    c = catenoid_parameter(big_r, d)
    r = np.hypot(v[:, 0], v[:, 1])
    assert np.max(np.abs(r - c * np.cosh(v[:, 2] / c))) <= ON_SURFACE * big_r
    assert np.max(np.abs(v[:, 2])) == 0.5 * d
    ring = np.abs(v[:, 2]) == 0.5 * d
    assert np.max(np.abs(r[ring] - big_r)) <= ON_SURFACE * big_r
    # outward: the normal points away from the axis
    radial = tm.triangles_center[:, :2]
    assert np.all(np.einsum("ij,ij->i", tm.face_normals[:, :2], radial) > 0)


def test_cone_tent():
    kw = {"outer_radius": 1.2, "inner_radius": 0.2, "height": 0.7}
    v, f = cone_tent(n_around=40, n_radial=10, **kw)
    tm = _check_mesh(v, f, n_faces=800, euler=0, loops=2)
    r = np.hypot(v[:, 0], v[:, 1])
    z = 0.7 * np.log(1.2 / r) / math.log(1.2 / 0.2)
    assert np.max(np.abs(v[:, 2] - z)) <= ON_SURFACE
    assert np.isclose(r.min(), 0.2, rtol=1e-15) and np.isclose(r.max(), 1.2, rtol=1e-15)
    assert np.all(tm.face_normals[:, 2] > 0)
    _check_mesh(*cone_tent(), n_faces=2 * 64 * 24, euler=0, loops=2)


def test_twin_peak_tent():
    v, f = twin_peak_tent()
    tm = _check_mesh(v, f, n_faces=len(f), euler=-1, loops=3)  # disc with two holes
    assert np.max(np.abs(v[:, 2] - twin_peak_height(v[:, 0], v[:, 1]))) <= ON_SURFACE
    assert np.all(tm.face_normals[:, 2] > 0)
    # both inner rings are level at the peak height, the outer boundary is low
    for cx in (1.0, -1.0):
        ring = np.isclose(np.hypot(v[:, 0] - cx, v[:, 1]), 0.15, rtol=0, atol=1e-12)
        assert ring.sum() >= 16
        assert np.allclose(v[ring, 2], 0.6, rtol=0, atol=1e-12)
    outer = (np.abs(v[:, 0]) == 2.0) | (np.abs(v[:, 1]) == 1.0)
    assert v[outer, 2].max() < 0.3 * 0.6
    # not a surface of revolution: heights differ on a circle about the origin
    assert (
        np.ptp(twin_peak_height(0.5 * np.cos([0.0, 1.5]), 0.5 * np.sin([0.0, 1.5])))
        > 0.05
    )


def test_saddle():
    v, f = saddle(n=10, size=2.0, height=0.3)
    tm = _check_mesh(v, f, n_faces=200, euler=1, loops=1)
    z = 0.3 * (v[:, 0] ** 2 - v[:, 1] ** 2) / 4.0
    assert np.max(np.abs(v[:, 2] - z)) <= ON_SURFACE
    assert np.all(tm.face_normals[:, 2] > 0)
    _check_mesh(*saddle(), n_faces=2 * 32 * 32, euler=1, loops=1)
