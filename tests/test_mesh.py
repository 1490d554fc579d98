"""Mesh construction: every bad input raises `JaxgeoError` naming the problem, the
connectivity satisfies its invariants, and the pytree works under jit and grad."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import trimesh

from jaxgeo._errors import JaxgeoError
from jaxgeo.mesh import DEGENERATE_AREA_RATIO, Mesh

# --------------------------------------------------------------------------- helpers

TRIANGLE_V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
TRIANGLE_F = np.array([[0, 1, 2]])


def icosphere(subdivisions: int = 2, radius: float = 1.0):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(s.vertices), np.asarray(s.faces)


def grid(nx: int, ny: int):
    """An open, flat nx × ny grid of unit squares, each split into two triangles."""
    xs, ys = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0), indexing="ij")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return v, f


def moebius(n: int = 12, radius: float = 2.0, width: float = 0.5):
    """A Möbius strip: a ring of n quads whose last one joins the first with a
    half twist, so that its two rows of vertices swap."""
    theta = 2 * np.pi * np.arange(n) / n
    centre = radius * np.stack([np.cos(theta), np.sin(theta), 0 * theta], 1)
    across = np.stack(
        [
            np.cos(theta / 2) * np.cos(theta),
            np.cos(theta / 2) * np.sin(theta),
            np.sin(theta / 2),
        ],
        1,
    )
    v = np.concatenate([centre - width * across, centre + width * across])

    def idx(i, side):  # side 0 = lower row, 1 = upper row; row n is row 0 flipped
        return (1 - side) * n if i == n else side * n + i

    faces = []
    for i in range(n):
        a, b, c, d = idx(i, 0), idx(i, 1), idx(i + 1, 0), idx(i + 1, 1)
        if i == n - 1:  # the twist: row n's lower vertex is row 0's upper one
            c, d = idx(0, 1), idx(0, 0)
        faces += [[a, c, b], [b, c, d]]
    return v, np.array(faces)


def directed_half_edges(faces):
    f = np.asarray(faces)
    return f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)


def assert_consistently_oriented(faces):
    """Every directed edge occurs once: an interior edge is run through in opposite
    directions by its two faces."""
    half = directed_half_edges(faces)
    assert np.unique(half, axis=0).shape[0] == half.shape[0]


# ------------------------------------------------------------- bad input, one each


def test_vertices_wrong_shape():
    with pytest.raises(JaxgeoError, match=r"vertices must have shape \(V, 3\)"):
        Mesh(TRIANGLE_V[:, :2], TRIANGLE_F)


def test_vertices_wrong_ndim():
    with pytest.raises(JaxgeoError, match=r"vertices must have shape \(V, 3\)"):
        Mesh(TRIANGLE_V.ravel(), TRIANGLE_F)


def test_faces_wrong_shape():
    with pytest.raises(JaxgeoError, match=r"faces must have shape \(F, 3\)"):
        Mesh(np.concatenate([TRIANGLE_V, [[1.0, 1.0, 0.0]]]), [[0, 1, 2, 3]])


def test_vertices_non_numeric_dtype():
    with pytest.raises(JaxgeoError, match="vertices must be a real array.*<U"):
        Mesh(TRIANGLE_V.astype(str), TRIANGLE_F)


def test_vertices_object_dtype():
    with pytest.raises(JaxgeoError, match="vertices must be a real array.*object"):
        Mesh(TRIANGLE_V.astype(object), TRIANGLE_F)


def test_vertices_complex_dtype():
    with pytest.raises(JaxgeoError, match="vertices must be a real array.*complex"):
        Mesh(TRIANGLE_V.astype(complex), TRIANGLE_F)


def test_vertices_bool_dtype():
    with pytest.raises(JaxgeoError, match="vertices must be a real array.*bool"):
        Mesh(TRIANGLE_V.astype(bool), TRIANGLE_F)


def test_faces_float_indices():
    with pytest.raises(JaxgeoError, match="faces must be an integer array.*float64"):
        Mesh(TRIANGLE_V, TRIANGLE_F.astype(float))


def test_faces_bool_indices():
    with pytest.raises(JaxgeoError, match="faces must be an integer array.*bool"):
        Mesh(TRIANGLE_V, np.ones((1, 3), dtype=bool))


def test_ragged_input():
    with pytest.raises(JaxgeoError, match="vertices could not be converted"):
        Mesh([[0.0, 0.0, 0.0], [1.0, 0.0]], TRIANGLE_F)


def test_empty_mesh_no_vertices():
    with pytest.raises(JaxgeoError, match="empty mesh"):
        Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int))


def test_empty_mesh_no_faces():
    with pytest.raises(JaxgeoError, match="empty mesh"):
        Mesh(TRIANGLE_V, np.zeros((0, 3), dtype=int))


def test_empty_mesh_plain_lists():
    with pytest.raises(JaxgeoError, match="empty mesh"):
        Mesh(TRIANGLE_V, [])


def test_nan_coordinates():
    v = TRIANGLE_V.copy()
    v[1, 2] = np.nan
    with pytest.raises(JaxgeoError, match="NaN at vertices: 1$"):
        Mesh(v, TRIANGLE_F)


def test_inf_coordinates():
    v = TRIANGLE_V.copy()
    v[2, 0] = -np.inf
    with pytest.raises(JaxgeoError, match="infinite at vertices: 2$"):
        Mesh(v, TRIANGLE_F)


def test_coordinates_too_large():
    with pytest.raises(JaxgeoError, match="too large for float64"):
        Mesh(TRIANGLE_V * 1e300, TRIANGLE_F)


def test_negative_face_index():
    with pytest.raises(JaxgeoError, match=r"out of range \[0, 3\) in faces: 0$"):
        Mesh(TRIANGLE_V, [[0, -1, 2]])


def test_too_large_face_index():
    v, f = grid(2, 1)
    f = f.copy()
    f[3, 1] = len(v)
    with pytest.raises(JaxgeoError, match=rf"out of range \[0, {len(v)}\) .*: 3$"):
        Mesh(v, f)


def test_zero_area_face():
    v = np.concatenate([TRIANGLE_V, [[2.0, 0.0, 0.0]]])  # 0, 1, 3 collinear
    with pytest.raises(JaxgeoError, match="zero area.*collinear.*: 1$"):
        Mesh(v, [[0, 1, 2], [0, 1, 3]])


def test_repeated_vertex_in_face():
    with pytest.raises(JaxgeoError, match="vertex repeated within the face.*: 0$"):
        Mesh(TRIANGLE_V, [[0, 1, 1]])


def test_needle_face():
    # height / longest edge = 1e-9: area / longest² = 5e-10, below the threshold
    # but far above rounding, so it is a needle and not a zero-area face.
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1e-9, 0.0]])
    assert 0.5 * 1e-9 < DEGENERATE_AREA_RATIO
    with pytest.raises(JaxgeoError, match="needle faces.*: 0$"):
        Mesh(v, TRIANGLE_F)


def test_thin_but_acceptable_face():
    # aspect ratio 1e6 is thin but well inside float64's range: accepted
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 1e-6, 0.0]])
    assert Mesh(v, TRIANGLE_F).n_faces == 1


def test_duplicate_faces():
    v, f = grid(2, 2)
    f = np.concatenate([f, f[[2]][:, ::-1]])  # same vertices, other orientation
    with pytest.raises(JaxgeoError, match=rf"duplicate faces.*: 2, {len(f) - 1}$"):
        Mesh(v, f)


def test_non_manifold_edge():
    # three triangles on the edge (0, 1)
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]], dtype=float
    )
    with pytest.raises(JaxgeoError, match=r"non-manifold edges.*: \(0, 1\)$"):
        Mesh(v, [[0, 1, 2], [1, 0, 3], [0, 1, 4]])


def test_non_manifold_vertex_bowtie():
    # two triangles touching only at vertex 0
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0]], dtype=float
    )
    with pytest.raises(JaxgeoError, match="non-manifold vertices.*: 0$"):
        Mesh(v, [[0, 1, 2], [0, 3, 4]])


def test_non_orientable_moebius():
    v, f = moebius()
    # it is a valid manifold strip otherwise: every edge has one or two faces
    with pytest.raises(JaxgeoError, match="not orientable.*Möbius"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # and no warning before the error
            Mesh(v, f)


def test_with_vertices_wrong_shape():
    mesh = Mesh(TRIANGLE_V, TRIANGLE_F)
    with pytest.raises(JaxgeoError, match=r"with_vertices: expected shape \(3, 3\)"):
        mesh.with_vertices(jnp.zeros((4, 3)))


def test_traced_input_is_refused():
    with pytest.raises(JaxgeoError, match="outside jax.jit"):
        jax.jit(lambda v: Mesh(v, TRIANGLE_F).vertices)(TRIANGLE_V)


# ----------------------------------------------------------------- orientation fix


@pytest.mark.parametrize("fraction", [0.1, 0.7])
def test_inconsistent_orientation_is_fixed(fraction):
    v, f = icosphere(2)
    rng = np.random.default_rng(0)
    flipped = rng.random(len(f)) < fraction
    bad = np.where(flipped[:, None], f[:, ::-1], f)
    with pytest.warns(UserWarning, match="inconsistently oriented.*reoriented"):
        mesh = Mesh(v, bad)
    out = np.asarray(mesh.faces)
    assert_consistently_oriented(out)
    # the majority's faces are kept as they are; the others are only reversed
    majority = flipped == (flipped.mean() > 0.5)
    assert np.array_equal(out[majority], bad[majority])
    assert np.array_equal(out, f if flipped.mean() < 0.5 else f[:, ::-1])


def test_orientation_majority_is_per_component():
    v, f = icosphere(1)
    rng = np.random.default_rng(5)
    first = rng.random(len(f)) < 0.2  # mostly as given
    second = rng.random(len(f)) < 0.8  # mostly reversed
    bad = np.concatenate(
        [
            np.where(first[:, None], f[:, ::-1], f),
            np.where(second[:, None], f[:, ::-1], f) + len(v),
        ]
    )
    with pytest.warns(UserWarning, match=f"{first.sum() + (~second).sum()} faces"):
        mesh = Mesh(np.concatenate([v, v + [3.0, 0.0, 0.0]]), bad)
    out = np.asarray(mesh.faces)
    assert np.array_equal(out[: len(f)], f)
    assert np.array_equal(out[len(f) :], f[:, ::-1] + len(v))


def test_orientation_warning_points_at_caller():
    v, f = grid(2, 2)
    f = f.copy()
    f[0] = f[0, ::-1]
    with pytest.warns(UserWarning, match="1 faces") as record:
        Mesh(v, f)
    assert record[0].filename == __file__


def test_consistent_mesh_gives_no_warning():
    v, f = icosphere(1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh = Mesh(v, f)
    assert np.array_equal(np.asarray(mesh.faces), f)


# ------------------------------------------------------------------ invariants


def check_connectivity(mesh: Mesh):
    faces = np.asarray(mesh.faces)
    edges = np.asarray(mesh.edges)
    edge_faces = np.asarray(mesh.edge_faces)
    face_edges = np.asarray(mesh.face_edges)
    vertex_faces = np.asarray(mesh.vertex_faces)
    # unique, sorted edges
    assert (edges[:, 0] < edges[:, 1]).all()
    assert np.unique(edges, axis=0).shape == edges.shape
    # face_edges[f, i] is the edge opposite corner i
    for fi, face in enumerate(faces):
        for i in range(3):
            e = face_edges[fi, i]
            assert set(edges[e]) == {face[(i + 1) % 3], face[(i + 2) % 3]}
            assert fi in edge_faces[e]
    # edge_faces lists exactly the faces holding the edge
    for e, (a, b) in enumerate(edges):
        holding = np.flatnonzero(((faces == a) | (faces == b)).sum(1) == 2)
        listed = edge_faces[e][edge_faces[e] >= 0]
        assert sorted(listed) == sorted(holding)
        assert edge_faces[e, 0] >= 0  # a boundary edge keeps its face in slot 0
    # vertex_faces lists exactly the faces containing the vertex
    for vi in range(mesh.n_vertices):
        listed = vertex_faces[vi][vertex_faces[vi] >= 0]
        assert sorted(listed) == sorted(np.flatnonzero((faces == vi).any(1)))


def test_icosphere_topology():
    v, f = icosphere(2)
    mesh = Mesh(v, f)
    assert mesh.n_vertices - mesh.n_edges + mesh.n_faces == 2
    assert (np.asarray(mesh.edge_faces) >= 0).all()  # closed: two faces per edge
    assert mesh.boundary_edges.size == 0
    assert 2 * mesh.n_edges == 3 * mesh.n_faces
    check_connectivity(mesh)
    assert (np.asarray(mesh.face_component) == 0).all()
    lengths = np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1)
    assert lengths.min() <= float(mesh.mean_edge_length) <= lengths.max()


def test_open_grid_boundary():
    nx, ny = 4, 3
    v, f = grid(nx, ny)
    mesh = Mesh(v, f)
    edge_faces = np.asarray(mesh.edge_faces)
    boundary = edge_faces[:, 1] == -1
    assert boundary.sum() == 2 * (nx + ny)
    assert mesh.boundary_edges.size == 2 * (nx + ny)
    # boundary edges are exactly those on the grid's rim
    e = np.asarray(mesh.edges)
    p, q = v[e[:, 0]], v[e[:, 1]]
    on_rim = np.zeros(len(e), bool)
    for axis, top in ((0, nx), (1, ny)):
        for side in (0, top):
            on_rim |= (p[:, axis] == side) & (q[:, axis] == side)
    assert np.array_equal(boundary, on_rim)
    assert mesh.n_vertices - mesh.n_edges + mesh.n_faces == 1
    check_connectivity(mesh)


def holed_grid():
    """`grid(4, 3)` without the two faces of square (1, 1) and with an unused
    vertex: an outer boundary loop and a hole."""
    v, f = grid(4, 3)
    f = np.delete(f, [4, 4 + 12], axis=0)
    return np.concatenate([v, [[9.0, 9.0, 9.0]]]), f


@pytest.mark.parametrize(
    "make", [lambda: grid(4, 3), holed_grid, lambda: icosphere(1)], ids=str
)
def test_boundary_next_runs_along_the_boundary_edges_faces(make):
    """`boundary_next[a] = b` exactly for the boundary edges a → b as their face
    runs through them; −1 for interior and unused vertices."""
    v, f = make()
    mesh = Mesh(v, f)
    edges = np.asarray(mesh.edges)[np.asarray(mesh.edge_faces)[:, 1] < 0]
    boundary = {tuple(e) for e in edges.tolist()}
    expect = np.full(mesh.n_vertices, -1)
    for a, b in directed_half_edges(np.asarray(mesh.faces)).tolist():
        if (min(a, b), max(a, b)) in boundary:
            assert expect[a] == -1  # one boundary edge leaves each vertex
            expect[a] = b
    assert (expect >= 0).sum() == len(boundary)
    np.testing.assert_array_equal(np.asarray(mesh.boundary_next), expect)
    on_edge = np.isin(np.arange(mesh.n_vertices), edges)
    np.testing.assert_array_equal(np.asarray(mesh.is_boundary_vertex), on_edge)
    inside = jax.jit(lambda m: m.is_boundary_vertex)(mesh)
    np.testing.assert_array_equal(np.asarray(inside), on_edge)


def test_two_disjoint_spheres_two_components():
    v, f = icosphere(1)
    mesh = Mesh(
        np.concatenate([v, v + [3.0, 0.0, 0.0]]), np.concatenate([f, f + len(v)])
    )
    comp = np.asarray(mesh.face_component)
    assert np.unique(comp).size == 2
    assert np.unique(comp[: len(f)]).size == 1
    assert np.unique(comp[len(f) :]).size == 1
    assert comp[0] != comp[-1]


def test_unreferenced_vertex_is_allowed():
    v = np.concatenate([TRIANGLE_V, [[5.0, 5.0, 5.0]]])
    mesh = Mesh(v, TRIANGLE_F)
    assert (np.asarray(mesh.vertex_faces)[3] == -1).all()


# --------------------------------------------------------------- dtypes, pytree


def test_float32_stays_float32():
    assert jax.config.jax_enable_x64
    v, f = icosphere(1)
    mesh = Mesh(v.astype(np.float32), f)
    assert mesh.vertices.dtype == jnp.float32
    assert mesh.mean_edge_length.dtype == jnp.float32


def test_float64_stays_float64():
    v, f = icosphere(1)
    assert Mesh(v, f).vertices.dtype == jnp.float64


def test_integer_vertices_become_float():
    v, f = grid(2, 2)
    mesh = Mesh(v.astype(np.int32), f.astype(np.uint16))
    assert jnp.issubdtype(mesh.vertices.dtype, jnp.floating)
    assert np.array_equal(np.asarray(mesh.vertices), v)
    assert mesh.faces.dtype == jnp.int32


def test_jax_array_input():
    v, f = icosphere(1)
    mesh = Mesh(jnp.asarray(v), jnp.asarray(f))
    assert mesh.n_faces == len(f)


def total_edge_length(mesh: Mesh):
    e = mesh.edges
    return jnp.sum(
        jnp.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    )


def test_with_vertices_under_jit_and_grad():
    v, f = icosphere(1)
    mesh = Mesh(v, f)

    @jax.jit
    def loss(verts):
        return total_edge_length(mesh.with_vertices(verts))

    scaled = jnp.asarray(v) * 2.0
    assert jnp.allclose(loss(scaled), 2 * total_edge_length(mesh))
    g = jax.grad(loss)(jnp.asarray(v))
    # d/dv Σ |v_i − v_j| = Σ over edges at v of the unit vector away from the other
    # end; on the icosphere it points outwards along the radius.
    e = np.asarray(mesh.edges)
    expected = np.zeros_like(v)
    d = v[e[:, 0]] - v[e[:, 1]]
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    np.add.at(expected, e[:, 0], u)
    np.add.at(expected, e[:, 1], -u)
    np.testing.assert_allclose(np.asarray(g), expected, atol=1e-12)
    radial = np.sum(np.asarray(g) * v, axis=1) / np.linalg.norm(np.asarray(g), axis=1)
    assert (radial > 0.99).all()


def test_mesh_passes_through_jit_as_argument():
    v, f = icosphere(1)
    mesh = Mesh(v, f)
    out = jax.jit(total_edge_length)(mesh)
    assert jnp.isclose(out, total_edge_length(mesh))


def test_trimesh_round_trip():
    v, f = icosphere(1)
    mesh = Mesh.from_trimesh(trimesh.Trimesh(v, f, process=False))
    tm = mesh.to_trimesh()
    assert np.array_equal(tm.faces, f)
    assert np.array_equal(tm.vertices, v)
    assert tm.is_watertight and tm.is_winding_consistent
