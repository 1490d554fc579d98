"""The `jaxgeo` command line."""

import argparse
import functools
import json

import numpy as np
import pytest
import trimesh

import jaxgeo as jg
from jaxgeo.cli import build_parser, main

from .helpers import unit_icosphere


@pytest.fixture(scope="module")
def sphere_file(tmp_path_factory):
    """A 320-face unit icosphere as OBJ (every vertex on the sphere)."""
    mesh = unit_icosphere(2)
    file = tmp_path_factory.mktemp("mesh") / "sphere.obj"
    trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)).export(file)
    return file


def test_path_on_builtin_example_prints_one_line_summary(capsys):
    assert main(["path"]) == 0
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert len(lines) == 1 and "length" in lines[0] and "built-in catenoid" in lines[0]
    # the built-in catenoid's ring points are 1 apart in z: the path is longer
    assert float(lines[0].split("length ")[1].split(",")[0]) > 1.0
    assert err == ""


def test_path_format_json_goes_to_stdout_summary_to_stderr(capsys):
    assert main(["path", "--format", "json"]) == 0
    out, err = capsys.readouterr()
    d = json.loads(out)
    assert d["status"] == "success" and d["length"] > 1.0
    pts = np.array(d["points"])
    assert pts.shape == (d["count"], 3)
    np.testing.assert_allclose(pts[0], [1.0, 0.0, -0.5], atol=1e-12)
    # the endpoints (face, barycentrics) and the method's stats come along
    assert [d["start"]["face"], d["end"]["face"]] == [
        d["elements"][0],
        d["elements"][-1],
    ]
    for end in (d["start"], d["end"]):
        assert len(end["bary"]) == 3 and abs(sum(end["bary"]) - 1) <= 1e-12
    assert d["stats"]["starts"] >= 1 and "corridor_length" in d["stats"]
    assert "length" in err


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_path_on_mesh_file_writes_obj(sphere_file, tmp_path, capsys):
    out = tmp_path / "seam.obj"
    args = ["path", str(sphere_file), "--from", "1", "0", "0", "--to", "0", "1", "0"]
    assert main([*args, "-o", str(out)]) == 0  # format from the extension
    text = out.read_text()
    n_v = sum(1 for line in text.splitlines() if line.startswith("v "))
    line = [ln for ln in text.splitlines() if ln.startswith("l ")][0]
    assert len(line.split()) - 1 == n_v >= 2
    stdout = capsys.readouterr().out
    assert "length" in stdout and "written to" in stdout


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_vertex_endpoints_give_the_path_between_the_vertices(sphere_file, capsys):
    mesh = jg.load_mesh(sphere_file)
    v = np.asarray(mesh.vertices)
    i, j = 3, 100
    assert main(["path", str(sphere_file), "--from-vertex", str(i)] +
                ["--to-vertex", str(j), "--format", "json"]) == 0  # fmt: skip
    by_index = json.loads(capsys.readouterr().out)
    xyz = [*map(str, v[i]), "--to", *map(str, v[j])]
    assert main(["path", str(sphere_file), "--from", *xyz, "--format", "json"]) == 0
    by_point = json.loads(capsys.readouterr().out)
    # Both start exactly at vertex i; the located point equals the vertex to
    # rounding, so the lengths agree to a few ulps of the mesh size (1).
    np.testing.assert_array_equal(by_index["points"][0], v[i])
    np.testing.assert_allclose(by_index["points"][-1], v[j], atol=1e-15)
    assert by_index["length"] == pytest.approx(by_point["length"], rel=1e-12)


def test_vertex_out_of_range_is_a_usage_error_naming_the_option(sphere_file, capsys):
    argv = ["path", str(sphere_file), "--from-vertex", "0", "--to-vertex", "162"]
    assert main(argv) == 2  # the 320-face icosphere has 162 vertices
    assert "--to-vertex: vertex 162 is out of range [0, 162)" in capsys.readouterr().err


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_far_point_is_a_clear_error(sphere_file, capsys):
    code = main(["path", str(sphere_file), "--from", "0", "0", "5", "--to", "0", "1"])
    assert code == 2  # usage error: --to takes three numbers
    code = main(
        ["path", str(sphere_file), "--from", "0", "0", "5", "--to", "0", "1", "0"]
    )
    assert code == 2
    assert "too far from the surface" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["path", "m.obj", "--from", "1", "0", "0"], "give both ends"),
        (["path", "m.obj", "--to-vertex", "2"], "give both ends"),
        (["path", "--from", "1", "0", "0", "--from-vertex", "1"], "not allowed"),
        (["path", "--method", "fast"], "invalid choice"),
        (["paths", "m.obj"], "required"),
        (["surface", "torus"], "invalid choice"),
        (["surface", "cone_tent", "n_around"], "KEY=VALUE"),
        (["surface", "cone_tent", "n_around=many"], "expected a number"),
    ],
)
def test_every_usage_error_exits_2(argv, message, capsys):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_help_exits_0_and_every_option_says_its_default(capsys):
    assert main(["path", "--help"]) == 0
    assert "--from-vertex" in capsys.readouterr().out
    parser = build_parser()
    subparsers = next(
        a for a in parser._actions if isinstance(a, argparse._SubParsersAction)
    )
    for name in ("path", "paths", "surface", "validate"):
        for action in subparsers.choices[name]._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            assert action.help, f"{name} {action.dest} has no help text"
            if action.option_strings and action.default not in (None, False):
                assert "default" in action.help, f"{name} {action.dest}"


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_method_default_is_the_librarys_and_is_passed_on(monkeypatch, capsys):
    import inspect

    import jaxgeo.geodesic

    default = inspect.signature(jg.shortest_path).parameters["method"].default
    assert build_parser().parse_args(["path"]).method == default
    seen = {}
    real = jaxgeo.geodesic.shortest_path

    @functools.wraps(real)  # same signature: the parser reads its defaults
    def spy(mesh, p1, p2, **kwargs):
        seen.update(kwargs)
        return real(mesh, p1, p2, **{**kwargs, "method": "laser"})

    monkeypatch.setattr(jaxgeo.geodesic, "shortest_path", spy)
    assert main(["path", "--method", "smooth", "--max-distance", "0.25"]) == 0
    assert seen["method"] == "smooth" and seen["max_distance"] == 0.25
    assert "method smooth" in capsys.readouterr().out


def _pairs(n: int, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(n, 2, 3))
    return (p / np.linalg.norm(p, axis=-1, keepdims=True)).reshape(n, 6)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_paths_batch_from_csv_with_header(sphere_file, tmp_path, capsys):
    pairs = tmp_path / "pairs.csv"
    np.savetxt(pairs, _pairs(5), delimiter=",", header="x1,y1,z1,x2,y2,z2", comments="")
    assert pairs.read_text().startswith("x1,")  # a plain header row, no '#'
    out = tmp_path / "lengths.csv"
    code = main(["paths", str(sphere_file), str(pairs), "-o", str(out)] +
                ["--chunk-size", "4"])  # fmt: skip
    assert code == 0
    rows = out.read_text().splitlines()
    assert rows[0] == "row,status,length,points" and len(rows) == 6
    assert all(r.split(",")[1] == "success" for r in rows[1:])
    stdout, stderr = capsys.readouterr()
    assert "5/5 paths" in stderr and "5 paths complete, 0 failed" in stdout


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_paths_leaves_failed_rows_empty_and_writes_points(
    sphere_file, tmp_path, capsys
):
    p = _pairs(4, seed=1)
    p[2, :3] = [0.0, 0.0, 5.0]  # far from the sphere: this row fails
    pairs = tmp_path / "pairs.csv"
    np.savetxt(pairs, p, delimiter=",")
    table = tmp_path / "lengths.csv"
    base = [
        "paths",
        str(sphere_file),
        str(pairs),
        "--chunk-size",
        "4",
        "-o",
        str(table),
    ]
    for ext in ("obj", "csv", "json"):
        assert main([*base, "--points", str(tmp_path / f"seams.{ext}")]) == 1
    stdout = capsys.readouterr().out
    assert "3 paths complete, 1 failed (far_from_surface; row 2" in stdout
    rows = [r.split(",") for r in table.read_text().splitlines()[1:]]
    assert rows[2] == ["2", "far_from_surface", "", ""]
    counts = [int(r[3]) for r in rows if r[1] == "success"]
    assert len(counts) == 3 and all(float(r[2]) > 0 for r in rows if r[1] == "success")

    obj = (tmp_path / "seams.obj").read_text().splitlines()
    polylines = [ln.split()[1:] for ln in obj if ln.startswith("l ")]
    assert [len(pl) for pl in polylines] == counts  # one polyline per complete row
    n_v = sum(1 for ln in obj if ln.startswith("v "))
    assert int(polylines[-1][-1]) == n_v == sum(counts)  # 1-based, consecutive
    long = np.loadtxt(tmp_path / "seams.csv", delimiter=",", skiprows=1)
    assert np.bincount(long[:, 0].astype(int), minlength=4).tolist() == [
        counts[0], counts[1], 0, counts[2]
    ]  # fmt: skip
    js = json.loads((tmp_path / "seams.json").read_text())
    assert [len(r["points"]) for r in js] == [counts[0], counts[1], 0, counts[2]]
    assert js[2]["length"] is None and js[2]["status"] == "far_from_surface"
    # the written points are the paths: their polyline lengths are the table's
    for r, row in zip(js, rows):
        if row[1] == "success":
            pts = np.asarray(r["points"])
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
            assert seg == pytest.approx(float(row[2]), rel=1e-12)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_paths_accepts_vertex_index_pairs(sphere_file, tmp_path, capsys):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("i,j\n0,10\n5,100\n")
    out = tmp_path / "lengths.csv"
    argv = ["paths", str(sphere_file), str(pairs), "-o", str(out), "--chunk-size", "4"]
    assert main(argv) == 0
    rows = out.read_text().splitlines()[1:]
    assert [r.split(",")[1] for r in rows] == ["success", "success"]
    pairs.write_text("0,1.5\n")
    assert main(["paths", str(sphere_file), str(pairs)]) == 2
    assert "vertex indices" in capsys.readouterr().err


def test_surface_writes_the_shipped_example(tmp_path, capsys):
    from jaxgeo.data import EXAMPLES

    for name, params in EXAMPLES.items():
        out = tmp_path / f"{name}.obj"
        kv = [f"{k}={v}" for k, v in params.items()]
        assert main(["surface", name, *kv, "-o", str(out)]) == 0
        shipped = jg.example_mesh_path(name)
        # the shipped file is what the command writes (regenerate them with
        # `python -m jaxgeo.data` if a generator changes): the same header and
        # faces, and the same vertices to rounding. Not byte for byte: numpy's
        # sin/cos differ by an ulp between builds and CPUs (SIMD paths, ≤ 4 ulp),
        # which changed 52 of 1,391 twin-peak vertices in their last digit here.
        ours, theirs = out.read_text().splitlines(), open(shipped).read().splitlines()
        assert len(ours) == len(theirs), name
        assert [r for r in ours if not r.startswith("v ")] == [
            r for r in theirs if not r.startswith("v ")
        ], name
        a, b = (
            np.array([r.split()[1:] for r in rows if r.startswith("v ")], float)
            for rows in (ours, theirs)
        )
        extent = np.ptp(b, axis=0).max()
        np.testing.assert_allclose(a, b, rtol=0, atol=16 * np.finfo(float).eps * extent)
    assert "faces" in capsys.readouterr().out


@pytest.mark.parametrize("user", [None, "3"])
def test_cli_limits_blas_threads_unless_the_user_set_them(user):
    """`limit_blas_threads` (run by `main`) sets every OpenBLAS already loaded by
    `import jaxgeo` to one thread, and leaves a user's OPENBLAS_NUM_THREADS."""
    import os
    import subprocess
    import sys

    code = (
        "import os, jaxgeo\n"
        "from threadpoolctl import threadpool_info\n"
        "from jaxgeo._cache import limit_blas_threads\n"
        "n = limit_blas_threads()\n"
        "most = max(i['num_threads'] for i in threadpool_info()"
        " if i['user_api'] == 'blas')\n"
        "print(n, os.environ.get('OPENBLAS_NUM_THREADS'), most)\n"
    )
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
    }
    if user:
        env["OPENBLAS_NUM_THREADS"] = user
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    n, value, most = out.stdout.split()
    if user:
        assert (int(n), value) == (0, user)
    else:
        # numpy's and scipy's OpenBLAS are loaded by `import jaxgeo`: both now
        # run one thread (the machine's cores otherwise, 2 here)
        assert (value, int(most)) == ("1", 1) and int(n) >= 1


def test_obj_polylines_round_trip(tmp_path):
    """The one OBJ polyline writer (`format_path`'s "obj" and the pattern
    command's seams.obj): each polyline's coordinates read back bitwise (17
    significant digits) and its `l` element indexes its own vertices."""
    from jaxgeo.export import write_seams_obj

    rng = np.random.default_rng(0)
    lines = [rng.standard_normal((n, 3)) for n in (2, 5, 3)]
    write_seams_obj(lines, tmp_path / "s.obj")
    rows = (tmp_path / "s.obj").read_text().splitlines()
    v = np.array([[float(x) for x in r.split()[1:]] for r in rows if r[:2] == "v "])
    assert np.array_equal(v, np.concatenate(lines))
    elements = [[int(i) for i in r.split()[1:]] for r in rows if r[:2] == "l "]
    assert elements == [[1, 2], [3, 4, 5, 6, 7], [8, 9, 10]]
    assert [r for r in rows if r[:2] == "o "] == ["o seam_0", "o seam_1", "o seam_2"]


def test_fold_warning_names_each_folded_cloth_with_its_count():
    """The CLI's warning names every cloth whose flattening has inverted
    triangles, with the count ("1 triangle" singular), and none otherwise."""
    import re

    from jaxgeo.cli.pattern import _fold_warning

    assert _fold_warning([("A1", 0), ("A2", 0)]) is None
    warning = _fold_warning([("A1", 0), ("B2", 1), ("C3", 12)])
    assert warning is not None and "folds over itself" in warning
    named = dict(re.findall(r"cloth (\w+) \((\d+) triangles?\)", warning))
    assert named == {"B2": "1", "C3": "12"}
    assert "(1 triangle)" in warning and "(12 triangles)" in warning
