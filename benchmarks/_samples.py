"""Real meshes shipped inside installed packages, for the benchmarks."""

from __future__ import annotations

import importlib.util
from pathlib import Path


def pymeshlab_sample(name: str) -> Path | None:
    """The path of a sample mesh in pymeshlab's wheel (`tests/sample_meshes`),
    found without importing pymeshlab (it loads Qt and MeshLab's plugins on
    import), or None when pymeshlab or the file is missing."""
    spec = importlib.util.find_spec("pymeshlab")
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        path = Path(root) / "tests" / "sample_meshes" / name
        if path.is_file():
            return path
    return None


def referenced(mesh):
    """`mesh` without its unreferenced vertices (pygeodesic and potpourri3d
    refuse them; some sample files have them). Imports inside: the scripts
    enable x64 before jaxgeo is imported."""
    import numpy as np
    import trimesh

    import jaxgeo as jg

    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    tm = trimesh.Trimesh(v, f, process=False)
    tm.remove_unreferenced_vertices()
    return jg.Mesh(tm.vertices, tm.faces)
