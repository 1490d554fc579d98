"""`jaxgeo validate`: the validation suites (sphere, catenoid) and their table,
convergence summary and plot."""

from __future__ import annotations

import argparse
import sys

#: Default `jaxgeo validate` resolution: icosphere of 5120 faces and catenoid of
#: 6144; about 45 s on 2 cores, of which ~35 s is JIT compilation (one per mesh).
VALIDATE_RESOLUTION = 4


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


def add_validate_parser(subparsers) -> argparse.ArgumentParser:
    """The `validate` subcommand."""
    v = subparsers.add_parser(
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
    return v
