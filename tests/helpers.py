"""Shared test helpers: small meshes and random surface points."""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import numpy as np
import pytest
import trimesh

import jaxgeo as jg


@functools.cache
def unit_icosphere(subdivisions: int) -> jg.Mesh:
    """Icosphere of radius 1 with every vertex exactly on the sphere."""
    tm = trimesh.creation.icosphere(subdivisions)
    v = tm.vertices / np.linalg.norm(tm.vertices, axis=1, keepdims=True)
    return jg.Mesh(v, tm.faces)


def face_points(mesh: jg.Mesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """`n` points strictly inside random faces (not vertices, not on edges):
    returns (faces, barycentrics)."""
    rng = np.random.default_rng(seed)
    faces = rng.integers(0, mesh.n_faces, n)
    bary = rng.dirichlet([3.0, 3.0, 3.0], n)
    bary = 0.1 + 0.7 * bary  # keep away from edges, then renormalise
    return faces, bary / bary.sum(1, keepdims=True)


def position(mesh: jg.Mesh, face: int, bary: np.ndarray) -> np.ndarray:
    return np.asarray(bary) @ np.asarray(mesh.vertices)[np.asarray(mesh.faces)[face]]


def great_circle(p: np.ndarray, q: np.ndarray) -> float:
    """Great-circle length between the radial projections of p and q on the unit
    sphere (atan2 form: accurate near 0 and π)."""
    p, q = p / np.linalg.norm(p), q / np.linalg.norm(q)
    return float(np.arctan2(np.linalg.norm(np.cross(p, q)), p @ q))


def package_mesh(relpath: str) -> Path:
    """The path of a mesh file shipped inside an installed package, e.g.
    `"pymeshlab/tests/sample_meshes/cow.obj"`, found without importing the package
    (pymeshlab loads Qt and MeshLab's plugins on import). Skips the test when the
    package is not installed (the `dev` extra installs pymeshlab and compas; their
    wheels do not exist for every platform)."""
    package, _, inner = relpath.partition("/")
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        pytest.skip(f"{package} is not installed (it ships {inner})")
    for root in spec.submodule_search_locations:
        path = Path(root) / inner
        if path.is_file():
            return path
    raise FileNotFoundError(f"{package} is installed but holds no {inner}")
