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
