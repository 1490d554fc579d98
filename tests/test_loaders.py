"""`load_mesh`: round trips through trimesh's writers, clear errors on bad files,
and fuzzing: a malformed file either loads into a valid `Mesh` or raises
`JaxgeoError` — never another exception, a crash or a hang."""

import contextlib
import random
import re
import signal
import struct
import warnings

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings, strategies as st

import jaxgeo as jg
from jaxgeo._checks import _COINCIDENT, check_point, warn_if_coincident
from jaxgeo._errors import JaxgeoError
from jaxgeo.loading import load_mesh
from jaxgeo.mesh import Mesh

from .helpers import package_mesh

FORMATS = {
    # name: (extension, trimesh export arguments)
    "obj": ("obj", {"file_type": "obj"}),
    "ply_binary": ("ply", {"file_type": "ply", "encoding": "binary"}),
    "ply_ascii": ("ply", {"file_type": "ply", "encoding": "ascii"}),
    "stl_binary": ("stl", {"file_type": "stl"}),
    "stl_ascii": ("stl", {"file_type": "stl_ascii"}),
    "off": ("off", {"file_type": "off"}),
}


def export(tm: trimesh.Trimesh, fmt: str) -> bytes:
    out = tm.export(**FORMATS[fmt][1])
    return out.encode() if isinstance(out, str) else out


def write(tmp_path, name: str, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def open_grid() -> trimesh.Trimesh:
    xs, ys = np.meshgrid(np.arange(4.0), np.arange(3.0), indexing="ij")
    v = np.stack([xs.ravel(), ys.ravel(), 0.1 * xs.ravel() * ys.ravel()], 1)
    idx = np.arange(12).reshape(4, 3)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
        idx[:-1, 1:].ravel(),
    )
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return trimesh.Trimesh(v, f, process=False)


def triangles(vertices, faces) -> np.ndarray:
    """The corner coordinates of every face, each face rotated to start at its
    smallest corner (keeping its orientation), sorted: comparable across vertex
    and face numberings."""
    t = np.round(np.asarray(vertices)[np.asarray(faces)], 6)  # (F, 3, 3)
    keys = [
        tuple(map(tuple, np.roll(tri, -min(range(3), key=lambda i: tuple(tri[i])), 0)))
        for tri in t
    ]
    return np.array(sorted(keys))


# ------------------------------------------------------------------ round trips


@pytest.mark.parametrize("fmt", list(FORMATS))
@pytest.mark.parametrize("shape", ["sphere", "grid"])
def test_round_trip(tmp_path, fmt, shape):
    tm = trimesh.creation.icosphere(1) if shape == "sphere" else open_grid()
    path = write(tmp_path, f"mesh.{FORMATS[fmt][0]}", export(tm, fmt))
    mesh = load_mesh(path)
    assert isinstance(mesh, Mesh)
    # STL stores each triangle's corners separately: merging restores the shared
    # vertices, so every format gives the original counts
    assert (mesh.n_vertices, mesh.n_faces) == (len(tm.vertices), len(tm.faces))
    # text formats keep about 8 significant digits, STL float32: 1e-6 is ample
    np.testing.assert_allclose(
        triangles(mesh.vertices, mesh.faces),
        triangles(tm.vertices, tm.faces),
        atol=2e-6,
    )
    if not fmt.startswith("stl"):  # no duplicates: the file's numbering is kept
        assert np.array_equal(np.asarray(mesh.faces), tm.faces)
        np.testing.assert_allclose(np.asarray(mesh.vertices), tm.vertices, atol=1e-7)
    boundary = int((np.asarray(mesh.edge_faces)[:, 1] < 0).sum())
    assert boundary == (0 if shape == "sphere" else 2 * (3 + 2))


def test_stl_merge_keeps_first_occurrence_order(tmp_path):
    tm = trimesh.creation.icosphere(0)
    mesh = load_mesh(write(tmp_path, "m.stl", export(tm, "stl_binary")))
    # merged vertices are numbered in the order the STL first lists them
    flat = np.asarray(mesh.faces).ravel()
    _, first = np.unique(flat, return_index=True)
    assert np.array_equal(flat[np.sort(first)], np.arange(mesh.n_vertices))


def test_merge_vertices_can_be_turned_off(tmp_path):
    tm = trimesh.creation.icosphere(0)
    path = write(tmp_path, "m.stl", export(tm, "stl_binary"))
    # unmerged, every STL triangle is its own component
    mesh = load_mesh(path, merge_vertices=False)
    assert mesh.n_vertices == 3 * mesh.n_faces
    assert np.unique(np.asarray(mesh.face_component)).size == mesh.n_faces


def test_quads_and_polygons_are_triangulated(tmp_path):
    obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0.5 0\nf 1 2 3 4\nf 2 5 3\n"
    mesh = load_mesh(write(tmp_path, "quad.obj", obj))
    assert (mesh.n_vertices, mesh.n_faces) == (5, 3)
    off = b"OFF\n5 1 0\n0 0 0\n1 0 0\n1.5 1 0\n0.5 1.5 0\n-0.5 1 0\n5 0 1 2 3 4\n"
    assert load_mesh(write(tmp_path, "pentagon.off", off)).n_faces == 3


def test_non_utf8_comment_in_obj(tmp_path):
    obj = b"# caf\xe9 (latin-1)\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    assert load_mesh(write(tmp_path, "latin1.obj", obj)).n_faces == 1


def test_obj_negative_relative_indices(tmp_path):
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n"
    mesh = load_mesh(write(tmp_path, "rel.obj", obj))
    assert np.array_equal(np.asarray(mesh.faces), [[0, 1, 2]])


def test_uppercase_extension(tmp_path):
    obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    assert load_mesh(write(tmp_path, "UPPER.OBJ", obj)).n_faces == 1


# ---------------------------------------------------------------- bad files


def test_missing_file(tmp_path):
    with pytest.raises(JaxgeoError, match="mesh file not found: .*nowhere.obj"):
        load_mesh(tmp_path / "nowhere.obj")


def test_directory_is_not_a_file(tmp_path):
    with pytest.raises(JaxgeoError, match="not a file"):
        load_mesh(tmp_path)


def test_no_extension(tmp_path):
    with pytest.raises(JaxgeoError, match="has no extension"):
        load_mesh(write(tmp_path, "mesh", b"v 0 0 0\n"))


@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "off"])
def test_empty_file(tmp_path, ext):
    with pytest.raises(JaxgeoError, match=rf"mesh file .*empty\.{ext} is empty"):
        load_mesh(write(tmp_path, f"empty.{ext}", b""))


PLY_HEADER = (
    b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
    b"end_header\n"
)
STL_TRIANGLE = np.array([0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0], "<f4").tobytes() + b"\0\0"

BAD_FILES = {
    # name: (contents, pattern the JaxgeoError message must match)
    "nan.obj": (b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "NaN at vertices: 1"),
    "inf.off": (b"OFF\n3 1 0\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n", "infinite"),
    "nan.ply": (PLY_HEADER + b"0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "NaN"),
    "range.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "out of bounds"),
    "range.off": (b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "outside the range"),
    "range.ply": (PLY_HEADER + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 70000\n", "out of range"),
    "lines.obj": (b"v 0 0 0\nv 1 0 0\nl 1 2\n", "holds no triangles"),
    "no_faces.off": (b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "holds no triangles"),
    "huge_count.off": (
        b"OFF\n1000000000 1 0\n0 0 0\n3 0 1 2\n",
        "header promises 1000000000 vertices, but the file holds 2 lines",
    ),
    "huge_count.ply": (
        PLY_HEADER.replace(b"ascii", b"binary_little_endian").replace(
            b"vertex 3", b"vertex 4000000000"
        )
        + b"\0" * 40,
        "header promises 4000000000 vertex, 1 face, but the file holds 40 bytes",
    ),
    "not_ply.ply": (b"hello\n", "could not read .* as PLY"),
    "short.stl": (b"\0" * 50, "neither an ASCII STL .* nor a binary STL"),
    "truncated.stl": (
        b"\0" * 80 + struct.pack("<I", 3) + 2 * STL_TRIANGLE + STL_TRIANGLE[:20],
        r"truncated or corrupt: its header says 3 triangles",
    ),
    "bad_ascii.stl": (
        b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0\n"
        b"endloop\nendfacet\nendsolid\n",
        "could not read .* as STL",
    ),
    "degenerate.obj": (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "zero area"),
    "duplicate.obj": (
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 2\n",
        "duplicate faces",
    ),
    "mesh.notaformat": (b"whatever", "could not read .* as NOTAFORMAT"),
}


@pytest.mark.parametrize("name", list(BAD_FILES))
def test_bad_file(tmp_path, name):
    data, pattern = BAD_FILES[name]
    with pytest.raises(JaxgeoError, match=pattern) as info:
        load_mesh(write(tmp_path, name, data))
    assert name in str(info.value)  # the message names the file


def test_binary_stl_with_wrong_count_is_repaired(tmp_path):
    tm = trimesh.creation.icosphere(0)
    data = bytearray(export(tm, "stl_binary"))
    data[80:84] = struct.pack("<I", 0)  # some exporters leave the count at 0
    with pytest.warns(
        UserWarning, match="header says 0 triangles but the file holds 20"
    ):
        mesh = load_mesh(write(tmp_path, "zero_count.stl", bytes(data)))
    assert (mesh.n_vertices, mesh.n_faces) == (12, 20)


def test_binary_stl_with_trailing_bytes(tmp_path):
    tm = trimesh.creation.icosphere(0)
    data = export(tm, "stl_binary") + b"\0" * 7
    with pytest.warns(UserWarning, match="ignoring 7 bytes after its 20 triangles"):
        assert load_mesh(write(tmp_path, "tail.stl", data)).n_faces == 20


def test_no_trimesh_log_noise(tmp_path, caplog):
    with pytest.raises(JaxgeoError):
        load_mesh(write(tmp_path, "bad.ply", b"ply\nformat ascii 1.0\nend_header\n1 2"))
    assert not [r for r in caplog.records if r.name.startswith("trimesh")]


# ------------------------------------------------------------------ lying files

OBJ_TRIANGLES = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n"

LYING_FILES = {
    # name: (contents, pattern the JaxgeoError message must match)
    "index0.obj": (
        OBJ_TRIANGLES + b"f 0 1 2\n",
        r"face with vertex index 0 on line 7 \('f 0 1 2'; 1 such",
    ),
    "index0_slashes.obj": (
        OBJ_TRIANGLES.replace(b"f 2 4 3", b"f 2/1/1 4/1/1 0/1/1"),
        "vertex index 0 on line 6.*OBJ indices start at 1",
    ),
    "short_vertices.off": (
        b"OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "promises 4 vertices, 1 faces, but the file holds 4 lines",
    ),
    "short_faces.off": (
        b"OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "promises 3 vertices, 2 faces, but the file holds 4 lines",
    ),
    "short_vertices.ply": (
        PLY_HEADER.replace(b"vertex 3", b"vertex 4")
        + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "promises 4 vertex, 1 face, but the file holds 4 lines",
    ),
    "short_faces.ply": (
        PLY_HEADER.replace(b"face 1", b"face 2") + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "promises 3 vertex, 2 face, but the file holds 4 lines",
    ),
    "short_vertices_binary.ply": (
        PLY_HEADER.replace(b"ascii", b"binary_little_endian").replace(
            b"vertex 3", b"vertex 4"
        )
        + np.zeros(9, "<f4").tobytes()
        + struct.pack("<B3i", 3, 0, 1, 2),
        "promises 4 vertex, 1 face, but the file holds 49 bytes",
    ),
    "count_beyond_file.stl": (
        b"\0" * 80 + struct.pack("<I", 5) + 3 * STL_TRIANGLE,
        r"header says 5 triangles \(334 bytes\) but the file has 234 bytes "
        r"\(3 whole triangles\)",
    ),
}


@pytest.mark.parametrize("name", list(LYING_FILES))
def test_lying_file_refused(tmp_path, name):
    data, pattern = LYING_FILES[name]
    with pytest.raises(JaxgeoError, match=pattern) as info:
        load_mesh(write(tmp_path, name, data))
    assert name in str(info.value)


def test_lying_file_fixtures_are_honest_when_fixed(tmp_path):
    """The same files with the lie removed load: the refusals above are about
    the lie, not about something else in the fixture."""
    honest = {
        "a.obj": OBJ_TRIANGLES,
        "b.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "c.ply": PLY_HEADER + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        "d.ply": PLY_HEADER.replace(b"ascii", b"binary_little_endian")
        + np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], "<f4").tobytes()
        + struct.pack("<B3i", 3, 0, 1, 2),
        "e.stl": b"\0" * 80 + struct.pack("<I", 1) + STL_TRIANGLE,
    }
    for name, data in honest.items():
        assert load_mesh(write(tmp_path, name, data)).n_faces >= 1, name


def test_obj_separated_by_tabs(tmp_path):
    data = OBJ_TRIANGLES.replace(b" ", b"\t").replace(b"\nf", b"\n  f")
    mesh = load_mesh(write(tmp_path, "tabs.obj", data))
    expected = load_mesh(write(tmp_path, "spaces.obj", OBJ_TRIANGLES))
    assert np.array_equal(np.asarray(mesh.faces), np.asarray(expected.faces))
    assert np.array_equal(np.asarray(mesh.vertices), np.asarray(expected.vertices))


# ------------------------------------------------------ merging never invalidates


def two_tetrahedra(shared: str) -> trimesh.Trimesh:
    """Two closed tetrahedra touching at a vertex, along an edge or on a face (the
    second is the first turned or mirrored), each with its own copies of the
    shared vertices: valid as it is, a pinch, an edge of four faces or a doubled
    face once identical vertices are merged."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    w = {"vertex": -v, "edge": v * [1, -1, -1], "face": v * [1, 1, -1]}[shared]
    g = f if shared == "edge" else f[:, ::-1]  # a mirror image turns inside out
    return trimesh.Trimesh(
        np.concatenate([v, w]), np.concatenate([f, g + 4]), process=False
    )


@pytest.mark.parametrize("shared", ["vertex", "edge", "face"])
@pytest.mark.parametrize("fmt", ["obj", "stl_binary"])
def test_merge_keeps_touching_solids_apart(tmp_path, shared, fmt):
    tm = two_tetrahedra(shared)
    path = write(tmp_path, f"touch.{FORMATS[fmt][0]}", export(tm, fmt))
    kept = {"vertex": 1, "edge": 2, "face": 3}[shared]  # positions held by two
    with pytest.warns(UserWarning, match=f"{kept} positions hold several vertices"):
        mesh = load_mesh(path)
    assert mesh.n_faces == 8
    if shared == "face" and fmt == "stl_binary":
        # an STL does not tell which of the four faces at each edge of the shared
        # face belong together: kept apart there, valid, but not closed
        assert 8 < mesh.n_vertices <= 24
    else:  # two closed tetrahedra: what the file holds
        assert mesh.n_vertices == 8
        assert not (np.asarray(mesh.edge_faces)[:, 1] < 0).any()
        assert np.unique(np.asarray(mesh.face_component)).size == 2


@pytest.mark.parametrize("shared", ["vertex", "edge", "face"])
def test_merge_and_repair_touching_solids(tmp_path, shared):
    """With repair, every position merges and repair separates per fan; solids
    that share a face become one (the doubled face, a wall, goes)."""
    path = write(tmp_path, "touch.stl", export(two_tetrahedra(shared), "stl_binary"))
    warn = "2 duplicate faces" if shared == "face" else "non-manifold vertices split"
    with pytest.warns(UserWarning, match=warn):
        mesh = load_mesh(path, repair=True)
    assert not (np.asarray(mesh.edge_faces)[:, 1] < 0).any()
    parts = np.unique(np.asarray(mesh.face_component)).size
    assert (mesh.n_vertices, mesh.n_faces, parts) == {
        "vertex": (8, 8, 2),
        "edge": (8, 8, 2),
        "face": (5, 6, 1),
    }[shared]


def test_merge_real_pinch():
    """cow.obj: a closed mesh with one vertex duplicated where two parts touch.
    Merged naively it was refused (non-manifold vertex); now it loads as the file
    means it, with a warning naming the two vertices."""
    path = package_mesh("pymeshlab/tests/sample_meshes/cow.obj")
    with pytest.warns(UserWarning, match=r"1 positions .* vertices \(44, 2903\)"):
        mesh = load_mesh(path)
    apart = load_mesh(path, merge_vertices=False)
    assert np.array_equal(np.asarray(mesh.faces), np.asarray(apart.faces))
    assert not (np.asarray(mesh.edge_faces)[:, 1] < 0).any()


def test_merge_real_touching_cubes():
    """compas's cube_ascii.stl: 668 cubes, some sharing edges. Merged naively it
    was refused (656 non-manifold edges); merged per fan, it is 668 closed cubes."""
    path = package_mesh("compas/data/samples/cube_ascii.stl")
    with pytest.warns(UserWarning, match="1324 positions hold several vertices"):
        mesh = load_mesh(path)
    assert mesh.n_faces == 8016
    assert np.unique(np.asarray(mesh.face_component)).size == 668
    assert not (np.asarray(mesh.edge_faces)[:, 1] < 0).any()


def test_textured_obj():
    """A textured OBJ: trimesh keeps its vertices apart at the texture seams, so
    as `trimesh.load` gives it the mesh has bow-ties; `load_mesh` merges them."""
    path = package_mesh("pymeshlab/tests/sample_meshes/bunny10k_textured.obj")
    mesh = load_mesh(path)
    assert (mesh.n_vertices, mesh.n_faces) == (5051, 9999)
    tm = trimesh.load(path)
    with pytest.raises(JaxgeoError, match="merge_vertices=True.*load_mesh"):
        Mesh.from_trimesh(tm)
    merged = Mesh.from_trimesh(tm, merge_vertices=True)
    assert (merged.n_vertices, merged.n_faces) == (5051, 9999)


# ------------------------------------------------------- coincident endpoints


@pytest.fixture(scope="module")
def pinched():
    """Two tetrahedra touching at the origin, kept apart (vertices 0 and 4)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Mesh.from_trimesh(two_tetrahedra("vertex"))


def test_coincident_endpoint_warns(pinched):
    with pytest.warns(UserWarning, match=r"p1 = .* shared by vertices 0, 4") as info:
        check_point("p1", np.zeros(3), pinched)
    message = str(info[0].message)
    assert "jaxgeo.SurfacePoint" in message and "for vertex 4" in message
    # within rounding of the position, still ambiguous
    scale = float(pinched.mean_edge_length)
    with pytest.warns(UserWarning, match="shared by vertices 0, 4"):
        check_point("p2", np.full(3, 1e-8 * scale), pinched)


def test_coincident_rows_of_a_batch_warn(pinched):
    # for shortest_paths: one warning naming the first ambiguous row
    points = np.array([[0.2, 0.2, 0], [0, 0, 0], [0.1, 0, 0.1], [0, 0, 0]])
    with pytest.warns(UserWarning, match=r"P1\[1\] = .* vertices 0, 4 \(2 such rows"):
        warn_if_coincident("P1", points, pinched)


def test_other_endpoints_do_not_warn(pinched):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_point("p1", np.array([1.0, 0, 0]), pinched)  # an ordinary vertex
        check_point("p1", np.array([0.2, 0.2, 0]), pinched)  # inside a face
        check_point("p1", np.full(3, 1e-4), pinched)  # near, not at, the pinch
        check_point("p1", jg.SurfacePoint(0, [1.0, 0, 0]), pinched)


def test_coincident_lookup_is_cached(pinched):
    check_point("p1", np.array([0.2, 0.2, 0]), pinched)
    entry = _COINCIDENT[id(pinched.vertices)]
    check_point("p1", np.array([0.3, 0.2, 0]), pinched)
    assert _COINCIDENT[id(pinched.vertices)] is entry


def test_shortest_path_warns_at_coincident_endpoint(pinched):
    # p2 is refused before anything compiles, after p1 was checked
    with pytest.warns(UserWarning, match="p1 = .* shared by vertices 0, 4"):
        with pytest.raises(JaxgeoError, match="p2 has NaN"):
            jg.shortest_path(pinched, np.zeros(3), [np.nan, 0, 0])


# ------------------------------------------------------------------------ fuzzing

CASE_SECONDS = 5  # one malformed file of a few kB: anything slower is a hang


@contextlib.contextmanager
def time_limit(seconds: float):
    def on_alarm(signum, frame):
        raise TimeoutError(f"load_mesh took more than {seconds} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def load_or_refuse(path):
    """The contract under fuzzing: a valid Mesh, or JaxgeoError. Anything else
    (another exception type, a timeout) propagates and fails the test."""
    with time_limit(CASE_SECONDS), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # repair and reorientation warnings
        try:
            mesh = load_mesh(path)
        except JaxgeoError as e:
            assert str(e)
            return None
    assert isinstance(mesh, Mesh)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert np.isfinite(v).all() and mesh.n_faces > 0
    assert f.min() >= 0 and f.max() < len(v)
    return mesh


GARBAGE = [
    b"nan", b"inf", b"-inf", b"1e999", b"-1e-400", b"-", b"abc", b"1.2.3", b"\0",
    b"0x10", b"", b"3/4/5", b"99999999999999999999", b"-7", b"4000000000",
]  # fmt: skip


def mutate(data: bytes, rng: random.Random) -> bytes:
    """One malformation of a well-formed file."""
    b = bytearray(data)
    kind = rng.randrange(9)
    if kind == 0:  # truncated anywhere
        return bytes(b[: rng.randrange(len(b) + 1)])
    if kind == 1:  # a few random bytes changed
        for _ in range(rng.randrange(1, 10)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if kind == 2:  # random bytes inserted
        pos = rng.randrange(len(b) + 1)
        return bytes(b[:pos]) + rng.randbytes(rng.randrange(1, 60)) + bytes(b[pos:])
    if kind == 3:  # number tokens replaced by garbage
        tokens = re.split(rb"(\s+)", bytes(b))
        numeric = [
            i for i, t in enumerate(tokens) if re.fullmatch(rb"-?[0-9.eE+-]+", t)
        ]
        for _ in range(rng.randrange(1, 6)):
            if numeric:
                tokens[rng.choice(numeric)] = rng.choice(GARBAGE)
        return b"".join(tokens)
    if kind == 4:  # integers (counts, indices) replaced by out-of-range ones
        tokens = re.split(rb"(\s+)", bytes(b))
        ints = [i for i, t in enumerate(tokens) if re.fullmatch(rb"[0-9]+", t)]
        for _ in range(rng.randrange(1, 4)):
            if ints:
                value = rng.choice([-1, 0, 3, 12, 2**31, 2**63, 10**12])
                tokens[rng.choice(ints)] = str(value).encode()
        return b"".join(tokens)
    if kind == 5:  # a line deleted or duplicated
        lines = bytes(b).split(b"\n")
        i = rng.randrange(len(lines))
        if rng.random() < 0.5:
            del lines[i]
        else:
            lines.insert(i, lines[rng.randrange(len(lines))])
        return b"\n".join(lines)
    if kind == 6:  # a face line turned into a quad or a longer polygon
        lines = bytes(b).split(b"\n")
        faces = [i for i, s in enumerate(lines) if s.startswith((b"f ", b"3 "))]
        if faces:
            i = rng.choice(faces)
            extra = b" ".join(str(rng.randrange(1, 13)).encode() for _ in range(2))
            lines[i] = lines[i].replace(b"3 ", b"5 ", 1) + b" " + extra
        return b"\n".join(lines)
    if kind == 7:  # binary STL count field set to something else
        if len(b) >= 84:
            b[80:84] = struct.pack("<I", rng.choice([0, 1, 19, 21, 2**32 - 1]))
        return bytes(b)
    return rng.randbytes(rng.randrange(0, 400))  # pure noise


@pytest.fixture(scope="module")
def well_formed():
    tm = trimesh.creation.icosphere(0)
    return {fmt: export(tm, fmt) for fmt in FORMATS}


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_fuzz_seeded(tmp_path, well_formed, fmt):
    """200 malformed files per format (seeded, so a failure reproduces)."""
    rng = random.Random(f"jaxgeo-{fmt}")
    ext = FORMATS[fmt][0]
    loaded = 0
    for case in range(200):
        data = mutate(well_formed[fmt], rng)
        path = write(tmp_path, f"case.{ext}", data)
        try:
            loaded += load_or_refuse(path) is not None
        except BaseException as e:
            keep = write(tmp_path, f"failing_{case}.{ext}", data)
            raise AssertionError(
                f"case {case} ({keep}): {type(e).__name__}: {e}"
            ) from e
    assert 0 < loaded < 200  # both outcomes occur: the mutations are not all fatal


@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    ext=st.sampled_from(["obj", "ply", "stl", "off"]),
    data=st.one_of(
        st.binary(max_size=300),
        st.lists(
            st.sampled_from(
                [
                    b"v",
                    b"f",
                    b"OFF",
                    b"ply",
                    b"solid",
                    b"facet",
                    b"vertex",
                    b"1",
                    b"-1",
                    b"0.5",
                    b"nan",
                    b"3",
                    b"end_header",
                    b"\n",
                    b" ",
                    b"/",
                ]
            ),  # fmt: skip
            max_size=80,
        ).map(b" ".join),
    ),
)
def test_fuzz_hypothesis(tmp_path_factory, ext, data):
    path = tmp_path_factory.mktemp("hyp") / f"case.{ext}"
    path.write_bytes(data)
    load_or_refuse(path)
