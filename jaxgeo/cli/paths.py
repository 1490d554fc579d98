"""`jaxgeo paths`: many geodesics from a CSV file of endpoint pairs, a CSV table of
their lengths and, optionally, their points."""

from __future__ import annotations

import argparse
import io
import json
import os
import sys

import numpy as np

from .common import FORMATS, UsageError, add_solver_options, load_mesh_arg, write_text


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
    mesh, name = load_mesh_arg(args.mesh)
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
        write_text(args.output, table.getvalue())
    else:
        sys.stdout.write(table.getvalue())
    if points_fmt is not None:
        write_text(args.points, _points_text(paths, ok, points_fmt))
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


def add_paths_parser(subparsers) -> argparse.ArgumentParser:
    """The `paths` subcommand."""
    b = subparsers.add_parser(
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
    add_solver_options(b)
    b.add_argument(
        "--chunk-size",
        type=int,
        default=256,
        metavar="N",
        help="pairs solved per compiled call (bounds memory); default 256",
    )
    b.set_defaults(func=_cmd_paths, parser=b)
    return b
