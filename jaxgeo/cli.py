"""The `jaxgeo` command line."""

from __future__ import annotations

import argparse
import os
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


#: Default `jaxgeo validate` resolution: icosphere of 5120 faces and catenoid of
#: 6144; about 45 s on 2 cores, of which ~35 s is JIT compilation (one per mesh).
VALIDATE_RESOLUTION = 4


def _progress_bar(done: int, total: int, width: int = 30) -> None:
    filled = width * done // total
    end = "\n" if done == total else ""
    bar = "#" * filled + "-" * (width - filled)
    print(f"\r[{bar}] {done}/{total} paths", end=end, file=sys.stderr, flush=True)


def _cmd_paths(args: argparse.Namespace) -> int:
    from ._errors import JaxgeoError
    from .batch import shortest_paths
    from .path import Status

    mesh, name = _load(args.mesh)
    try:
        pairs = np.loadtxt(args.pairs, delimiter=",", ndmin=2, comments="#")
    except (OSError, ValueError) as e:
        raise JaxgeoError(f"could not read pairs file {args.pairs}: {e}") from e
    if pairs.shape[1] != 6:
        raise JaxgeoError(
            f"{args.pairs}: each row must be x1,y1,z1,x2,y2,z2 (6 numbers), "
            f"got {pairs.shape[1]}"
        )
    print(f"{name}: {mesh.n_faces} faces; {len(pairs)} pairs", file=sys.stderr)
    paths = shortest_paths(
        mesh,
        pairs[:, :3],
        pairs[:, 3:],
        method=args.method,
        candidates=args.candidates,
        chunk_size=args.chunk_size,
        throw=False,
        progress=_progress_bar,
    )
    out = open(args.output, "w") if args.output else sys.stdout
    try:
        out.write("row,status,length,points\n")
        for i in range(len(pairs)):
            status = Status(int(paths.status[i])).name.lower()
            out.write(f"{i},{status},{paths.length[i]:.17g},{int(paths.count[i])}\n")
    finally:
        if args.output:
            out.close()
    failed = int(np.sum(paths.status != Status.SUCCESS))
    print(f"{len(pairs) - failed} paths complete, {failed} failed", file=sys.stderr)
    return 0 if failed == 0 else 1


def _resolutions(text: str) -> list[int]:
    try:
        out = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected integers separated by commas, got {text!r}"
        ) from None
    if not out:
        raise argparse.ArgumentTypeError("no resolution given")
    return out


def _names(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


def _cmd_validate(args: argparse.Namespace) -> int:
    import time

    from . import validation

    def progress(line: str) -> None:
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    table = validation.validate(
        args.resolution,
        suites=args.suite,
        methods=args.methods,
        exact_solver=args.exact,
        progress=progress,
    )
    text = table.to_markdown()
    summary = None
    if len(args.resolution) > 1:
        summary = validation.convergence_summary(table)
        text += (
            "\nConvergence (median |relative error| over the pairs):\n\n"
            + validation.summary_markdown(summary, table.methods)
        )
    sys.stdout.write(text)
    if args.csv:
        table.to_csv(args.csv)
        progress(f"table written to {args.csv}")
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(text)
        progress(f"Markdown written to {args.markdown}")
    if summary is not None:
        plot = args.plot or "jaxgeo-convergence.png"
        validation.plot_convergence(summary, table.methods, plot)
        progress(f"convergence plot written to {plot}")
    progress(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


def _add_solver_options(parser: argparse.ArgumentParser) -> None:
    from .geodesic import METHODS

    parser.add_argument(
        "--method",
        choices=METHODS,
        default="laser",
        help="laser (the paper's method, default), exact (polyhedral geodesic) or "
        "smooth (geodesic of the Phong surface)",
    )
    parser.add_argument("--candidates", choices=("local", "all"), default="local")


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
    _add_solver_options(p)
    p.set_defaults(func=_cmd_path)

    b = sub.add_parser(
        "paths",
        help="trace many geodesics from a CSV of endpoint pairs",
        description="Trace the geodesics between the endpoint pairs of a CSV file "
        "(rows x1,y1,z1,x2,y2,z2) in vmapped chunks; writes row,status,length,"
        "points as CSV. Exit status 1 if any path failed.",
    )
    b.add_argument("mesh", help="mesh file (OBJ, PLY, STL, OFF, ...)")
    b.add_argument("pairs", help="CSV file with rows x1,y1,z1,x2,y2,z2")
    b.add_argument("--output", "-o", help="write the CSV here (default stdout)")
    _add_solver_options(b)
    b.add_argument("--chunk-size", type=int, default=256)
    b.set_defaults(func=_cmd_paths)

    v = sub.add_parser(
        "validate",
        help="compare with analytic geodesics on a sphere and a catenoid",
        description="Run the validation suites (unit icosphere: great circles; "
        "catenoid between rings of radius 1 at distance 1: Clairaut geodesics) and "
        "print the table: analytic length, exact polyhedral length (the shortest "
        "path on the mesh itself), each method's length, its total error and its "
        "method error (vs the exact polyhedral length). Progress goes to stderr.",
    )
    v.add_argument(
        "--resolution",
        type=_resolutions,
        default=[VALIDATE_RESOLUTION],
        metavar="R[,R...]",
        help="refinement level(s), >= 3: icosphere with 20*4**R faces, catenoid "
        f"of 6*2**R x 2**(R+1) vertices (default {VALIDATE_RESOLUTION}); several "
        "levels run a convergence study and write a log-log plot",
    )
    v.add_argument(
        "--suite",
        type=_names,
        default=["sphere", "catenoid"],
        metavar="NAME[,NAME]",
        help="sphere, catenoid or both (default both)",
    )
    v.add_argument(
        "--methods",
        type=_names,
        default=None,
        metavar="M[,M...]",
        help="shortest_path methods to run (default: all that it accepts)",
    )
    v.add_argument(
        "--exact",
        default="auto",
        help="exact polyhedral reference: auto, pygeodesic, potpourri3d or none",
    )
    v.add_argument("--csv", metavar="FILE", help="write the table as CSV")
    v.add_argument("--markdown", metavar="FILE", help="write the table as Markdown")
    v.add_argument(
        "--plot",
        metavar="FILE",
        help="convergence plot (PNG) for several resolutions "
        "(default jaxgeo-convergence.png)",
    )
    v.add_argument("--quiet", "-q", action="store_true", help="no progress output")
    v.set_defaults(func=_cmd_validate)

    from ._pattern_cli import add_pattern_parser

    add_pattern_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    # Compiled solvers are cached on disk: the second run of a command skips the
    # JIT compilation that dominates a short run.
    cache = os.environ.get(
        "JAX_COMPILATION_CACHE_DIR",
        os.path.join(os.path.expanduser("~"), ".cache", "jaxgeo", "xla"),
    )
    jax.config.update("jax_compilation_cache_dir", cache)
    from ._errors import JaxgeoError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except JaxgeoError as e:
        print(f"jaxgeo: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
