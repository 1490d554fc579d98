"""The `jaxgeo` command line."""

import json

import numpy as np
import trimesh

from jaxgeo.cli import main

from .helpers import unit_icosphere


def test_path_on_builtin_example_prints_json(capsys):
    assert main(["path"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "success"
    # the built-in catenoid's ring points are 1 apart in z: the path is longer
    assert out["length"] > 1.0
    pts = np.array(out["points"])
    assert pts.shape == (out["count"], 3)
    np.testing.assert_allclose(pts[0], [1.0, 0.0, -0.5], atol=1e-12)


def test_path_on_mesh_file_writes_obj(tmp_path, capsys):
    mesh = unit_icosphere(2)
    file = tmp_path / "sphere.obj"
    trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)).export(file)
    out = tmp_path / "seam.obj"
    code = main(
        [
            "path",
            str(file),
            "--from",
            "1",
            "0",
            "0",
            "--to",
            "0",
            "1",
            "0",
            "--format",
            "obj",
            "-o",
            str(out),
        ]
    )
    assert code == 0
    text = out.read_text()
    n_v = sum(1 for line in text.splitlines() if line.startswith("v "))
    line = [ln for ln in text.splitlines() if ln.startswith("l ")][0]
    assert len(line.split()) - 1 == n_v >= 2
    assert "length" in capsys.readouterr().err


def test_far_point_is_a_clear_error(tmp_path, capsys):
    mesh = unit_icosphere(2)
    file = tmp_path / "sphere.obj"
    trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)).export(file)
    code = main(["path", str(file), "--from", "0", "0", "5", "--to", "0", "1", "0"])
    assert code == 2
    assert "too far from the surface" in capsys.readouterr().err


def test_paths_batch_from_csv(tmp_path, capsys):
    mesh = unit_icosphere(2)
    file = tmp_path / "sphere.obj"
    trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)).export(file)
    rng = np.random.default_rng(0)
    p = rng.normal(size=(5, 2, 3))
    p /= np.linalg.norm(p, axis=-1, keepdims=True)
    pairs = tmp_path / "pairs.csv"
    np.savetxt(pairs, p.reshape(5, 6), delimiter=",", header="x1,y1,z1,x2,y2,z2")
    out = tmp_path / "lengths.csv"
    code = main(["paths", str(file), str(pairs), "-o", str(out), "--chunk-size", "4"])
    assert code == 0
    rows = out.read_text().splitlines()
    assert rows[0] == "row,status,length,points" and len(rows) == 6
    assert all(r.split(",")[1] == "success" for r in rows[1:])
    err = capsys.readouterr().err
    assert "5/5 paths" in err and "5 paths complete, 0 failed" in err
