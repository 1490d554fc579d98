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
