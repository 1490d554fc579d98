"""The exact method against pygeodesic's exact MMP (and potpourri3d's edge flips)
on random vertex pairs: the table of `docs/accuracy.md`, "The exact method is
locally shortest".

    python benchmarks/accuracy_vs_mmp.py --pairs 60 --seed 1

Per mesh: pairs solved as one `shortest_paths` batch with the default `Exact()`
(or `--starts N`), the share within 1e-9 relative of MMP, the largest excess and
deficit, failures, and the same share for potpourri3d's `EdgeFlipGeodesicSolver`.
Meshes: the generated ones of `tests/test_exact.py` and pymeshlab's sample meshes
(scanned and CAD), unreferenced vertices removed (pygeodesic refuses them).
"""

from __future__ import annotations

import argparse
import sys

import jax
import numpy as np
import trimesh
from _samples import pymeshlab_sample, referenced

jax.config.update("jax_enable_x64", True)

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402

EQUAL = 1e-9  # relative: issue 13's acceptance bound


def meshes() -> list[tuple[str, jg.Mesh]]:
    tor = trimesh.creation.torus(1.0, 0.35, major_sections=24, minor_sections=10)
    out = [
        ("catenoid 24 x 10", jg.Mesh(*surfaces.catenoid(n_around=24, n_height=10))),
        ("icosphere, 2 subdivisions", jg.Mesh(*surfaces.icosphere(2))),
        ("torus 24 x 10 (trimesh)", referenced(tor)),
        # cone-free discs: certified, the first converged start ends the search
        ("saddle 16 x 16 (`surfaces.saddle`)", jg.Mesh(*surfaces.saddle(n=16))),
        (
            "four-point sail (`surfaces.four_point_sail`)",
            jg.Mesh(*surfaces.four_point_sail()),
        ),
    ]
    for name in ("bone.ply", "airplane.obj", "cow.obj", "bunny10k_textured.obj"):
        if (path := pymeshlab_sample(name)) is not None:
            out.append((f"`{name}` (pymeshlab)", referenced(jg.load_mesh(path))))
    return out


def compare(mesh: jg.Mesh, n_pairs: int, seed: int, method) -> dict:
    import potpourri3d as pp3d
    import pygeodesic.geodesic as pg

    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    rng = np.random.default_rng(seed)
    pairs = rng.integers(0, mesh.n_vertices, (n_pairs, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    paths = jg.shortest_paths(
        mesh, pairs[:, 0], pairs[:, 1], method=method, throw=False
    )
    ok = np.asarray(paths.status) == jg.Status.SUCCESS
    mmp = pg.PyGeodesicAlgorithmExact(v, f)
    ref = np.array([mmp.geodesicDistance(int(a), int(b))[0] for a, b in pairs])
    rel = (np.asarray(paths.length) - ref) / ref
    flip = pp3d.EdgeFlipGeodesicSolver(v, f)
    pp = np.array(
        [
            np.linalg.norm(
                np.diff(flip.find_geodesic_path(int(a), int(b)), axis=0), axis=1
            ).sum()
            for a, b in pairs
        ]
    )
    pp_rel = (pp - ref) / ref
    good = rel[ok]
    return {
        "faces": mesh.n_faces,
        "pairs": len(pairs),
        "failures": int(np.sum(~ok)),
        "within 1e-9": f"{np.mean(np.abs(good) <= EQUAL) * 100:.1f} %",
        "largest excess": f"{good.max():.2g}",
        "largest deficit": f"{-min(good.min(), 0.0):.2g}",
        "above 1e-3": int(np.sum(good > 1e-3)),
        "certified": f"{np.mean(np.asarray(paths.stats['certified'])) * 100:.0f} %",
        "potpourri3d within 1e-9": f"{np.mean(np.abs(pp_rel) <= EQUAL) * 100:.1f} %",
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=60)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--starts", type=int, default=None, help="Exact(max_starts=N)")
    ap.add_argument("--no-walls", action="store_true", help="Exact(walls=False)")
    ap.add_argument("--detours", type=int, default=None, help="Exact(detours=N)")
    ap.add_argument("--detour-rounds", type=int, default=None)
    ap.add_argument("--only", default=None, help="meshes whose name contains this")
    args = ap.parse_args()
    options = {
        "max_starts": args.starts,
        "walls": False if args.no_walls else None,
        "detours": args.detours,
        "detour_rounds": args.detour_rounds,
    }
    method = jg.Exact(**{k: x for k, x in options.items() if x is not None})
    print("python benchmarks/accuracy_vs_mmp.py " + " ".join(sys.argv[1:]))
    print(method)
    rows = []
    for name, mesh in meshes():
        if args.only and args.only not in name:
            continue
        row = {"mesh": name, **compare(mesh, args.pairs, args.seed, method)}
        rows.append(row)
        print(row, flush=True)
    cols = list(rows[0])
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        print("| " + " | ".join(str(r[c]) for c in cols) + " |")


if __name__ == "__main__":
    main()
