"""Bad arguments, edge cases that must work, and statuses (issue 7, items 1–3).

Mesh-input errors are in `test_mesh.py`, loader fuzzing in `test_loaders.py`, the
basic endpoint errors (far point, components, shape, NaN, dtype, SurfacePoint) in
`test_locate.py`; this file covers the rest.

Almost every mesh here has the topology of `surfaces.saddle(6)` (a 7 × 7 vertex
grid over [-1, 1]², h = 1/3), with the vertices moved: flat, a saddle, needles, an
annulus sector. Same array shapes, so the solver compiles once for all of them;
the float32 and `max_points=4` tests each add one compile.

The fast set runs the argument checks (no compile) and the paths on the flat
grid with the default options (one compile); the rest is slow.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import surfaces
from jaxgeo.path import VERTEX

from .helpers import unit_icosphere

geodesic = pytest.importorskip("pygeodesic.geodesic")

N = 6  # grid cells per side


@functools.cache
def _grid():
    return surfaces.saddle(N)


def vid(i: int, j: int) -> int:
    """Vertex index of grid node (i, j): x = -1 + 2i/N, y = -1 + 2j/N."""
    return i * (N + 1) + j


def grid(height=None, squeeze: float = 1.0) -> jg.Mesh:
    """The grid with z = height(x, y) (0 if None) and x scaled by `squeeze`."""
    v, f = _grid()
    v = v.copy()
    v[:, 2] = 0.0 if height is None else height(v[:, 0], v[:, 1])
    v[:, 0] *= squeeze
    return jg.Mesh(v, f)


def sector(sweep: float, inner: float = 1.0, width: float = 0.5) -> jg.Mesh:
    """The grid bent, in the plane z = 0, into an annulus sector of angle `sweep`:
    node (i, j) at radius inner + width·i/N, angle sweep·j/N."""
    v, f = _grid()
    radius = inner + (v[:, 0] + 1) / 2 * width
    angle = (v[:, 1] + 1) / 2 * sweep
    return jg.Mesh(
        np.column_stack([radius * np.cos(angle), radius * np.sin(angle), 0 * angle]),
        f,
    )


FLAT = grid()
SADDLE = grid(lambda x, y: 0.5 * (x**2 - y**2))


def V(mesh: jg.Mesh) -> np.ndarray:
    return np.asarray(mesh.vertices)


def exact(mesh: jg.Mesh, i: int, j: int) -> float:
    """The exact polyhedral geodesic between vertices i and j (MMP, test-only)."""
    alg = geodesic.PyGeodesicAlgorithmExact(V(mesh), np.asarray(mesh.faces))
    return float(alg.geodesicDistance(i, j)[0])


def ok(path: jg.Path) -> jg.Path:
    assert int(path.status) == jg.Status.SUCCESS
    for leaf in (path.points, path.params, path.length):
        assert np.all(np.isfinite(np.asarray(leaf)))
    return path


# ---------------------------------------------------------- item 1: bad arguments

A, B = V(FLAT)[vid(1, 1)], V(FLAT)[vid(5, 4)]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(candidates="bogus"), "candidates must be one of"),
        (dict(max_points=1), "max_points must be at least 2"),
        (dict(max_points=-3), "max_points must be at least 2"),
        (dict(max_points=2.5), "max_points must be an integer"),
        (dict(max_points="10"), "max_points must be an integer"),
        (dict(max_points=True), "max_points must be an integer"),
        (dict(normals="bogus"), "normals must be one of"),
        (dict(max_distance=-1.0), "max_distance must be positive"),
        (dict(max_distance=0), "max_distance must be positive"),
        (dict(max_distance=float("nan")), "max_distance must be positive"),
        (dict(max_distance="x"), "max_distance must be a real number"),
        (dict(max_distance=np.array([1.0, 2.0])), "max_distance must be a real"),
        (dict(throw="no"), "throw must be True or False"),
        (dict(method=None), "unknown method"),
        (dict(method="LASER"), "unknown method"),
    ],
)
@pytest.mark.mistyped
def test_bad_options_raise(kwargs, message):
    with pytest.raises(jg.JaxgeoError, match=message):
        jg.shortest_path(FLAT, A, B, **kwargs)


@pytest.mark.slow  # compiles another max_points: ~12 s cold (README tests ≤ 5 min)
def test_numpy_integer_options_are_accepted():
    path = jg.shortest_path(FLAT, A, B, max_points=np.int64(1024))
    np.testing.assert_allclose(float(path.length), np.linalg.norm(B - A), rtol=1e-12)


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.array([True, False, True]), "dtype bool"),
        (np.array([1.0, 0.0, 0.0], complex), "dtype complex"),
        (None, "dtype object"),
        ("abc", "dtype <U3"),
        (1.0, r"shape \(3,\), or an integer vertex index, got shape \(\)"),
        (
            np.zeros((1, 3)),
            r"shape \(3,\), or an integer vertex index, got shape \(1, 3\)",
        ),
        (np.array([0.0, 0.0, np.inf]), "NaN or infinite"),
    ],
)
@pytest.mark.mistyped
def test_bad_endpoint_arrays_raise(bad, message):
    for args in ((bad, B), (A, bad)):
        with pytest.raises(jg.JaxgeoError, match=message):
            jg.shortest_path(FLAT, *args)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_endpoints_as_lists_and_integers_work():
    path = ok(jg.shortest_path(FLAT, list(A), tuple(B)))
    np.testing.assert_allclose(float(path.length), np.linalg.norm(B - A), rtol=1e-12)
    ok(jg.shortest_path(FLAT, np.array([0, 0, 0]), B))  # int dtype, on the mesh


@pytest.mark.mistyped
@pytest.mark.parametrize(
    "face, bary, message",
    [
        (2.0, np.ones(3) / 3, "face must be an integer scalar"),
        (np.array([1, 2]), np.ones(3) / 3, "face must be an integer scalar"),
        (-1, np.ones(3) / 3, "out of range"),
        (2, np.ones(2) / 2, "bary must be 3 finite numbers"),
        (2, np.array([np.nan, 0.5, 0.5]), "bary must be 3 finite numbers"),
        (2, np.array([-0.5, 0.5, 1.0]), "non-negative and sum to 1"),
    ],
)
def test_bad_surface_points_raise(face, bary, message):
    with pytest.raises(jg.JaxgeoError, match=message):
        jg.shortest_path(FLAT, jg.SurfacePoint(face, bary), B)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(chunk_size=0), "chunk_size must be at least 1"),
        (dict(chunk_size=2.5), "chunk_size must be an integer"),
        (dict(chunk_size="4"), "chunk_size must be an integer"),
        (dict(shard="yes"), "shard must be True or False"),
        (dict(progress=3), "progress must be callable"),
        (dict(candidates="bogus"), "candidates must be one of"),
        (dict(max_points=1), "max_points must be at least 2"),
        (dict(normals="bogus"), "normals must be one of"),
        (dict(max_distance="x"), "max_distance must be a real number"),
        (dict(throw=None), "throw must be True or False"),
    ],
)
@pytest.mark.mistyped
def test_bad_batch_options_raise(kwargs, message):
    with pytest.raises(jg.JaxgeoError, match=message):
        jg.shortest_paths(FLAT, V(FLAT)[:2], V(FLAT)[2:4], **kwargs)


@pytest.mark.parametrize(
    "p1, message",
    [
        (np.zeros(3), r"shape \(N, 3\), or vertex indices.*; got shape \(3,\)"),
        (np.zeros((1, 2, 3)), r"shape \(N, 3\), or vertex .*; got shape \(1, 2, 3\)"),
        (np.zeros((0, 3)), "empty batch"),
        (np.array([["a", "b", "c"]]), "dtype <U1"),
        (np.zeros((1, 3), complex), "dtype complex128"),
        (np.full((2, 3), np.inf), r"NaN or infinite coordinates in rows \[0 1\]"),
    ],
)
def test_bad_batch_arrays_raise(p1, message):
    p2 = np.zeros(np.shape(p1)) if np.ndim(p1) == 2 else np.zeros((1, 3))
    with pytest.raises(jg.JaxgeoError, match=message):
        jg.shortest_paths(FLAT, p1, p2)


@pytest.mark.mistyped
def test_with_vertices_bad_values_raise_at_use():
    """`Mesh.with_vertices` does not re-validate (it must take tracers); a concrete
    bad vertex array is caught when the mesh is used."""
    v = V(FLAT).copy()
    v[3] = np.nan
    jg.shortest_path(FLAT, A, B)  # (checked good and remembered: not the new array)
    with pytest.raises(jg.JaxgeoError, match=r"NaN or infinite .* vertices \[3\]"):
        jg.shortest_path(FLAT.with_vertices(jnp.asarray(v)), A, B)
    with pytest.raises(jg.JaxgeoError, match="float32 or float64"):
        jg.shortest_path(FLAT.with_vertices(jnp.asarray(v.astype(complex))), A, B)
    with pytest.raises(jg.JaxgeoError, match="float32 or float64"):
        jg.shortest_paths(FLAT.with_vertices(np.ones((49, 3), int)), A[None], B[None])
    with pytest.raises(jg.JaxgeoError, match="expected shape"):
        FLAT.with_vertices(V(FLAT).T)


@pytest.mark.slow
def test_nan_point_is_infinitely_far_under_jit():
    """Under jit the eager checks cannot run: `locate` must put a NaN point at an
    infinite distance (so `shortest_path` reports FAR_FROM_SURFACE), never at
    face 0 (`argmin` returns the first NaN)."""
    _, dist = jax.jit(jg.locate)(FLAT, jnp.array([np.nan, 0.0, 0.0]))
    assert float(dist) == np.inf
    v = V(FLAT).copy()
    v[vid(0, 0)] = np.nan  # a NaN vertex (traced meshes are not checked)
    sp, dist = jax.jit(jg.locate)(FLAT.with_vertices(jnp.asarray(v)), jnp.asarray(B))
    assert float(dist) < 1e-12 and vid(0, 0) not in np.asarray(FLAT.faces)[sp.face]


# ------------------------------------------------------- item 2: cases that work


@pytest.mark.parametrize(
    "where",
    ["face", "interior edge", "interior vertex", "boundary edge", "corner"],
)
@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_identical_endpoints_give_length_zero(where):
    v = V(FLAT)
    p = {
        "face": v[vid(2, 2)] * 0.2 + v[vid(3, 2)] * 0.3 + v[vid(3, 3)] * 0.5,
        "interior edge": 0.5 * (v[vid(2, 2)] + v[vid(2, 3)]),
        "interior vertex": v[vid(3, 3)],
        "boundary edge": 0.3 * v[vid(0, 2)] + 0.7 * v[vid(0, 3)],
        "corner": v[vid(0, 0)],
    }[where]
    path = ok(jg.shortest_path(FLAT, p, p))
    assert int(path.count) == 2 and float(path.length) == 0.0


@pytest.mark.slow  # a SurfacePoint endpoint: a solver compile of its own
def test_identical_surface_points_give_length_zero():
    sp = jg.SurfacePoint(jnp.asarray(5), jnp.array([0.0, 0.0, 1.0]))
    assert float(ok(jg.shortest_path(FLAT, sp, sp)).length) == 0.0


@pytest.mark.parametrize(
    "start, end",
    [
        ("vertex", "vertex"),
        ("vertex", "edge"),
        ("edge", "edge"),
        ("boundary vertex", "face"),
        ("boundary edge", "vertex"),
        ("boundary edge", "boundary edge"),
    ],
)
@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_endpoints_on_vertices_edges_and_boundary(start, end):
    """On the flat square (convex) the geodesic is the segment: the length is the
    chord to rounding whatever element the endpoints lie on."""
    v = V(FLAT)
    points = {
        "vertex": v[vid(2, 1)],
        "edge": 0.4 * v[vid(4, 4)] + 0.6 * v[vid(4, 5)],
        "boundary vertex": v[vid(0, 4)],
        "boundary edge": 0.25 * v[vid(6, 1)] + 0.75 * v[vid(6, 2)],
        "face": v[vid(1, 5)] * 0.5 + v[vid(2, 5)] * 0.3 + v[vid(2, 6)] * 0.2,
    }
    a = points[start]
    b = points[end] if end != start else v[vid(5, 6)] * 0.5 + v[vid(5, 5)] * 0.5
    path = ok(jg.shortest_path(FLAT, a, b))
    np.testing.assert_allclose(float(path.length), np.linalg.norm(b - a), rtol=1e-12)
    np.testing.assert_allclose(path.polyline()[[0, -1]], [a, b], atol=1e-14)


@pytest.mark.slow  # 16 s cold on 2 cores (README tests <= 5 min)
def test_path_along_a_straight_boundary():
    v = V(FLAT)
    path = ok(jg.shortest_path(FLAT, v[vid(0, 0)], v[vid(6, 0)]))
    assert float(path.length) == pytest.approx(2.0, rel=1e-12)
    np.testing.assert_allclose(path.polyline()[:, 1], -1.0, atol=1e-14)  # y = -1


@pytest.mark.slow
def test_path_through_vertices_on_a_symmetric_diagonal():
    """The diagonal of the grid runs exactly through vertices (and along the
    diagonal edges of half the cells): crossings at u = 0 or 1 snap to vertices."""
    v = V(FLAT)
    path = ok(jg.shortest_path(FLAT, v[vid(0, 0)], v[vid(6, 6)], method="laser"))
    assert float(path.length) == pytest.approx(2 * np.sqrt(2), rel=1e-12)
    kinds = np.asarray(path.kinds)[1 : int(path.count) - 1]
    assert np.all(kinds == VERTEX)
    # a chord through the central vertex from two points inside faces
    a, b = np.array([-0.9, -0.8, 0.0]), np.array([0.9, 0.8, 0.0])
    path = ok(jg.shortest_path(FLAT, a, b, method="laser"))
    assert float(path.length) == pytest.approx(np.linalg.norm(b - a), rel=1e-12)
    kinds = np.asarray(path.kinds)[: int(path.count)]
    elems = np.asarray(path.elements)[: int(path.count)]
    assert vid(3, 3) in elems[kinds == VERTEX]


@pytest.mark.slow
@pytest.mark.parametrize(
    "i, j",
    [(vid(0, 3), vid(6, 3)), (vid(3, 0), vid(3, 6)), (vid(1, 1), vid(5, 5))],
    ids=["convex way (x axis)", "concave way (y axis)", "diagonal"],
)
def test_saddle_where_zeta_changes_sign(i, j):
    """z = (x² − y²)/2: along x the chord runs below the surface, along y above
    it (ζ of System (16) has opposite signs); both must work."""
    path = ok(jg.shortest_path(SADDLE, V(SADDLE)[i], V(SADDLE)[j]))
    d = exact(SADDLE, i, j)
    assert d * (1 - 1e-9) <= float(path.length) <= d * (1 + 1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("squeeze", [1e-3, 1e-6])
def test_needle_triangles(squeeze):
    """x squeezed by 1e-6: every triangle is a needle of aspect ratio ~1e6 (the
    mesh accepts up to ~5e7). The flat domain is convex: length = chord."""
    mesh = grid(squeeze=squeeze)
    v = V(mesh)
    for a, b in [
        (v[vid(0, 0)], v[vid(6, 5)]),
        (0.3 * v[vid(0, 1)] + 0.7 * v[vid(1, 1)], v[vid(5, 6)]),
    ]:
        path = ok(jg.shortest_path(mesh, a, b))
        assert float(path.length) == pytest.approx(np.linalg.norm(b - a), rel=1e-9)


@pytest.mark.slow
def test_curved_needles():
    mesh = grid(lambda x, y: 0.3 * np.sin(3 * y), squeeze=1e-4)
    i, j = vid(0, 0), vid(6, 6)
    path = ok(jg.shortest_path(mesh, V(mesh)[i], V(mesh)[j]))
    d = exact(mesh, i, j)
    assert d * (1 - 1e-9) <= float(path.length) <= d * (1 + 1e-3)


@pytest.mark.slow
def test_path_around_the_inside_of_an_annulus_sector():
    """Half an annulus: the chord between the inner tips crosses the empty middle,
    so the trace slides along the inner boundary; that is the exact polyhedral
    geodesic (the inner polygon)."""
    mesh = sector(np.pi)
    v = V(mesh)
    path = ok(jg.shortest_path(mesh, v[vid(0, 0)], v[vid(0, N)]))
    inner = v[[vid(0, j) for j in range(N + 1)]]
    polygon = np.linalg.norm(np.diff(inner, axis=0), axis=1).sum()
    assert float(path.length) == pytest.approx(polygon, rel=1e-12)
    assert float(path.length) == pytest.approx(exact(mesh, vid(0, 0), vid(0, N)))


@functools.cache
def _tent():
    return jg.Mesh(*surfaces.cone_tent(n_around=12, n_radial=4))  # as test_properties


@pytest.mark.slow
@pytest.mark.parametrize("k", [3, 6])
def test_paths_across_the_hole_of_a_tent(k):
    """Cone tent: a membrane with a hole (its inner ring). Between inner-ring
    vertices the chord crosses the hole; the trace slides along the ring."""
    mesh = _tent()
    top = 4 * 12  # first vertex of the inner ring
    i, j = top, top + k
    path = ok(jg.shortest_path(mesh, V(mesh)[i], V(mesh)[j]))
    d = exact(mesh, i, j)
    assert d * (1 - 1e-9) <= float(path.length) <= d * 1.2
    pts = path.polyline()
    assert np.all(np.hypot(pts[:, 0], pts[:, 1]) >= 0.15 * (1 - 1e-12))  # not inside


@pytest.mark.slow
def test_float32_matches_float64():
    """float32 meshes work; lengths agree with float64 to the accuracy documented
    in docs/accuracy.md (here ~1e-7 relative, bound 1e-5)."""
    v = V(SADDLE)
    m32 = jg.Mesh(v.astype(np.float32), np.asarray(SADDLE.faces))
    for i, j in [
        (vid(0, 3), vid(6, 3)),
        (vid(1, 1), vid(5, 5)),
        (vid(0, 1), vid(6, 5)),
    ]:
        p32 = ok(
            jg.shortest_path(m32, v[i].astype(np.float32), v[j].astype(np.float32))
        )
        p64 = ok(jg.shortest_path(SADDLE, v[i], v[j]))
        assert p32.points.dtype == jnp.float32
        assert int(p32.count) == int(p64.count)
        np.testing.assert_allclose(float(p32.length), float(p64.length), rtol=1e-5)


@pytest.mark.slow
def test_identical_endpoints_on_a_closed_mesh():
    mesh = unit_icosphere(2)  # shares its compile with test_locate
    p = np.asarray(mesh.vertices)[17]
    path = ok(jg.shortest_path(mesh, p, p))
    assert float(path.length) == 0.0


# ---------------------------------------------------------- item 3: statuses


@pytest.mark.slow
def test_out_of_steps_is_a_status_and_raises():
    v = V(SADDLE)
    with pytest.raises(jg.JaxgeoError, match="out of steps"):
        jg.shortest_path(
            SADDLE, v[vid(0, 0)], v[vid(6, 6)], max_points=4, method="laser"
        )
    path = jg.shortest_path(
        SADDLE, v[vid(0, 0)], v[vid(6, 6)], max_points=4, throw=False, method="laser"
    )
    assert int(path.status) == jg.Status.MAX_STEPS
    assert int(path.count) <= 4 and not bool(path.ok)
    assert np.all(np.isfinite(np.asarray(path.points)))
    # the partial polyline does not end at point 2
    assert np.linalg.norm(path.polyline()[-1] - v[vid(6, 6)]) > 0.5


@pytest.mark.slow
def test_no_crossing_is_a_status_and_raises():
    """Three quarters of an annulus: from an inner tip the chord to the other tip
    leaves the mesh, and neither boundary edge at the tip points ahead (the
    geodesic would first go away from point 2): NO_CROSSING, never a partial path
    passed off as complete."""
    mesh = sector(1.5 * np.pi)
    v = V(mesh)
    a, b = v[vid(0, 0)], v[vid(0, N)]
    with pytest.raises(jg.JaxgeoError, match="no crossing ahead"):
        jg.shortest_path(mesh, a, b, method="laser")
    path = jg.shortest_path(mesh, a, b, throw=False, method="laser")
    assert int(path.status) == jg.Status.NO_CROSSING
    assert np.all(np.isfinite(np.asarray(path.points)))


def test_every_status_has_a_message():
    for status in jg.Status:
        assert status.message and isinstance(status.message, str)
