"""`jaxgeo surface`: write a built-in surface of `jaxgeo.surfaces` to a mesh
file."""

from __future__ import annotations

import argparse
import ast


def _parameter(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key.isidentifier():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        return key, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        raise argparse.ArgumentTypeError(
            f"{key}: expected a number, got {value!r}"
        ) from None


def _cmd_surface(args: argparse.Namespace) -> int:
    from .. import surfaces
    from ..loading import load_mesh

    params = dict(args.params)
    out = args.output or f"{args.name}.obj"
    surfaces.save(args.name, out, **params)
    mesh = load_mesh(out)
    call = ", ".join(f"{k}={v!r}" for k, v in params.items())
    print(
        f"{out}: surfaces.{args.name}({call}), {mesh.n_faces} faces, "
        f"{mesh.n_vertices} vertices"
    )
    return 0


def add_surface_parser(subparsers) -> argparse.ArgumentParser:
    """The `surface` subcommand."""
    from ..surfaces import SURFACES

    s = subparsers.add_parser(
        "surface",
        help="write a built-in surface to a mesh file",
        description="Write a built-in surface of jaxgeo.surfaces to a file, e.g. "
        "`jaxgeo surface cone_tent n_around=48 n_radial=12 -o tent.obj` (the "
        "shipped example mesh jaxgeo.example_mesh_path('cone_tent')).",
    )
    s.add_argument("name", choices=sorted(SURFACES), help="the surface")
    s.add_argument(
        "params",
        nargs="*",
        type=_parameter,
        metavar="KEY=VALUE",
        help="keyword arguments of the generator (see help(jaxgeo.surfaces.NAME)); "
        "default: its defaults",
    )
    s.add_argument(
        "--output",
        "-o",
        metavar="FILE",
        help="the file; its extension picks the format (.obj, .ply, .stl, .off); "
        "default NAME.obj",
    )
    s.set_defaults(func=_cmd_surface, parser=s)
    return s
