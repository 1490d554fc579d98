"""The `jaxgeo` command line."""

from __future__ import annotations

import argparse
import sys

import numpy as np

EXAMPLE = "catenoid"
#: Default endpoints on the built-in catenoid (rings of radius 1, 1 apart): one on
#: the lower ring, one on the upper ring a third of a turn further on.
EXAMPLE_FROM = (1.0, 0.0, -0.5)
EXAMPLE_TO = (np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3), 0.5)


def _load(mesh_arg: str | None):
    from . import surfaces
    from .mesh import Mesh, load_mesh

    if mesh_arg is None:
        return Mesh(*surfaces.catenoid()), f"built-in {EXAMPLE}"
    return load_mesh(mesh_arg), mesh_arg


def _fmt(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in p) + ")"


def _cmd_path(args: argparse.Namespace) -> int:
    from .geodesic import shortest_path
    from .io import format_path

    mesh, name = _load(args.mesh)
    p1 = np.asarray(args.from_ if args.from_ else EXAMPLE_FROM, dtype=np.float64)
    p2 = np.asarray(args.to if args.to else EXAMPLE_TO, dtype=np.float64)
    if args.mesh is not None and (args.from_ is None or args.to is None):
        raise SystemExit("jaxgeo path: --from and --to are required with a MESH")
    path = shortest_path(mesh, p1, p2, method=args.method, candidates=args.candidates)
    text = format_path(path, args.format)
    if args.output:
        with open(args.output, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    # The summary goes to stderr, so stdout carries the data alone.
    print(
        f"{name}: {mesh.n_faces} faces; path {_fmt(p1)} -> {_fmt(p2)}\n"
        f"length {float(path.length):.10g} ({int(path.count)} points, "
        f"{int(path.n_branch_points)} branch points, method {args.method})"
        + (f"; written to {args.output}" if args.output else ""),
        file=sys.stderr,
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxgeo", description="Differentiable geodesics on triangle meshes."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser(
        "path",
        help="trace the geodesic between two points",
        description="Trace the geodesic between two points of a mesh and print its "
        "length; without MESH, a built-in catenoid with default endpoints.",
    )
    p.add_argument("mesh", nargs="?", help="mesh file (OBJ, PLY, STL, OFF, ...)")
    p.add_argument("--from", dest="from_", nargs=3, type=float, metavar=("X", "Y", "Z"))
    p.add_argument("--to", nargs=3, type=float, metavar=("X", "Y", "Z"))
    p.add_argument("--format", choices=("json", "csv", "obj"), default="json")
    p.add_argument("--output", "-o", help="write the polyline here (default stdout)")
    p.add_argument("--method", default="laser", help="laser (the paper's method)")
    p.add_argument("--candidates", choices=("local", "all"), default="local")
    p.set_defaults(func=_cmd_path)
    return parser


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from ._errors import JaxgeoError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except JaxgeoError as e:
        print(f"jaxgeo: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
