"""`jaxgeo pattern MESH --seams N --roll-width W --out DIR`: seam layout,
optimisation, flattened cloths (DXF, SVG), seams (OBJ) and a JSON report."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def add_pattern_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "pattern",
        help="optimise geodesic seams on a tent mesh and write cutting patterns",
        description=__doc__,
    )
    p.add_argument("mesh", help="mesh file (OBJ, PLY, STL, OFF, …) of an open tent")
    p.add_argument("--seams", type=int, required=True, help="seams (per peak ring)")
    p.add_argument("--roll-width", type=float, required=True, help="fabric width")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--valley", type=int, default=3, help="valley seams (2 peaks)")
    p.add_argument("--steps", type=int, default=25, help="BFGS steps per round")
    p.add_argument("--rounds", type=int, default=3, help="calibration rounds")
    p.add_argument("--allowance", type=float, default=0.0, help="seam allowance")
    p.set_defaults(func=run_pattern)
    return p


def run_pattern(args: argparse.Namespace) -> int:
    import numpy as np

    from . import seams as sm
    from .export import write_dxf, write_seams_obj, write_svg
    from .mesh import load_mesh

    t0 = time.time()

    def log(msg: str) -> None:
        print(f"[{time.time() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mesh = load_mesh(args.mesh)
    loops = sm.boundary_loops(mesh)
    log(f"{args.mesh}: {mesh.n_faces} faces, {len(loops)} boundary loops")
    if len(loops) == 2:
        layout = sm.radial_layout(mesh, args.seams)
    elif len(loops) == 3:
        xs = np.asarray(mesh.vertices)[:, 0]
        half = 0.1 * (xs.max() - xs.min())
        layout = sm.peaks_layout(mesh, args.seams, args.valley, half)
    else:
        print("jaxgeo pattern: need a tent with 2 or 3 boundary loops", file=sys.stderr)
        return 2
    log(f"{layout.n_seams} seams; tracing (the first call compiles, ~40 s)")
    first, layout, pat, history = sm.fit_roll(
        mesh, layout, args.roll_width, rounds=args.rounds, steps=args.steps, log=log
    )
    _, paths = sm.cut(mesh, layout)
    polylines = [
        np.asarray(paths.points[i])[: int(paths.count[i])]
        for i in range(layout.n_seams)
    ]
    write_seams_obj(polylines, out / "seams.obj")
    write_dxf(pat, out / "pattern.dxf", seam_allowance=args.allowance)
    write_svg(pat, out / "pattern.svg")
    fits = bool((pat.widths <= args.roll_width).all())
    report = {
        "mesh": str(args.mesh),
        "roll_width": args.roll_width,
        "objective_start": first.j_start,
        "objective_end": history[-1][0] if history else first.j_start,
        "rounds": [{"objective": j, "widest": w} for j, w in history],
        "all_fit": fits,
        "seams": [
            {
                "loops": [int(a), int(b)],
                "s": [float(x), float(y)],
                "length": float(paths.length[i]),
            }
            for i, (a, b, x, y) in enumerate(
                zip(layout.loop_a, layout.loop_b, layout.s_a, layout.s_b)
            )
        ],
        "cloths": [c.summary() for c in pat.cloths],
        "seam_copy_difference": {
            str(k): v for k, v in pat.seam_copy_difference().items()
        },
    }
    (out / "report.json").write_text(json.dumps(report, indent=2))
    log(
        f"{len(pat.cloths)} cloths, widest {pat.widths.max():.4g} "
        f"(roll {args.roll_width}); max strain "
        f"{max(c.strain_max for c in pat.cloths):.3%}; written to {out}"
    )
    return 0 if fits else 1


def main(argv: list[str] | None = None) -> int:  # stand-alone use and tests
    parser = argparse.ArgumentParser(prog="jaxgeo")
    add_pattern_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
