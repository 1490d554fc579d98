"""`jaxgeo path`: one geodesic between two points, a one-line summary and the
polyline as JSON, CSV or OBJ."""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from .common import FORMATS, UsageError, add_solver_options, load_mesh_arg, write_text

#: Default endpoints on the built-in catenoid (rings of radius 1, 1 apart): one on
#: the lower ring, one on the upper ring a third of a turn further on.
EXAMPLE_FROM = (1.0, 0.0, -0.5)
EXAMPLE_TO = (np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3), 0.5)


def _fmt(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in p) + ")"


def _endpoint(mesh, point, vertex, default, option: str):
    """(endpoint for the API, text for the summary) from --from/--to or
    --from-vertex/--to-vertex (an integer: the API reads it as a vertex index)."""
    if vertex is not None:
        from .._checks import check_point

        check_point(option, vertex, mesh)  # JaxgeoError naming the option
        return vertex, f"vertex {vertex} {_fmt(np.asarray(mesh.vertices[vertex]))}"
    p = np.asarray(point if point is not None else default, dtype=np.float64)
    return p, _fmt(p)


def _format_of(output: str | None, given: str | None) -> str | None:
    """--format if given, else the output file's extension if it is a format,
    else json for a file; None when nothing asks for data."""
    if given is not None:
        return given
    if output is None:
        return None
    ext = os.path.splitext(output)[1].lower().lstrip(".")
    return ext if ext in FORMATS else "json"


def _cmd_path(args: argparse.Namespace) -> int:
    from ..geodesic import shortest_path
    from ..io import format_path

    if args.mesh is not None and not (
        (args.from_ is not None or args.from_vertex is not None)
        and (args.to is not None or args.to_vertex is not None)
    ):
        raise UsageError(
            "with a MESH, give both ends: --from X Y Z or --from-vertex I, and "
            "--to X Y Z or --to-vertex J"
        )
    mesh, name = load_mesh_arg(args.mesh)
    p1, text1 = _endpoint(
        mesh, args.from_, args.from_vertex, EXAMPLE_FROM, "--from-vertex"
    )
    p2, text2 = _endpoint(mesh, args.to, args.to_vertex, EXAMPLE_TO, "--to-vertex")
    path = shortest_path(
        mesh,
        p1,
        p2,
        method=args.method,
        candidates=args.candidates,
        max_points=args.max_points,
        max_distance=args.max_distance,
    )
    fmt = _format_of(args.output, args.format)
    if fmt is not None:
        text = format_path(path, fmt)
        text = text if text.endswith("\n") else text + "\n"
        if args.output:
            write_text(args.output, text)
        else:
            sys.stdout.write(text)
    summary = (
        f"{name}: {mesh.n_faces} faces; {text1} -> {text2}: length "
        f"{float(path.length):.10g}, {int(path.count)} points, "
        f"{int(path.n_branch_points)} branch points, method {args.method}"
        + (f"; {fmt.upper()} written to {args.output}" if args.output and fmt else "")
    )
    # stdout carries the summary, unless it carries the data
    data_on_stdout = fmt is not None and not args.output
    print(summary, file=sys.stderr if data_on_stdout else sys.stdout)
    return 0


def add_path_parser(subparsers) -> argparse.ArgumentParser:
    """The `path` subcommand."""
    p = subparsers.add_parser(
        "path",
        help="trace the geodesic between two points",
        description="Trace the geodesic between two points of a mesh and print a "
        "one-line summary (length, points, method); the polyline itself with "
        "--format or -o. Without MESH: a built-in catenoid (rings of radius 1 at "
        "z = -0.5 and 0.5) and default endpoints on its two rings.",
    )
    p.add_argument(
        "mesh", nargs="?", help="mesh file (OBJ, PLY, STL, OFF, ...); see `surface`"
    )
    start = p.add_mutually_exclusive_group()
    start.add_argument(
        "--from",
        dest="from_",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="start point, near the surface (moved to the nearest mesh point); "
        f"default on the built-in catenoid {_fmt(np.asarray(EXAMPLE_FROM))}",
    )
    start.add_argument(
        "--from-vertex",
        type=int,
        metavar="I",
        help="start at mesh vertex I (0-based index into the file's vertices)",
    )
    end = p.add_mutually_exclusive_group()
    end.add_argument(
        "--to",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="end point, near the surface; default on the built-in catenoid "
        f"{_fmt(np.asarray(EXAMPLE_TO))}",
    )
    end.add_argument(
        "--to-vertex", type=int, metavar="J", help="end at mesh vertex J (0-based)"
    )
    p.add_argument(
        "--format",
        choices=FORMATS,
        default=None,
        help="write the polyline as json (points, kinds, elements, edge "
        "parameters, length, status), csv (x,y,z,kind,element,param per point) or "
        "obj (vertices and one `l` polyline); default: from the -o extension, "
        "else json; without -o or --format only the summary is printed",
    )
    p.add_argument(
        "--output",
        "-o",
        metavar="FILE",
        help="write the polyline to FILE (default: to stdout if --format is given)",
    )
    add_solver_options(p)
    p.set_defaults(func=_cmd_path, parser=p)
    return p
