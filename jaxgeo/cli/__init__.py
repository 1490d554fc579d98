"""The `jaxgeo` command line.

Exit status: 0 on success; 1 when `jaxgeo paths` could not complete some paths (or
`jaxgeo pattern` does not fit the roll); 2 for a usage error or bad input (a
missing option, an unreadable file, a point far from the mesh, a path that cannot
be completed by `jaxgeo path`).
"""

from __future__ import annotations

import argparse
import ast
import inspect
import io
import json
import os
import sys

import numpy as np

EXAMPLE = "catenoid"
#: Default endpoints on the built-in catenoid (rings of radius 1, 1 apart): one on
#: the lower ring, one on the upper ring a third of a turn further on.
EXAMPLE_FROM = (1.0, 0.0, -0.5)
EXAMPLE_TO = (np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3), 0.5)

#: Formats of `jaxgeo path --format` and `jaxgeo paths --points`.
FORMATS = ("json", "csv", "obj")


class UsageError(Exception):
    """A command line that cannot run as given (exit status 2, like argparse)."""


def _default(name: str):
    """The library's default for `shortest_path`'s keyword `name`, so that the
    command line follows the API."""
    from ..geodesic import shortest_path

    return inspect.signature(shortest_path).parameters[name].default


def _load(mesh_arg: str | None):
    from .. import surfaces
    from ..mesh import Mesh, load_mesh

    if mesh_arg is None:
        return Mesh(*surfaces.catenoid()), f"built-in {EXAMPLE}"
    return load_mesh(mesh_arg), mesh_arg


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


def _write(path: str, text: str) -> None:
    from .._errors import JaxgeoError

    try:
        with open(path, "w") as f:
            f.write(text)
    except OSError as e:
        raise JaxgeoError(f"could not write {path}: {e}") from e


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
    mesh, name = _load(args.mesh)
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
            _write(args.output, text)
        else:
            sys.stdout.write(text)
    summary = (
        f"{name}: {mesh.n_faces} faces; {text1} -> {text2}: length "
        f"{float(path.length):.10g}, {int(path.count)} points, "
        f"{int(path.n_branch_points)} branch points, method {args.method}"
        + (f"; {fmt.upper()} written to {args.output}" if args.output else "")
    )
    # stdout carries the summary, unless it carries the data
    data_on_stdout = fmt is not None and not args.output
    print(summary, file=sys.stderr if data_on_stdout else sys.stdout)
    return 0


#: Default `jaxgeo validate` resolution: icosphere of 5120 faces and catenoid of
#: 6144; about 45 s on 2 cores, of which ~35 s is JIT compilation (one per mesh).
VALIDATE_RESOLUTION = 4


def _progress_bar(done: int, total: int, width: int = 30) -> None:
    filled = width * done // total
    end = "\n" if done == total else ""
    bar = "#" * filled + "-" * (width - filled)
    print(f"\r[{bar}] {done}/{total} paths", end=end, file=sys.stderr, flush=True)


def _header_lines(path: str) -> int:
    """Lines to skip before the numbers of a CSV file: comments and blank lines up
    to the first data line, plus that line if it is a header (a field that is not
    a number)."""
    with open(path) as f:
        for n, line in enumerate(f):
            text = line.split("#", 1)[0].strip()
            if not text:
                continue
            try:
                [float(x) for x in text.split(",")]
            except ValueError:
                return n + 1
            return n
    return 0


def read_pairs(path: str, mesh) -> tuple[np.ndarray, np.ndarray]:
    """Endpoint pairs from a CSV file, `(p1, p2)` for `shortest_paths`: rows
    x1,y1,z1,x2,y2,z2 give two `(N, 3)` arrays, rows i,j (vertex indices) two
    integer `(N,)` arrays. A header row and `#` comments are allowed."""
    from .._errors import JaxgeoError

    try:
        pairs = np.loadtxt(
            path,
            delimiter=",",
            ndmin=2,
            comments="#",
            skiprows=_header_lines(path),
        )
    except (OSError, ValueError) as e:
        raise JaxgeoError(f"could not read pairs file {path}: {e}") from e
    if pairs.size == 0:
        raise JaxgeoError(f"{path}: no endpoint pairs")
    if pairs.shape[1] == 2:
        idx = pairs.astype(np.int64)
        if (idx != pairs).any() or (idx < 0).any() or (idx >= mesh.n_vertices).any():
            raise JaxgeoError(
                f"{path}: two columns are vertex indices i,j, integers in "
                f"[0, {mesh.n_vertices})"
            )
        return idx[:, 0], idx[:, 1]
    if pairs.shape[1] != 6:
        raise JaxgeoError(
            f"{path}: each row must be x1,y1,z1,x2,y2,z2 (6 numbers) or i,j (2 "
            f"vertex indices), got {pairs.shape[1]} columns"
        )
    return pairs[:, :3], pairs[:, 3:]


def _points_text(paths, ok: np.ndarray, fmt: str) -> str:
    """The points of a batch: `json` (one object per row), `obj` (one polyline
    per row) or `csv` (long format: row,index,x,y,z). Failed rows are empty."""
    from ..io import path_to_dict
    from ..path import Status

    rows = list(paths)
    if fmt == "json":
        out = []
        for i, row in enumerate(rows):
            if ok[i]:
                out.append({"row": i, **path_to_dict(row)})
            else:
                status = Status(int(row.status)).name.lower()
                out.append(
                    {
                        "row": i,
                        "status": status,
                        "length": None,
                        "count": 0,
                        "points": [],
                    }
                )
        return json.dumps(out, indent=1) + "\n"
    buf = io.StringIO()
    if fmt == "csv":
        buf.write("row,index,x,y,z\n")
        for i, row in enumerate(rows):
            if ok[i]:
                for k, p in enumerate(row.polyline()):
                    buf.write(f"{i},{k},{p[0]:.17g},{p[1]:.17g},{p[2]:.17g}\n")
        return buf.getvalue()
    # obj: vertices of every complete row, then one `l` element per row
    buf.write(f"# jaxgeo paths: {len(rows)} rows, {int(ok.sum())} complete\n")
    base = 1
    for i, row in enumerate(rows):
        if not ok[i]:
            buf.write(f"# row {i}: {Status(int(row.status)).name.lower()}, no path\n")
            continue
        pts = row.polyline()
        buf.write(f"o row{i}\n# length {float(row.length):.17g}\n")
        for p in pts:
            buf.write(f"v {p[0]:.17g} {p[1]:.17g} {p[2]:.17g}\n")
        buf.write("l " + " ".join(str(base + k) for k in range(len(pts))) + "\n")
        base += len(pts)
    return buf.getvalue()


def _cmd_paths(args: argparse.Namespace) -> int:
    from ..batch import shortest_paths
    from ..path import Status

    points_fmt = None
    if args.points:
        points_fmt = os.path.splitext(args.points)[1].lower().lstrip(".")
        if points_fmt not in FORMATS:
            raise UsageError(
                f"--points {args.points}: the extension must be one of "
                f"{', '.join('.' + f for f in FORMATS)}"
            )
    mesh, name = _load(args.mesh)
    p1, p2 = read_pairs(args.pairs, mesh)
    print(f"{name}: {mesh.n_faces} faces; {len(p1)} pairs", file=sys.stderr)
    paths = shortest_paths(
        mesh,
        p1,
        p2,
        method=args.method,
        candidates=args.candidates,
        max_points=args.max_points,
        max_distance=args.max_distance,
        chunk_size=args.chunk_size,
        throw=False,
        progress=_progress_bar,
    )
    ok = np.asarray(paths.status) == Status.SUCCESS
    table = io.StringIO()
    table.write("row,status,length,points\n")
    for i in range(len(p1)):
        status = Status(int(paths.status[i])).name.lower()
        if ok[i]:
            table.write(f"{i},{status},{paths.length[i]:.17g},{int(paths.count[i])}\n")
        else:  # a failed row has no length: empty, never a number
            table.write(f"{i},{status},,\n")
    if args.output:
        _write(args.output, table.getvalue())
    else:
        sys.stdout.write(table.getvalue())
    if points_fmt is not None:
        _write(args.points, _points_text(paths, ok, points_fmt))
    failed = np.flatnonzero(~ok)
    summary = f"{len(p1) - failed.size} paths complete, {failed.size} failed"
    if failed.size:
        codes = sorted({Status(int(paths.status[i])).name.lower() for i in failed})
        shown = ", ".join(str(i) for i in failed[:10])
        more = ", ..." if failed.size > 10 else ""
        rows = "row" if failed.size == 1 else "rows"
        summary += f" ({', '.join(codes)}; {rows} {shown}{more}: lengths left empty)"
    written = [f for f in (args.output, args.points) if f]
    if written:
        summary += "; written to " + " and ".join(written)
    print(summary, file=sys.stderr if not args.output else sys.stdout)
    return 0 if failed.size == 0 else 1


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
    from ..mesh import load_mesh

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

    from .. import validation

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


def build_parser() -> argparse.ArgumentParser:
    from ..surfaces import SURFACES

    parser = argparse.ArgumentParser(
        prog="jaxgeo",
        description="Differentiable geodesics on triangle meshes. Coordinates and "
        "lengths are in the mesh's units.",
        epilog="Exit status: 0 success; 1 some paths of `paths` failed (or a "
        "pattern does not fit); 2 usage error or bad input.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser(
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
    _add_solver_options(p)
    p.set_defaults(func=_cmd_path, parser=p)

    b = sub.add_parser(
        "paths",
        help="trace many geodesics from a CSV of endpoint pairs",
        description="Trace the geodesics between the endpoint pairs of a CSV file "
        "in vmapped chunks and write row,status,length,points (number of points) "
        "as CSV; failed rows have empty length and points. Progress and the count "
        "of failed paths go to stderr. Exit status 1 if any path failed.",
    )
    b.add_argument("mesh", help="mesh file (OBJ, PLY, STL, OFF, ...)")
    b.add_argument(
        "pairs",
        help="CSV file, one pair per row: x1,y1,z1,x2,y2,z2 (points) or i,j (vertex "
        "indices, 0-based); a header row and # comments are allowed",
    )
    b.add_argument(
        "--output",
        "-o",
        metavar="FILE",
        help="write the CSV table here (default stdout)",
    )
    b.add_argument(
        "--points",
        metavar="FILE",
        help="also write the paths' points, format by extension: .json (one object "
        "per row), .obj (one polyline per row) or .csv (row,index,x,y,z); failed "
        "rows are left empty",
    )
    _add_solver_options(b)
    b.add_argument(
        "--chunk-size",
        type=int,
        default=256,
        metavar="N",
        help="pairs solved per compiled call (bounds memory); default 256",
    )
    b.set_defaults(func=_cmd_paths, parser=b)

    s = sub.add_parser(
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
        help="exact polyhedral reference: auto (pygeodesic, else potpourri3d), "
        "pygeodesic, potpourri3d or none; default auto",
    )
    v.add_argument("--csv", metavar="FILE", help="also write the table as CSV")
    v.add_argument(
        "--markdown", metavar="FILE", help="also write the table as Markdown"
    )
    v.add_argument(
        "--plot",
        metavar="FILE",
        help="convergence plot (PNG) for several resolutions "
        "(default jaxgeo-convergence.png)",
    )
    v.add_argument("--quiet", "-q", action="store_true", help="no progress output")
    v.set_defaults(func=_cmd_validate, parser=v)

    from .pattern import add_pattern_parser

    add_pattern_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    import jax

    from .._cache import enable_compilation_cache
    from .._errors import JaxgeoError

    jax.config.update("jax_enable_x64", True)
    # Compiled solvers are cached on disk: the second run of a command skips the
    # JIT compilation that dominates a short run.
    enable_compilation_cache()
    try:
        args = build_parser().parse_args(argv)
        try:
            return args.func(args)
        except UsageError as e:
            args.parser.error(str(e))  # prints the usage; exits with status 2
        except JaxgeoError as e:
            print(f"jaxgeo: error: {e}", file=sys.stderr)
            return 2
    except SystemExit as e:  # argparse: --help (0) and usage errors (2)
        return e.code if isinstance(e.code, int) else 2
    return 0
