"""`jaxgeo pattern MESH --seams N --roll-width W --out DIR`: seam layout and its
optimisation (for roll width and equal seams, or `--objective stress` for the
reassembly stress deviation), cut cloths with prestress compensation and
allowances (DXF, SVG), the reassembly stress check (figure, JSON report) and the
seams (OBJ).

Exit codes: 0 the pattern fits the roll, 1 the stress optimisation could not
start (a seam or a flattening failed), 2 usage error, 3 the pattern does not fit
the roll (the message names the widest cloth and suggests a seam count)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

#: exit code of a pattern whose widest cloth is wider than the roll
DOES_NOT_FIT = 3


def _floats(n: int, what: str):
    def parse(text: str) -> tuple[float, ...]:
        try:
            v = tuple(float(t) for t in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what}: not numbers: {text!r}") from None
        if len(v) == 1 and n == 2:
            v = v * 2
        if len(v) != n:
            raise argparse.ArgumentTypeError(
                f"{what}: expected {n} comma-separated numbers, got {text!r}"
            )
        if not all(math.isfinite(x) for x in v):
            raise argparse.ArgumentTypeError(f"{what}: not finite: {text!r}")
        return v

    return parse


def _fold_warning(inverted: list[tuple[str, int]]) -> str | None:
    """The warning for the cloths (name, inverted triangles) whose flattening
    folds, or None if none does."""
    folded = [(name, n) for name, n in inverted if n]
    if not folded:
        return None
    return (
        "jaxgeo pattern: warning: the flattening of "
        + ", ".join(
            f"cloth {name} ({n} triangle{'s' if n > 1 else ''})" for name, n in folded
        )
        + " folds over itself (inverted triangles): too curved to lie flat "
        "without folds; more seams through it would split it"
    )


def add_pattern_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "pattern",
        help="optimise geodesic seams on a membrane mesh and write cutting patterns",
        description=__doc__,
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("mesh", help="mesh file (OBJ, PLY, STL, OFF, …) of an open tent")
    p.add_argument("--seams", type=int, required=True, help="seams (per peak ring)")
    p.add_argument(
        "--roll-width", type=float, required=True, help="fabric roll width (m)"
    )
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument(
        "--valley",
        type=int,
        default=3,
        help="two peak rings (3 boundary loops): seams from ring to ring "
        "across the valley (jaxgeo.seams.bridged_layout)",
    )
    p.add_argument("--steps", type=int, default=25, help="BFGS steps per round")
    p.add_argument("--rounds", type=int, default=3, help="calibration rounds")
    p.add_argument(
        "--method",
        choices=("exact", "laser", "smooth"),
        default="exact",
        help="geodesic method of the final seams (both optimisations move "
        "seams with the laser method, whose points are differentiable)",
    )
    p.add_argument(
        "--objective",
        choices=("width", "stress"),
        default="width",
        help="what the seam optimisation minimises: roll fit and equal seams "
        "(width), or the RMS reassembly stress deviation plus waste and roll "
        "fit (stress: jaxgeo.cutting.optimise_seams, BFGS; each step is one "
        "gradient of the whole cut, so use few --steps and --rounds)",
    )
    p.add_argument(
        "--direction",
        type=float,
        default=0.0,
        help="plan direction (degrees from x) of the parallel seams of a mesh "
        "with one boundary loop (a four-point sail)",
    )
    p.add_argument(
        "--compensation",
        type=_floats(2, "--compensation"),
        default=(0.0, 0.0),
        metavar="WARP,WEFT",
        help="prestress compensation (%%): the cloth is cut smaller by this strain",
    )
    p.add_argument(
        "--prestress",
        type=_floats(2, "--prestress"),
        default=(2.0, 2.0),
        metavar="WARP,WEFT",
        help="design prestress (kN/m)",
    )
    p.add_argument(
        "--material",
        type=_floats(4, "--material"),
        default=(600.0, 400.0, 0.3, 30.0),
        metavar="EW,EF,NU,G",
        help="orthotropic membrane: warp and weft moduli (kN/m), Poisson ratio "
        "ν_wf, shear modulus (kN/m)",
    )
    p.add_argument(
        "--allowance",
        type=_floats(2, "--allowance"),
        default=(0.0, 0.0),
        metavar="WELD[,BOUNDARY]",
        help="allowances (m) outside weld lines and boundary lines",
    )
    p.add_argument(
        "--warp",
        choices=("principal", "strip"),
        default="principal",
        help="warp direction of each cloth: its principal axis, or the "
        "direction of its strip of least width",
    )
    p.add_argument(
        "--report", default=None, help="JSON report path (default OUT/report.json)"
    )
    p.set_defaults(func=run_pattern)
    return p


def _usage(msg: str) -> int:
    print(f"jaxgeo pattern: {msg}", file=sys.stderr)
    return 2


def run_pattern(args: argparse.Namespace) -> int:
    import numpy as np

    from .._errors import JaxgeoError
    from ..boundary import boundary_loops
    from ..cutting import (
        Compensation,
        Material,
        Prestress,
        Settings,
        compensate_pattern,
        layout as lay,
        optimise_seams,
        reassemble,
    )
    from ..cutting.cut import cut as cut_layout
    from ..cutting.export import write_dxf, write_svg
    from ..cutting.fabricate import make_pieces, weld_mismatch
    from ..cutting.plots import deviation_figure
    from ..cutting.seam_width import fit_roll
    from ..export import write_seams_obj
    from ..loading import load_mesh

    if args.seams < 1 or args.rounds < 1 or not args.roll_width > 0:
        return _usage("--seams and --rounds must be >= 1 and --roll-width > 0")
    try:
        material = Material(*args.material)
        prestress = Prestress(*args.prestress)
        compensation = Compensation(*args.compensation)
    except JaxgeoError as e:
        return _usage(str(e))
    t0 = time.time()

    def log(msg: str) -> None:
        print(f"[{time.time() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        mesh = load_mesh(args.mesh)
    except (JaxgeoError, OSError, ValueError) as e:
        return _usage(f"cannot read {args.mesh}: {e}")
    loops = boundary_loops(mesh)
    log(f"{args.mesh}: {mesh.n_faces} faces, {len(loops)} boundary loops")
    if len(loops) == 1:
        layout = lay.parallel_layout(mesh, args.seams, args.direction)
    elif len(loops) == 2:
        layout = lay.radial_layout(mesh, args.seams)
    elif len(loops) == 3:
        layout = lay.bridged_layout(mesh, args.seams, args.valley)
    else:
        return _usage(
            f"need a membrane with 1, 2 or 3 boundary loops, {args.mesh} has "
            f"{len(loops)}"
        )
    log(f"{layout.n_seams} seams; tracing (the first call compiles, ~40 s)")
    if args.objective == "width":
        first, layout, pat, history = fit_roll(
            mesh,
            layout,
            args.roll_width,
            rounds=args.rounds,
            steps=args.steps,
            method=args.method,
            log=log,
        )
        assert first is not None  # (fit_roll ran at least one round)
        j_start = first.j_start
        rounds = [{"objective": j, "widest": w} for j, w in history]
        j_end = history[-1][0] if history else j_start
        cut, paths = cut_layout(mesh, layout, method=args.method)
    else:
        from ..cutting.flatten import make_pattern

        settings = Settings(
            material,
            prestress,
            (args.compensation[0] / 100, args.compensation[1] / 100),
            args.roll_width,
        )
        log("stress objective: the first round compiles (minutes)")
        try:
            res = optimise_seams(
                mesh, layout, settings, steps=args.steps, rounds=args.rounds, log=log
            )
        except JaxgeoError as e:
            print(f"jaxgeo pattern: {e}", file=sys.stderr)
            return 1
        layout, j_start, j_end, rounds = res.layout, res.j_start, res.j_end, res.rounds
        cut, paths = cut_layout(mesh, layout, method=args.method)
        pat = make_pattern(cut)
    polylines = [
        np.asarray(paths.points[i])[: int(paths.count[i])]
        for i in range(layout.n_seams)
    ]
    write_seams_obj(polylines, out / "seams.obj")
    cloths = compensate_pattern(pat, compensation, warp=args.warp)
    weld, boundary = args.allowance
    pieces = make_pieces(cloths, weld, boundary)
    check = reassemble(cloths, material, prestress)
    per_seam, per_cloth = weld_mismatch(pieces)
    write_dxf(pieces, out / "pattern.dxf")
    write_svg(pieces, out / "pattern.svg")
    fig = deviation_figure(cloths, check, f"{args.mesh}: reassembly check")
    fig.savefig(out / "stress_deviation.png", dpi=110)
    widths = np.array([p.width for p in pieces])
    fits = bool((widths <= args.roll_width).all())
    total = check.total_stats()
    report = {
        "mesh": str(args.mesh),
        "roll_width": args.roll_width,
        "method": args.method,
        "objective": args.objective,
        "material": dict(zip(("e_warp", "e_weft", "nu", "g"), args.material)),
        "prestress": dict(zip(("warp", "weft"), args.prestress)),
        "compensation_percent": dict(zip(("warp", "weft"), args.compensation)),
        "allowance": {"weld": weld, "boundary": boundary},
        "all_fit": fits,
        "stress_deviation": {k: total[k] for k in ("max", "rms", "mean")},
        "objective_start": j_start,
        "objective_end": j_end,
        "rounds": rounds,
        "seams": [
            {
                "loops": [int(a), int(b)],
                "s": [float(x), float(y)],
                "length": float(paths.length[i]),
                "weld_length_mismatch": per_seam.get(i),
            }
            for i, (a, b, x, y) in enumerate(
                zip(layout.loop_a, layout.loop_b, layout.s_a, layout.s_b)
            )
        ],
        "cloths": [
            {
                "name": p.name,
                "width": p.width,
                "length": p.length,
                "area": p.area,
                "warp_angle": c.warp_angle,
                "weld_length_mismatch": per_cloth[k],
                "stress_deviation": {
                    key: v for key, v in check.cloth_stats(k).items() if key != "mean"
                },
                **c.cloth.summary(),
            }
            for k, (p, c) in enumerate(zip(pieces, cloths))
        ],
    }
    report_path = Path(args.report) if args.report else out / "report.json"
    report_path.write_text(json.dumps(report, indent=2))
    k = int(np.argmax(widths))
    log(
        f"{len(pieces)} cloths, widest {pieces[k].name} {widths[k]:.4g} m "
        f"(roll {args.roll_width} m); stress deviation RMS {total['rms']:.3g} kN/m, "
        f"max {total['max']:.3g} kN/m; written to {out}"
    )
    warning = _fold_warning(
        [(p.name, c.cloth.inverted) for p, c in zip(pieces, cloths)]
    )
    if warning:
        print(warning, file=sys.stderr)
    if not fits:
        n = layout.n_seams
        suggest = math.ceil(args.seams * widths[k] / args.roll_width)
        print(
            f"jaxgeo pattern: the pattern does not fit the roll: cloth "
            f"{pieces[k].name} needs {widths[k]:.3f} m (allowances included), the "
            f"roll is {args.roll_width} m wide; try --seams {suggest} "
            f"({n} seams now) or a wider roll",
            file=sys.stderr,
        )
        return DOES_NOT_FIT
    return 0


def main(argv: list[str] | None = None) -> int:  # stand-alone use and tests
    from .._cache import limit_blas_threads

    limit_blas_threads()  # as the `jaxgeo` command
    parser = argparse.ArgumentParser(prog="jaxgeo")
    add_pattern_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
