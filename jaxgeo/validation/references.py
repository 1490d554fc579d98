"""The references a validation run compares with: the methods of
`jaxgeo.shortest_path` and the exact polyhedral solvers of other packages
(pygeodesic, potpourri3d), and `MethodResult`, one solver run."""

from __future__ import annotations

import typing
from dataclasses import dataclass

import numpy as np

from .._errors import JaxgeoError


def available_methods() -> tuple[str, ...]:
    """The methods `jaxgeo.shortest_path` accepts: `jaxgeo.geodesic.METHODS` if it
    exists, else the arguments of its `Method` literal type, else ("laser",)."""
    from .. import geodesic

    methods = getattr(geodesic, "METHODS", None)
    if methods is None:
        methods = typing.get_args(getattr(geodesic, "Method", None)) or ("laser",)
    return tuple(str(m) for m in methods)


def _pygeodesic(vertices: np.ndarray, faces: np.ndarray):
    import pygeodesic.geodesic as pyg

    alg = pyg.PyGeodesicAlgorithmExact(
        np.ascontiguousarray(vertices, np.float64),
        np.ascontiguousarray(faces, np.int32),
    )
    return lambda i, j: float(alg.geodesicDistance(i, j)[0])


def _potpourri3d(vertices: np.ndarray, faces: np.ndarray):
    import potpourri3d as pp3d

    flip = pp3d.EdgeFlipGeodesicSolver(vertices, faces)

    def dist(i: int, j: int) -> float:
        pts = flip.find_geodesic_path(i, j)
        return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())

    return dist


#: Exact polyhedral solvers, in order of preference: pygeodesic's exact MMP
#: algorithm, then potpourri3d's edge-flip geodesics (started from a Dijkstra path:
#: locally shortest, in practice the shortest on these surfaces).
EXACT_SOLVERS = {"pygeodesic": _pygeodesic, "potpourri3d": _potpourri3d}


def exact_solver(name: str, vertices: np.ndarray, faces: np.ndarray):
    """(solver name, function (i, j) → exact polyhedral distance between vertices),
    or (None, None). `name`: a key of `EXACT_SOLVERS`, "auto" (the first one
    installed) or "none"."""
    if name == "none":
        return None, None
    if name != "auto" and name not in EXACT_SOLVERS:
        raise JaxgeoError(
            f"unknown exact solver {name!r}; expected auto, none or one of "
            f"{list(EXACT_SOLVERS)}"
        )
    for solver in EXACT_SOLVERS if name == "auto" else [name]:
        try:
            return solver, EXACT_SOLVERS[solver](vertices, faces)
        except ImportError:
            continue
    if name != "auto":
        raise JaxgeoError(f"exact solver {name!r} is not installed")
    return None, None


@dataclass(frozen=True)
class MethodResult:
    """One solver run: `length`, `status` (a `jaxgeo.Status` name) and wall time in
    seconds (after compilation)."""

    length: float
    status: str
    time: float
