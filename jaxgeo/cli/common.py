"""What the subcommands `jaxgeo path` and `jaxgeo paths` share: the usage error,
the data formats, loading the mesh argument, writing a file and the solver options."""

from __future__ import annotations

import argparse
import inspect

#: The built-in mesh of `jaxgeo path` without a MESH.
EXAMPLE = "catenoid"

#: Formats of `jaxgeo path --format` and `jaxgeo paths --points`.
FORMATS = ("json", "csv", "obj")


class UsageError(Exception):
    """A command line that cannot run as given (exit status 2, like argparse)."""


def _default(name: str):
    """The library's default for `shortest_path`'s keyword `name`, so that the
    command line follows the API."""
    from ..geodesic import shortest_path

    return inspect.signature(shortest_path).parameters[name].default


def load_mesh_arg(mesh_arg: str | None):
    """(mesh, its name for the summary): the file MESH, or the built-in catenoid."""
    from .. import surfaces
    from ..loading import load_mesh
    from ..mesh import Mesh

    if mesh_arg is None:
        return Mesh(*surfaces.catenoid()), f"built-in {EXAMPLE}"
    return load_mesh(mesh_arg), mesh_arg


def write_text(path: str, text: str) -> None:
    """Write an output file; failing to is a JaxgeoError (exit status 2)."""
    from .._errors import JaxgeoError

    try:
        with open(path, "w") as f:
            f.write(text)
    except OSError as e:
        raise JaxgeoError(f"could not write {path}: {e}") from e


def add_solver_options(parser: argparse.ArgumentParser) -> None:
    from ..geodesic import METHODS

    method = _default("method")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=method,
        help="exact (the exact polyhedral geodesic), laser (the paper's sliding "
        "laser ray) or smooth (the geodesic of the Phong surface); "
        f"default {method}",
    )
    candidates = _default("candidates")
    parser.add_argument(
        "--candidates",
        choices=("local", "all"),
        default=candidates,
        help="edges tried at each step of the trace: local (the faces around the "
        "current point) or all (every edge, as in the paper; slower); "
        f"default {candidates}",
    )
    max_points = _default("max_points")
    parser.add_argument(
        "--max-points",
        type=int,
        default=max_points,
        metavar="N",
        help=f"capacity of a path in points, endpoints included; default {max_points}",
    )
    max_distance = _default("max_distance")
    parser.add_argument(
        "--max-distance",
        type=float,
        default=max_distance,
        metavar="D",
        help="largest distance of a 3-D endpoint from the mesh, in mean edge "
        f"lengths (it is moved to the nearest mesh point); default {max_distance}",
    )
