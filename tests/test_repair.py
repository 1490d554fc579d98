"""`repair_mesh` and `load_mesh(repair=...)`: each problem `Mesh` refuses and
repair fixes is fixed, counted and warned about; a valid mesh is left as it is;
every refusal of such a problem points to repair; real meshes shipped inside
packages are refused as they come from `trimesh.load` and usable once repaired."""

import re
import warnings

import numpy as np
import pytest
import trimesh

import jaxgeo as jg
from jaxgeo._errors import JaxgeoError
from jaxgeo.mesh import Mesh

from .helpers import package_mesh


def grid(n: int = 3):
    """A flat n × n grid of unit squares, two triangles each."""
    xs, ys = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate(
        [
            np.stack([a.ravel(), b.ravel(), c.ravel()], 1),
            np.stack([a.ravel(), c.ravel(), d.ravel()], 1),
        ]
    )
    return v, f


def tetrahedron(offset=(0.0, 0.0, 0.0)):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) + offset
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return v, f


def max_faces_per_edge(f) -> int:
    half = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    return int(np.unique(half, axis=0, return_counts=True)[1].max())


def repaired(v, f, **kwargs):
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        out = jg.repair_mesh(v, f, **kwargs)
    return (*out, [str(w.message) for w in record])


# --------------------------------------------------------------------- synthetic


def test_valid_mesh_is_left_as_it_is():
    tm = trimesh.creation.icosphere(1)
    v, f, report, messages = repaired(tm.vertices, tm.faces)
    assert not report.changed and str(report) == "nothing to repair"
    assert np.array_equal(v, tm.vertices) and np.array_equal(f, tm.faces)
    assert np.array_equal(report.faces, np.arange(len(tm.faces)))
    assert messages == []


def test_degenerate_and_duplicate_faces_are_removed():
    v, f = grid(3)
    v = np.concatenate([v, [[1.5, 0.0, 0.0]]])  # on the edge (1, 0)–(2, 0)
    n = len(v) - 1
    bad = np.array(
        [
            [0, 0, 1],  # a repeated vertex
            [4, 8, n],  # zero area: (1,0), (2,0) and (1.5,0) are collinear
            f[5],  # the same face again
            f[7][::-1],  # the same face, reversed
        ]
    )
    v2, f2, report, messages = repaired(v, np.concatenate([f, bad]))
    assert (report.degenerate_faces, report.duplicate_faces) == (2, 2)
    assert (report.nonmanifold_faces, report.split_vertices) == (0, 0)
    assert np.array_equal(f2, f) and np.array_equal(report.faces, np.arange(len(f)))
    assert np.array_equal(v2, v)  # vertex indices stay valid
    assert messages == [
        "repair_mesh: 2 degenerate faces removed; 2 duplicate faces removed"
    ]
    Mesh(v2, f2)


def test_needle_face_is_removed():
    v, f = grid(2)
    # a needle on the boundary edge (0,0)–(1,0): height 1e-9 over length 1
    v = np.concatenate([v, [[0.5, -1e-9, 0.0]]])
    needle = np.array([[0, len(v) - 1, 3]])
    with pytest.raises(JaxgeoError, match="needle faces"):
        Mesh(v, np.concatenate([f, needle]))
    _, f2, report, _ = repaired(v, np.concatenate([f, needle]))
    assert report.degenerate_faces == 1 and np.array_equal(f2, f)


def test_bow_tie_vertex_is_split_per_fan():
    v, f = grid(2)
    # a second grid touching the first at its corner (2, 2) = vertex 8 only
    v2, f2 = grid(2)
    v2 = v2 + [2.0, 2.0, 0.0]  # its vertex 0 is at (2, 2)
    f2 = np.where(f2 == 0, 8, f2 + len(v) - 1)
    vv = np.concatenate([v, v2[1:]])
    ff = np.concatenate([f, f2])
    with pytest.raises(JaxgeoError, match="non-manifold vertices.*: 8$"):
        Mesh(vv, ff)
    out_v, out_f, report, messages = repaired(vv, ff)
    assert (report.split_vertices, report.added_vertices) == (1, 1)
    assert len(out_v) == len(vv) + 1 and np.array_equal(out_v[-1], vv[8])
    # the fan with the vertex's first corner keeps index 8; the other gets the copy
    assert np.array_equal(out_f[: len(f)], f)
    assert (out_f[len(f) :] == len(vv)).any() and not (out_f[len(f) :] == 8).any()
    assert "1 non-manifold vertices split into 1 added vertices" in messages[0]
    Mesh(out_v, out_f)


def fin():
    """A 3 × 3 grid with a vertical fin triangle on its interior edge (1,1)–(2,2),
    vertices 5 and 10: that edge has three faces."""
    v, f = grid(3)
    v = np.concatenate([v, [[1.5, 1.5, 1.0]]])
    return v, np.concatenate([f, [[5, 10, len(v) - 1]]])


def test_nonmanifold_edge_split_keeps_every_face():
    v, f = fin()
    with pytest.raises(JaxgeoError, match=r"non-manifold edges.*: \(5, 10\)$"):
        Mesh(v, f)
    out_v, out_f, report, _ = repaired(v, f)
    assert report.nonmanifold_faces == 0 and len(out_f) == len(f)
    assert max_faces_per_edge(out_f) == 2
    # the grid keeps its vertices; the fin is separated from it by two copies
    assert np.array_equal(out_f[:-1], f[:-1])
    assert report.split_vertices == 2 and set(out_f[-1][:2]) == {len(v), len(v) + 1}
    mesh = Mesh(out_v, out_f)
    assert np.unique(np.asarray(mesh.face_component)).size == 2


def test_nonmanifold_edge_remove_drops_the_smallest_face():
    v, f = fin()
    out_v, out_f, report, messages = repaired(v, f, nonmanifold="remove")
    # the fin (area 0.5·√2·1 ≈ 0.71) is larger than the grid's halves (0.5)
    assert report.nonmanifold_faces == 1 and len(out_f) == len(f) - 1
    assert len(report.faces) == len(f) - 1 and len(f) - 1 in report.faces
    assert max_faces_per_edge(out_f) <= 2
    assert "1 faces on non-manifold edges removed" in messages[0]
    Mesh(out_v, out_f)


def test_wall_between_touching_solids_cancels():
    # two tetrahedra glued on a face, each with its own copy of it (opposite
    # orientations): merged, the shared face is a wall with edges of 3 faces
    v, f = tetrahedron()
    apex = np.array([[1.0, 1.0, 1.0]])
    vv = np.concatenate([v, apex])
    ff = np.concatenate([f, [[1, 2, 4], [2, 3, 4], [3, 1, 4], [1, 3, 2]]])
    out_v, out_f, report, _ = repaired(vv, ff)
    assert report.duplicate_faces == 2  # both copies of the wall
    mesh = Mesh(out_v, out_f)
    assert mesh.n_faces == 6 and not (np.asarray(mesh.edge_faces)[:, 1] < 0).any()


@pytest.mark.mistyped
def test_bad_arguments():
    v, f = grid(1)
    with pytest.raises(JaxgeoError, match="nonmanifold must be 'split' or 'remove'"):
        jg.repair_mesh(v, f, nonmanifold="fix")
    with pytest.raises(JaxgeoError, match="out of range"):
        jg.repair_mesh(v, f + 10)
    with pytest.raises(JaxgeoError, match="no face is left"):
        jg.repair_mesh(v, [[0, 0, 1]])


@pytest.mark.parametrize(
    "faces, problem",
    [
        ([[0, 1, 2], [0, 0, 1]], "vertex repeated"),
        ([[0, 1, 2], [0, 1, 4]], "zero area"),
        ([[0, 1, 2], [0, 2, 1]], "duplicate faces"),
        ([[0, 1, 2], [0, 1, 3], [1, 0, 5]], "non-manifold edges"),
        ([[0, 1, 2], [0, 3, 5]], "non-manifold vertices"),
    ],
)
def test_refusals_point_to_repair(faces, problem):
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0.5], [2, 0, 0], [0, 0, 1.0]]
    )
    with pytest.raises(JaxgeoError, match=problem) as info:
        Mesh(v, faces)
    assert "jaxgeo.repair_mesh or load_mesh(path, repair=True)" in str(info.value)
    Mesh(*jg.repair_mesh(v, faces, warn=False)[:2])


def test_load_mesh_repair(tmp_path):
    v, f = fin()
    path = tmp_path / "fin.obj"
    trimesh.Trimesh(v, f, process=False).export(path)
    with pytest.raises(JaxgeoError, match=r"fin\.obj.*non-manifold edges.*repair=True"):
        jg.load_mesh(path, merge_vertices=False)
    with pytest.warns(UserWarning, match=r"repaired .*fin\.obj: 2 non-manifold"):
        assert jg.load_mesh(path, merge_vertices=False, repair=True).n_faces == len(f)
    with pytest.warns(UserWarning, match="1 faces on non-manifold edges removed"):
        mesh = jg.load_mesh(path, merge_vertices=False, repair="remove")
    assert mesh.n_faces == len(f) - 1


# -------------------------------------------------------------------- real meshes

#: Meshes shipped inside packages that `Mesh` refuses as `trimesh.load` gives them
#: (trimesh merges vertices by position, but keeps them apart at texture seams),
#: and what repair changes: (split vertices, added vertices, faces removed).
REAL = {
    # a closed scan: one vertex where two parts of the surface touch (a pinch)
    "pymeshlab/tests/sample_meshes/cow.obj": ("non-manifold vertices", 1, 1, 0),
    # a textured scan: vertices kept apart at the texture seams leave bow-ties
    "pymeshlab/tests/sample_meshes/bunny10k_textured.obj": (
        "non-manifold vertices",
        76,
        77,
        0,
    ),
    # a CAD/voxel STL of 668 cubes, some sharing edges
    "compas/data/samples/cube_ascii.stl": ("non-manifold edges", 1324, 1324, 0),
}


@pytest.mark.parametrize("relpath", list(REAL))
def test_repair_real_mesh(relpath):
    problem, split, added, removed = REAL[relpath]
    tm = trimesh.load(package_mesh(relpath), process=True)
    with pytest.raises(JaxgeoError, match=re.escape(problem)):
        Mesh.from_trimesh(tm)
    v, f, report, messages = repaired(tm.vertices, tm.faces)
    assert (report.split_vertices, report.added_vertices) == (split, added)
    assert report.degenerate_faces + report.duplicate_faces == removed
    assert len(f) == len(tm.faces) - removed and len(messages) == 1
    mesh = Mesh(v, f)
    assert max_faces_per_edge(np.asarray(mesh.faces)) <= 2
    # nothing moved: the input's vertices first, then copies of some of them
    out = np.asarray(mesh.vertices)
    assert np.array_equal(out[: len(tm.vertices)], tm.vertices)
    copies = out[len(tm.vertices) :]
    assert (copies[:, None] == tm.vertices[None]).all(-1).any(1).all()
