"""Before/after table of the reassembly stress deviation: uniform seams, the
width-only optimisation (`jaxgeo.seams.fit_roll`) and the stress optimisation
(`optimise_seams`), on the twin-peak tent and the four-point sail.

    python -m jaxgeo.cutting.compare --steps 6 --rounds 2 --only sail
    python -m jaxgeo.cutting.compare --steps 6 --rounds 4 --only twin [--roundings 3]

(it runs with one BLAS thread unless `OPENBLAS_NUM_THREADS` or
`OMP_NUM_THREADS` is set: on a shared 2-core CPU the batched LAPACK calls of
the banded flattening otherwise spin against other processes, docs/cutting.md)

Every layout is measured the same way: seams traced with the optimiser's
method, cut, flattened by `jaxgeo.pattern.make_pattern`, compensated by the
design prestress strain and checked by `reassemble` (numpy).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import numpy as np

from ..mesh import Mesh
from ..methods import Method
from ..trace import TraceOptions
from . import layout as lay
from .compensate import compensate_pattern
from .cut import cut as cut_layout
from .flatten import make_pattern
from .material import Compensation, Material, Prestress
from .objective import Settings
from .optimise import optimise_seams
from .reassembly import reassemble
from .seam_width import fit_roll

MATERIAL = Material(600.0, 400.0, 0.3, 30.0)
PRESTRESS = Prestress(2.0, 1.5)
#: relative size of `measure`'s perturbations of a cut (about one ulp)
ULP_JITTER = 2e-16


@dataclasses.dataclass
class Case:
    name: str
    mesh: Mesh
    layout: lay.Layout
    roll_width: float


def cases() -> list[Case]:
    """The twin-peak tent (example mesh, `bridged_layout(tent, 9, 3)`: 21
    seams, each leaving a peak ring; roll 1.1 m, which its uniform cloths fit,
    so that the stress optimiser is not held back by the roll-fit term) and
    the four-point sail
    (`surfaces.four_point_sail()`, 4 seams parallel to x; a middle seam would
    run along mesh edges, where no step keeps the cut)."""
    from .. import surfaces
    from ..data import example_mesh_path
    from ..loading import load_mesh

    tent = load_mesh(example_mesh_path("twin_peak_tent"))
    sail = Mesh(*surfaces.four_point_sail())
    return [
        Case("twin-peak tent", tent, lay.bridged_layout(tent, 9, 3), 1.1),
        Case("four-point sail", sail, lay.parallel_layout(sail, 4), 2.5),
    ]


def measure(
    mesh, layout, compensation: Compensation, method: Method, roundings: int = 0
) -> dict:
    """Stress deviation (max, RMS; kN/m), widest cloth of `layout`'s pattern,
    how many of its cloths' flattenings did not converge (`Cloth.converged`:
    such a cloth is measured on its trust-region fit) and how many flat
    triangles are inverted (`Cloth.inverted`: folds, in how many cloths).

    `roundings` > 0 measures the RMS again on that many copies of the cut whose
    vertices are multiplied by 1 + 2e-16·N(0, 1) (seeded; about one ulp): where
    cloths fold, their least-strain minimum is not unique and moves with the
    last bits of the cut (docs/cutting.md), and `rms_range` (min, max over the
    cut and its copies) says by how much."""
    cut, _ = cut_layout(mesh, layout, TraceOptions("local", 160), method)

    def check(cut):
        pat = make_pattern(cut)
        cloths = compensate_pattern(pat, compensation)
        return pat, reassemble(cloths, MATERIAL, PRESTRESS).total_stats()

    pat, total = check(cut)
    out = {
        "max": total["max"],
        "rms": total["rms"],
        "widest": float(pat.widths.max()),
        "unconverged": sum(not c.converged for c in pat.cloths),
        "inverted": sum(c.inverted for c in pat.cloths),
        "folded": sum(c.inverted > 0 for c in pat.cloths),
    }
    if roundings:
        rng = np.random.default_rng(0)
        rms = [total["rms"]]
        for _ in range(roundings):
            noise = 1 + ULP_JITTER * rng.standard_normal(cut.vertices.shape)
            moved = dataclasses.replace(cut, vertices=cut.vertices * noise)
            rms.append(check(moved)[1]["rms"])
        out["rms_range"] = [float(min(rms)), float(max(rms))]
    return out


def run(
    steps: int,
    rounds: int,
    log,
    only: str | None = None,
    max_move: float = 0.02,
    solver: str = "banded",
    roundings: int = 0,
) -> list[dict]:
    eps = np.asarray(PRESTRESS.strain(MATERIAL))[:2]
    comp = Compensation(*(100 * eps))
    rows = []
    for c in cases():
        if only and only not in c.name:
            continue
        settings = Settings(
            MATERIAL,
            PRESTRESS,
            (float(eps[0]), float(eps[1])),
            c.roll_width,
            solver=solver,
        )
        method = settings.method
        log(f"{c.name}: {c.mesh.n_faces} faces, {c.layout.n_seams} seams")
        t = time.time()
        uniform = measure(c.mesh, c.layout, comp, method, roundings)
        log(f"  uniform {uniform} ({time.time() - t:.0f} s)")
        t = time.time()
        _, lw, _, _ = fit_roll(
            c.mesh, c.layout, c.roll_width, rounds=rounds, steps=steps, method=method
        )
        width = measure(c.mesh, lw, comp, method, roundings)
        log(f"  width-only {width} ({time.time() - t:.0f} s)")
        t = time.time()
        res = optimise_seams(
            c.mesh,
            c.layout,
            settings,
            steps=steps,
            rounds=rounds,
            max_move=max_move,
            log=log,
        )
        stress = measure(c.mesh, res.layout, comp, method, roundings)
        log(f"  stress {stress} ({time.time() - t:.0f} s)")
        rows.append(
            {"case": c.name, "uniform": uniform, "width": width, "stress": stress}
        )
    return rows


def table(rows: list[dict]) -> str:
    out = [
        "| surface | seams | max (kN/m) | RMS (kN/m) | RMS vs uniform "
        "| widest cloth (m) | cloths not converged | inverted triangles (cloths) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    names = {"uniform": "uniform", "width": "width-only", "stress": "stress-optimised"}
    ranged = any("rms_range" in r[k] for r in rows for k in names)
    if ranged:
        out[0] += " RMS over roundings (min–max) |"
        out[1] += "---|"
    for r in rows:
        base = r["uniform"]["rms"]
        for key, label in names.items():
            m = r[key]
            out.append(
                f"| {r['case']} | {label} | {m['max']:.3g} | {m['rms']:.4g} | "
                f"{100 * (m['rms'] / base - 1):+.1f} % | {m['widest']:.3f} | "
                f"{m['unconverged']} | {m['inverted']} ({m['folded']}) |"
            )
            if ranged:
                lo, hi = m.get("rms_range", (m["rms"], m["rms"]))
                out[-1] += f" {lo:.4g}–{hi:.4g} |"
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m jaxgeo.cutting.compare")
    p.add_argument("--steps", type=int, default=6, help="optimiser steps per round")
    p.add_argument("--rounds", type=int, default=2, help="rounds of each optimiser")
    p.add_argument("--json", default=None, help="write the rows here too")
    p.add_argument("--only", default=None, help="the cases whose name has this")
    p.add_argument(
        "--max-move",
        type=float,
        default=0.02,
        help="the stress optimiser's largest seam-end move per round (of the loop)",
    )
    p.add_argument(
        "--solver",
        default="banded",
        choices=["banded", "sparse", "qr", "lsmr"],
        help="the flattening's solver in the stress objective (Settings.solver)",
    )
    p.add_argument(
        "--roundings",
        type=int,
        default=0,
        help="also measure each layout's RMS on this many copies of its cut moved "
        "by about one ulp (seeded), and report the range",
    )
    a = p.parse_args(argv)
    t0 = time.time()

    def log(msg: str) -> None:
        print(f"[{time.time() - t0:6.0f} s] {msg}", file=sys.stderr, flush=True)

    rows = run(a.steps, a.rounds, log, a.only, a.max_move, a.solver, a.roundings)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=2)
    print(table(rows))
    return 0


if __name__ == "__main__":
    import jax

    from .._cache import limit_blas_threads

    limit_blas_threads()
    jax.config.update("jax_enable_x64", True)
    raise SystemExit(main())
