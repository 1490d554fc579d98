"""What a new user meets first: batch results by row, readable status, example
meshes, the float32 warning, the compilation cache."""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import surfaces
from jaxgeo.data import EXAMPLES
from jaxgeo.locate import vertex_valid

from .helpers import unit_icosphere


@pytest.fixture(scope="module")
def batch():
    mesh = unit_icosphere(2)
    p = np.random.default_rng(3).normal(size=(3, 2, 3))
    p /= np.linalg.norm(p, axis=-1, keepdims=True)
    return mesh, p, jg.shortest_paths(mesh, p[:, 0], p[:, 1], chunk_size=4)


def test_batch_rows_are_paths(batch):
    mesh, p, paths = batch
    assert len(paths) == 3
    rows = list(paths)
    assert len(rows) == 3 and all(isinstance(r, jg.Path) for r in rows)
    for i, row in enumerate(rows):
        np.testing.assert_array_equal(row.points, paths.points[i])
        assert row.count == paths.count[i] and row.length == paths.length[i]
        assert row.outcome is jg.Status.SUCCESS
    np.testing.assert_array_equal(paths[-1].points, paths.points[2])
    # each row's endpoints (a batch axis of 3) are where its polyline starts/ends
    assert paths.start is not None and paths.end is not None
    assert paths.start.face.shape == (3,) and paths.end.bary.shape == (3, 3)
    np.testing.assert_allclose(np.sum(paths.start.bary, axis=1), 1.0, rtol=1e-12)
    for row in rows:
        assert row.start is not None and row.end is not None
        line = row.polyline()
        np.testing.assert_allclose(row.start.position(mesh), line[0], atol=1e-12)
        np.testing.assert_allclose(row.end.position(mesh), line[-1], atol=1e-12)
    assert len(paths[1:]) == 2  # a slice is a smaller batch
    with pytest.raises(IndexError, match="row 3 out of range for a batch of 3"):
        paths[3]


def test_polylines_of_a_batch(batch):
    mesh, p, paths = batch
    lines = paths.polylines()
    assert [len(x) for x in lines] == [int(c) for c in paths.count]
    for i, line in enumerate(lines):
        assert isinstance(line, np.ndarray) and line.shape[1] == 3
        np.testing.assert_array_equal(line, np.asarray(paths.points[i])[: len(line)])
        # each row is the path the single-path API traces, to the rounding of
        # the batched solve (1e-12 of the unit sphere's size)
        single = jg.shortest_path(mesh, p[i, 0], p[i, 1])
        np.testing.assert_allclose(line, single.polyline(), atol=1e-12)
    with pytest.raises(jg.JaxgeoError, match=r"batch of 3 paths: use paths.polylines"):
        paths.polyline()
    with pytest.raises(jg.JaxgeoError, match="outcome is for a single path"):
        _ = paths.outcome
    single = jg.shortest_path(mesh, p[0, 0], p[0, 1])
    assert len(single.polylines()) == 1
    with pytest.raises(TypeError):
        len(single)
    assert single and paths  # truthy like any object, never len()'s TypeError
    with pytest.raises(jg.JaxgeoError, match="has no rows"):
        single[0]


def test_outcome_reads_a_failure_and_refuses_tracers():
    mesh = unit_icosphere(2)
    far = jg.shortest_path(mesh, [0, 0, 5.0], [0, 1.0, 0], throw=False)
    assert far.outcome is jg.Status.FAR_FROM_SURFACE
    assert "too far" in far.outcome.message

    @jax.jit
    def f(a, b):
        return jg.shortest_path(mesh, a, b, throw=False).outcome

    with pytest.raises(jg.JaxgeoError, match="needs a concrete path"):
        f(jax.numpy.array([1.0, 0, 0]), jax.numpy.array([0, 1.0, 0]))


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_example_meshes_ship_and_match_their_generators(name):
    path = jg.example_mesh_path(name)
    assert os.path.isfile(path)
    mesh = jg.load_mesh(path)
    v, f = getattr(surfaces, name)(**EXAMPLES[name])
    np.testing.assert_array_equal(np.asarray(mesh.faces), f)
    # OBJ keeps 17 decimals: coordinates agree to 1e-17 absolute, i.e. below
    # float64 rounding of these O(1) meshes (a few ulps)
    np.testing.assert_allclose(mesh.vertices, v, rtol=0, atol=4 * np.finfo(float).eps)
    with pytest.raises(jg.JaxgeoError, match="unknown example mesh"):
        jg.example_mesh_path("tent")


@pytest.mark.parametrize("ext", ["obj", "ply", "off"])
def test_save_writes_any_builtin_surface(tmp_path, ext):
    out = surfaces.save("saddle", tmp_path / f"s.{ext}", n=4)
    mesh = jg.load_mesh(out)
    v, f = surfaces.saddle(n=4)
    np.testing.assert_array_equal(np.asarray(mesh.faces), f)
    np.testing.assert_allclose(mesh.vertices, v, rtol=0, atol=4 * np.finfo(float).eps)
    with pytest.raises(jg.JaxgeoError, match="unknown surface 'torus'"):
        surfaces.save("torus", tmp_path / "t.obj")
    with pytest.raises(jg.JaxgeoError, match="surfaces.saddle: .*radius"):
        surfaces.save("saddle", tmp_path / "t.obj", radius=2)


def _run(code: str, **env) -> subprocess.CompletedProcess:
    """`code` in a fresh Python (JAX's global config untouched by the tests')."""
    environ = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    environ.update(env)
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        env=environ,
        timeout=120,
    )


def test_float64_input_without_x64_warns_once():
    r = _run(
        """
        import warnings
        import jax
        import numpy as np
        import jaxgeo as jg
        from jaxgeo import surfaces
        from jaxgeo._precision import warn_if_x64_disabled

        v, f = surfaces.icosphere(1)
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            jg.Mesh(v.astype(np.float32), f)   # float32 asked for: no warning
            assert not w, w
            jg.Mesh(v, f)
            jg.Mesh(v, f)
        hits = [x for x in w if issubclass(x.category, jg.PrecisionWarning)]
        assert len(hits) == 1, [str(x.message) for x in w]
        assert warn_if_x64_disabled(v) and not warn_if_x64_disabled(v[:0] > 0)
        jax.config.update("jax_enable_x64", True)
        assert not warn_if_x64_disabled(v)     # float64 is float64 now
        print(hits[0].filename)
        print(hits[0].message)
        """
    )
    assert r.returncode == 0, r.stderr
    filename, message = r.stdout.split("\n", 1)
    assert filename == "<string>"  # points at the user's line, not at jaxgeo
    assert "float32" in message and "1e-7" in message and "jax_enable_x64" in message


def test_enable_compilation_cache_stores_compiled_code(tmp_path):
    cache, env = tmp_path / "xla", tmp_path / "env"
    r = _run(
        f"""
        import jax
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
        jax.jit(lambda x: x + 1)(1.0)          # compiled before: not stored
        import jaxgeo as jg
        print(jg.enable_compilation_cache())   # $JAX_COMPILATION_CACHE_DIR
        path = jg.enable_compilation_cache({str(cache)!r})
        assert jax.config.jax_compilation_cache_dir == path
        jax.jit(lambda x: x * 3)(1.0)
        print(path)
        """,
        JAX_COMPILATION_CACHE_DIR=str(env),
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == [str(env), str(cache)] and env.is_dir()
    assert any(cache.iterdir())  # the second function's executable is on disk


def test_pyproject_ships_every_example_mesh():
    """setuptools package-data names the example files, so a wheel has them (an
    editable install reads the source tree and would not notice)."""
    import fnmatch

    tomllib = pytest.importorskip("tomllib")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with open(os.path.join(root, "pyproject.toml"), "rb") as f:
        globs = tomllib.load(f)["tool"]["setuptools"]["package-data"]["jaxgeo.data"]
    for name in EXAMPLES:
        assert any(fnmatch.fnmatch(f"{name}.obj", g) for g in globs), name


def test_float32_note_names_the_cause_only_in_float32():
    from jaxgeo._precision import float32_note

    note = float32_note(np.float32)
    assert "float32" in note and "jax_enable_x64" in note
    assert float32_note(np.float64) == ""


# ------------------------------------------------------- endpoints by vertex index


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_integer_endpoints_are_vertex_indices():
    mesh = unit_icosphere(2)
    v = np.asarray(mesh.vertices)
    path = jg.shortest_path(mesh, 0, 100)
    # a vertex index is SurfacePoint.vertex: the same compiled solve, bit for bit
    sp = jg.shortest_path(
        mesh, jg.SurfacePoint.vertex(mesh, 0), jg.SurfacePoint.vertex(mesh, 100)
    )
    assert float(path.length) == float(sp.length)
    line = path.polyline()
    np.testing.assert_array_equal(line[0], v[0])  # exactly at the vertices
    np.testing.assert_array_equal(line[-1], v[100])
    # numpy and JAX integer scalars too; the 3-D points of the same vertices give
    # the same path, to the rounding of locating them (1e-12 of the unit sphere)
    same = jg.shortest_path(mesh, np.int64(0), jax.numpy.int32(100))
    assert float(same.length) == float(path.length)
    by_point = jg.shortest_path(mesh, v[0], v[100])
    assert float(by_point.length) == pytest.approx(float(path.length), rel=1e-12)


@pytest.mark.parametrize(
    "p1, p2, message",
    [
        (0, 162, r"p2: vertex 162 is out of range \[0, 162\)"),
        (-1, 5, r"p1: vertex -1 is out of range"),
        (True, 5, "p1 must be a real 3-D point, got dtype bool"),  # not an index
        (np.array([0]), 5, r"3-D point, shape \(3,\), or an integer vertex index"),
    ],
)
def test_bad_vertex_indices_name_the_endpoint(p1, p2, message):
    with pytest.raises(jg.JaxgeoError, match=message):
        jg.shortest_path(unit_icosphere(2), p1, p2)


def test_surface_point_vertex_works_on_traced_indices():
    mesh = unit_icosphere(2)
    faces = np.asarray(mesh.faces)
    at = jax.jit(lambda i: jg.SurfacePoint.vertex(mesh, i))
    for i in (0, 41, mesh.n_vertices - 1):
        for sp in (jg.SurfacePoint.vertex(mesh, i), at(i)):
            assert i in faces[int(sp.face)]
            assert sorted(np.asarray(sp.bary).tolist()) == [0.0, 0.0, 1.0]
            np.testing.assert_array_equal(sp.position(mesh), mesh.vertices[i])
    # no vertex: not a point of the mesh (NaN coordinates, vertex_valid False)
    for i in (-1, mesh.n_vertices):
        assert np.isnan(np.asarray(at(i).bary)).all()
    # a vertex that no face references
    v, f = np.asarray(mesh.vertices), faces
    loose = jg.Mesh(np.vstack([v, [[0.0, 0.0, 3.0]]]), f)
    np.testing.assert_array_equal(
        vertex_valid(loose, np.array([0, 162, 163])), [True, False, False]
    )
    with pytest.raises(jg.JaxgeoError, match="p1: vertex 162 belongs to no face"):
        jg.shortest_path(loose, 162, 0)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_batches_of_vertex_indices(batch):
    mesh = batch[0]
    v = np.asarray(mesh.vertices)
    i, j = np.array([0, 1, 7]), np.array([5, 100, 7])
    paths = jg.shortest_paths(mesh, i, j, chunk_size=4)
    for k in range(3):
        single = jg.shortest_path(mesh, int(i[k]), int(j[k]))
        # the batched solve equals the single one to rounding (1e-12 of the size)
        np.testing.assert_allclose(
            paths[k].polyline(), single.polyline(), rtol=0, atol=1e-12
        )
        np.testing.assert_array_equal(paths[k].polyline()[0], v[i[k]])
    assert float(paths.length[2]) == 0.0  # from a vertex to itself
    # one side by index, the other by 3-D point: one (N,) and one (N, 3)
    mixed = jg.shortest_paths(mesh, i, v[j], chunk_size=4)
    np.testing.assert_allclose(mixed.length, paths.length, rtol=1e-12, atol=1e-15)
    with pytest.raises(jg.JaxgeoError, match=r"p2\[1\]: vertex 500 is out of range"):
        jg.shortest_paths(mesh, i, np.array([5, 500, 7]))
    with pytest.raises(jg.JaxgeoError, match="same shape"):
        jg.shortest_paths(mesh, i, j[:2])


# ------------------------------------------------------- failures, status by row


def test_failed_rows_have_nan_length_and_readable_outcomes(batch):
    mesh, p, _ = batch
    far = p[:, 0].copy()
    far[1] *= 5  # 4 radii off the unit sphere
    paths = jg.shortest_paths(mesh, far, p[:, 1], chunk_size=4, throw=False)
    ok, bad = jg.Status.SUCCESS, jg.Status.FAR_FROM_SURFACE
    assert paths.outcomes == [ok, bad, ok]
    assert [jg.Status(int(s)) for s in paths.status] == paths.outcomes
    assert np.isnan(paths.length[1]) and np.isfinite(paths.length[[0, 2]]).all()
    assert paths.outcomes[1].name == "FAR_FROM_SURFACE"
    with pytest.raises(jg.JaxgeoError, match=r"1 of 3 paths failed .* rows \[1\]"):
        jg.shortest_paths(mesh, far, p[:, 1], chunk_size=4)
    one = jg.shortest_path(mesh, far[1], p[1, 1], throw=False)
    assert np.isnan(float(one.length)) and one.outcomes == [bad]
    assert jg.Status(int(one.status)) is one.outcome is bad
