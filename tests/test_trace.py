"""The sliding laser ray (`method="laser"`, named in every call: the default is
"exact") on the unit sphere: the paper's accuracy claim, path invariants, local vs
all candidates, far-side crossings, the exact polyhedral geodesic."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo.path import EDGE, VERTEX

from .helpers import face_points, great_circle, position, unit_icosphere

MESH = unit_icosphere(4)  # 5,120 faces


@functools.cache
def sphere_pairs():
    """12 pairs of points inside faces (not vertices), 10° to 160° apart."""
    faces, bary = face_points(MESH, 400, seed=7)
    pts = np.array([position(MESH, f, b) for f, b in zip(faces, bary)])
    pairs = []
    rng = np.random.default_rng(1)
    targets = np.linspace(10, 160, 12)
    for target in targets:
        i = rng.integers(len(pts))
        ang = np.degrees([great_circle(pts[i], q) for q in pts])
        j = int(np.argmin(np.abs(ang - target)))
        pairs.append((pts[i], pts[j]))
    return pairs


@functools.cache
def traced(candidates):
    return [
        jg.shortest_path(MESH, a, b, method="laser", candidates=candidates)
        for a, b in sphere_pairs()
    ]


@pytest.mark.slow
def test_pairs_span_10_to_160_degrees():
    ang = [np.degrees(great_circle(a, b)) for a, b in sphere_pairs()]
    assert min(ang) < 15 and max(ang) > 155 and all(5 < x < 165 for x in ang)


@pytest.mark.slow
def test_length_within_half_percent_of_great_circle():
    """The paper's claim (section 6): residual ≤ 0.5 %."""
    for (a, b), path in zip(sphere_pairs(), traced("local")):
        assert int(path.status) == jg.Status.SUCCESS
        gc = great_circle(a, b)
        assert abs(float(path.length) - gc) <= 5e-3 * gc


def _assert_on_edges_and_connected(path, mesh=MESH):
    v = np.asarray(mesh.vertices)
    edges = np.asarray(mesh.edges)
    edge_faces = np.asarray(mesh.edge_faces)
    vertex_faces = np.asarray(mesh.vertex_faces)
    n = int(path.count)
    pts = np.asarray(path.points)[:n]
    kinds = np.asarray(path.kinds)[:n]
    elems = np.asarray(path.elements)[:n]
    params = np.asarray(path.params)[:n]
    faces_of = []
    for p, k, el, u in zip(pts, kinds, elems, params):
        if k == EDGE:
            q = (1 - u) * v[edges[el, 0]] + u * v[edges[el, 1]]
            assert np.linalg.norm(p - q) <= 1e-9  # on its edge
            assert 0 <= u <= 1
            faces_of.append(set(edge_faces[el]) - {-1})
        elif k == VERTEX:
            assert np.linalg.norm(p - v[el]) <= 1e-12
            faces_of.append(set(vertex_faces[el]) - {-1})
        else:
            faces_of.append({int(el)})
    for f, g in zip(faces_of[:-1], faces_of[1:]):
        assert f & g, "consecutive points must share a face"


@pytest.mark.slow
def test_points_lie_on_their_edges_and_consecutive_points_share_a_face():
    for path in traced("local"):
        _assert_on_edges_and_connected(path)


@pytest.mark.slow
def test_all_and_local_candidates_give_the_same_path():
    for local, full in zip(traced("local"), traced("all")):
        assert int(full.status) == jg.Status.SUCCESS
        assert int(local.count) == int(full.count)
        n = int(local.count)
        assert np.array_equal(
            np.asarray(local.elements)[:n], np.asarray(full.elements)[:n]
        )
        np.testing.assert_allclose(local.points[:n], full.points[:n], atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("candidates", ["local", "all"])
def test_near_antipodal_pair_never_takes_a_far_side_crossing(candidates):
    faces, bary = face_points(MESH, 1, seed=3)
    a = position(MESH, faces[0], bary[0])
    # Rotate a by 176° about an axis perpendicular to it.
    axis = np.cross(a, [0.3, 0.5, 0.8])
    axis /= np.linalg.norm(axis)
    th = np.radians(176.0)
    b = (
        a * np.cos(th)
        + np.cross(axis, a) * np.sin(th)
        + axis * (axis @ a) * (1 - np.cos(th))
    )
    path = jg.shortest_path(MESH, a, b, method="laser", candidates=candidates)
    assert int(path.status) == jg.Status.SUCCESS
    pts = path.polyline()
    # Every step is a short hop within the faces around the current point (no
    # jump through the sphere) and the polyline advances monotonically in angle.
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert steps.max() < 3 * float(MESH.mean_edge_length)
    ang = np.array([great_circle(a, p) for p in pts])
    assert np.all(np.diff(ang) > -1e-9)
    assert abs(float(path.length) - great_circle(a, b)) <= 5e-3 * great_circle(a, b)
    _assert_on_edges_and_connected(path)


@pytest.mark.slow
def test_matches_exact_polyhedral_geodesic_between_vertices():
    """Between two mesh vertices the laser ray's length is within 1e-4 of the exact
    polyhedral geodesic (MMP, pygeodesic; used only in tests)."""
    geodesic = pytest.importorskip("pygeodesic.geodesic")
    v = np.asarray(MESH.vertices)
    f = np.asarray(MESH.faces)
    exact = geodesic.PyGeodesicAlgorithmExact(v, f)
    rng = np.random.default_rng(5)
    checked = 0
    while checked < 10:
        i, j = rng.integers(len(v), size=2)
        ang = np.degrees(great_circle(v[i], v[j]))
        if not 10 <= ang <= 160:
            continue
        d, _ = exact.geodesicDistance(int(i), int(j))
        path = jg.shortest_path(MESH, v[i], v[j], method="laser")
        assert int(path.status) == jg.Status.SUCCESS
        assert float(path.length) >= d * (1 - 1e-9)  # never below the exact one
        assert abs(float(path.length) - d) <= 1e-4 * d
        checked += 1


@pytest.mark.slow
def test_vmap_over_endpoint_batches_matches_single_calls():
    pairs = sphere_pairs()[:4]
    p1 = jnp.asarray(np.array([a for a, _ in pairs]))
    p2 = jnp.asarray(np.array([b for _, b in pairs]))
    paths = jax.vmap(lambda a, b: jg.shortest_path(MESH, a, b, method="laser"))(p1, p2)
    single = [float(p.length) for p in traced("local")[:4]]
    np.testing.assert_allclose(paths.length, single, rtol=1e-12)
    # the endpoints have the batch axis, and are where each row starts and ends
    assert paths.start is not None and paths.end is not None
    assert paths.start.bary.shape == (4, 3) and paths.end.face.shape == (4,)
    last = paths.points[np.arange(4), paths.count - 1]
    np.testing.assert_allclose(
        paths.start.position(MESH), paths.points[:, 0], atol=1e-12
    )
    np.testing.assert_allclose(paths.end.position(MESH), last, atol=1e-12)


@pytest.mark.slow
def test_same_face_and_identical_points():
    faces, bary = face_points(MESH, 1, seed=11)
    a = position(MESH, faces[0], bary[0])
    b = position(MESH, faces[0], np.array([0.2, 0.3, 0.5]))
    p = jg.shortest_path(MESH, a, b, method="laser")
    assert int(p.count) == 2
    np.testing.assert_allclose(float(p.length), np.linalg.norm(a - b), rtol=1e-12)
    p0 = jg.shortest_path(MESH, a, a, method="laser")
    assert float(p0.length) == 0.0
    g = jax.grad(lambda x: jg.path_length(MESH, x, jnp.asarray(a), method="laser"))(
        jnp.asarray(a)
    )
    assert np.all(np.isfinite(np.asarray(g)))


def test_one_laser_trace_on_the_builtin_catenoid():
    """The fast set's part: one laser trace with the default options on the
    built-in catenoid (the solver tests/test_cli.py's `jaxgeo path` compiles):
    its points on their edges, consecutive points sharing a face, the length the
    polyline's, never below the exact polyhedral geodesic. (No upper bound: the
    laser is not a shortest-path method; it tends to the steepest-descent curve
    of the distance to the end point, 11 % longer than the geodesic on this pair
    across the neck; tests/test_validation.py measures that curve.)"""
    from jaxgeo import surfaces

    mesh = jg.Mesh(*surfaces.catenoid())
    # points inside faces (a vertex endpoint may leave through any face of its
    # ring, which the face check below would not allow), across the neck
    faces, bary = face_points(mesh, 400, seed=2)
    pts = np.array([position(mesh, f, b) for f, b in zip(faces, bary)])
    a, b = pts[np.argmin(pts[:, 2])], pts[np.argmax(pts[:, 2])]
    path = jg.shortest_path(mesh, a, b, method="laser")
    assert int(path.status) == jg.Status.SUCCESS
    _assert_on_edges_and_connected(path, mesh)
    line = path.polyline()
    np.testing.assert_allclose(line[[0, -1]], [a, b], atol=1e-12)
    # the endpoints as located: the faces and coordinates they were made from
    assert path.start is not None and path.end is not None
    i, j = np.argmin(pts[:, 2]), np.argmax(pts[:, 2])
    assert [int(path.start.face), int(path.end.face)] == [faces[i], faces[j]]
    np.testing.assert_allclose(path.start.bary, bary[i], atol=1e-9)
    np.testing.assert_allclose(path.end.bary, bary[j], atol=1e-9)
    ends = [path.start.position(mesh), path.end.position(mesh)]
    np.testing.assert_allclose(ends, line[[0, -1]], atol=1e-12)
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1).sum()
    assert abs(seg - float(path.length)) <= 1e-12 * seg
    exact = float(jg.shortest_path(mesh, a, b).length)
    assert float(path.length) >= exact * (1 - 1e-9)
