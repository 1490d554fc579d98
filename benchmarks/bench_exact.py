"""The default method (`"exact"`, the JAX engine) against potpourri3d and
pygeodesic, on random vertex pairs drawn uniformly, in one run.

    pip install -e ".[dev]"
    python benchmarks/bench_exact.py                 # writes benchmarks/EXACT.md
    python benchmarks/bench_exact.py --pairs 30 --batch 200   # quicker

For each mesh (a 20k-face catenoid, and real meshes shipped inside pymeshlab's
wheel when it is installed): compile + first path, median single-path time,
`shortest_paths` throughput on a batch, potpourri3d's `find_geodesic_path`
(edge flips) and pygeodesic's exact MMP on the same pairs; accuracy against MMP
(share of pairs within 1e-9 relative, largest excess) for jaxgeo and potpourri3d.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import jax
from _samples import pymeshlab_sample

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402

HERE = Path(__file__).resolve().parent


def meshes() -> list[tuple[str, jg.Mesh]]:
    out = [("catenoid 20k", jg.Mesh(*surfaces.catenoid(n_around=100, n_height=100)))]
    for name in ("bone.ply", "cow.obj", "bunny10k_textured.obj"):
        if (path := pymeshlab_sample(name)) is not None:
            out.append((f"{name} (pymeshlab)", jg.load_mesh(path)))
    return out


def timed(fn, repeats=1):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench(name: str, mesh: jg.Mesh, n_pairs: int, n_batch: int, seed: int) -> dict:
    import potpourri3d as pp3d
    import pygeodesic.geodesic as pg

    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    rng = np.random.default_rng(seed)
    pairs = rng.integers(0, mesh.n_vertices, (n_pairs, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    t0 = time.perf_counter()
    jg.shortest_path(mesh, v[pairs[0, 0]], v[pairs[0, 1]])
    compile_s = time.perf_counter() - t0
    lengths, times = [], []
    for a, b in pairs:
        t0 = time.perf_counter()
        p = jg.shortest_path(mesh, v[a], v[b], throw=False)
        times.append(time.perf_counter() - t0)
        lengths.append(float(p.length) if int(p.status) == 0 else np.nan)
    solver = pp3d.EdgeFlipGeodesicSolver(v, f)
    pp_len, pp_t = [], []
    for a, b in pairs:
        t0 = time.perf_counter()
        pts = solver.find_geodesic_path(int(a), int(b))
        pp_t.append(time.perf_counter() - t0)
        pp_len.append(float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()))
    algo = pg.PyGeodesicAlgorithmExact(v, f)
    mmp, mmp_t = [], []
    for a, b in pairs[: min(len(pairs), 20)]:
        t0 = time.perf_counter()
        mmp.append(algo.geodesicDistance(int(a), int(b))[0])
        mmp_t.append(time.perf_counter() - t0)
    mmp = np.array(mmp)
    m = len(mmp)
    rel = (np.array(lengths[:m]) - mmp) / mmp
    rel_pp = (np.array(pp_len[:m]) - mmp) / mmp
    bp = rng.integers(0, mesh.n_vertices, (n_batch, 2))
    chunk = 256
    jg.shortest_paths(
        mesh, v[bp[:chunk, 0]], v[bp[:chunk, 1]], chunk_size=chunk, throw=False
    )
    t0 = time.perf_counter()
    batch = jg.shortest_paths(
        mesh, v[bp[:, 0]], v[bp[:, 1]], chunk_size=chunk, throw=False
    )
    batch_s = time.perf_counter() - t0
    single = statistics.median(times)
    pp_single = statistics.median(pp_t)
    return {
        "mesh": name,
        "faces": mesh.n_faces,
        "exact compile+first s": round(compile_s, 2),
        "exact ms": round(1e3 * single, 2),
        "pp3d ms": round(1e3 * pp_single, 2),
        "exact/pp3d": round(single / pp_single, 2),
        "pygeodesic ms": round(1e3 * statistics.median(mmp_t), 1),
        "batch paths/s": round(n_batch / batch_s, 1),
        "batch/pp3d throughput": round((n_batch / batch_s) * pp_single, 2),
        "batch failures": int(np.sum(batch.status != 0)),
        "single failures": int(np.sum(np.isnan(lengths))),
        "exact within 1e-9 of MMP": f"{np.mean(np.abs(rel) <= 1e-9):.0%} of {m}",
        "exact max excess": f"{np.nanmax(rel):.1e}",
        "pp3d within 1e-9": f"{np.mean(np.abs(rel_pp) <= 1e-9):.0%}",
        "pp3d max excess": f"{np.nanmax(rel_pp):.1e}",
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=60)
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(HERE / "EXACT.md"))
    args = ap.parse_args()
    rows = []
    for name, mesh in meshes():
        rows.append(bench(name, mesh, args.pairs, args.batch, args.seed))
        print(rows[-1], flush=True)
    cols = list(rows[0])
    lines = [
        "# The exact method against its peers",
        "",
        f"Command: `python benchmarks/bench_exact.py --pairs {args.pairs} "
        f"--batch {args.batch}`",
        "",
        f"Machine: {platform.platform()}, {os.cpu_count()} CPUs, "
        f"jax {jax.__version__}, backend {jax.default_backend()}. "
        "Random vertex pairs drawn uniformly; times are medians after the first "
        "call; MMP accuracy on the first 20 pairs.",
        "",
        "| " + " | ".join(cols) + " |",
        "|" + "---|" * len(cols),
    ]
    lines += ["| " + " | ".join(str(r[c]) for c in cols) + " |" for r in rows]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
