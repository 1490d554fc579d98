"""Single exact paths with XLA's CPU thread pool, and in a process on one core.

    python benchmarks/bench_threads.py        # prints a markdown section

XLA's CPU runtime runs the independent operations of a compiled program on a
thread pool sized from the CPUs the process may use (its affinity mask; no flag
or environment variable changes it in jax 0.10). The exact method's loops are
made of many small operations, whose hand-offs between threads cost more than
they bring. This script measures it: for each mesh, one child process with the
default pool (2 threads on this machine) and one whose affinity is set to a
single core before JAX starts, each timing the same random vertex pairs as
`bench_paths.py` (seed 0, CPU-time medians after a compile call), with
potpourri3d's edge flip in the same process; on the catenoid also a batch of
256 random pairs (one chunk, its second call). The pool also compiles, so the
one-core process compiles about twice as slowly.

To run a program on one core: `taskset -c 0 python ...`, or
`os.sched_setaffinity(0, {0})` before the first JAX computation.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
MESHES = ("catenoid 20k", "saddle 20k", "bone.ply", "airplane.obj")
#: The mesh that also runs a batch (`shortest_paths`, one chunk of `--batch`).
BATCH_MESH = "catenoid 20k"


def child(mesh_name: str, one_core: bool, queries: int, batch: int) -> dict:
    if one_core:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    import statistics
    import time

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from _samples import pymeshlab_sample, referenced
    from bench_paths import cpu_median, random_pairs

    import jaxgeo as jg
    from jaxgeo import surfaces

    if mesh_name == "catenoid 20k":
        v, f = surfaces.catenoid(100, 100)
    elif mesh_name == "saddle 20k":
        v, f = surfaces.saddle(n=100)
    else:
        path = pymeshlab_sample(mesh_name)
        if path is None:
            return {}
        m = referenced(jg.load_mesh(path))
        v, f = np.asarray(m.vertices), np.asarray(m.faces)
    mesh = jg.Mesh(v, f)
    pairs = [(int(i), int(j)) for i, j in random_pairs(len(v), queries, seed=0)]
    t0 = time.perf_counter()
    jg.shortest_path(mesh, *pairs[0], throw=False)
    compile_s = time.perf_counter() - t0
    cpu, wall = [], []
    for i, j in pairs:
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(jg.shortest_path(mesh, i, j, throw=False).length)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    row = {
        "threads": len(os.sched_getaffinity(0)),
        "compile+first s": compile_s,
        "exact ms CPU": 1e3 * statistics.median(cpu),
        "exact ms wall": 1e3 * statistics.median(wall),
    }
    try:
        import potpourri3d as pp3d
    except ImportError:
        return row
    solver = pp3d.EdgeFlipGeodesicSolver(v, f)
    solver.find_geodesic_path(*pairs[0])
    row["pp3d ms"] = 1e3 * cpu_median(solver.find_geodesic_path, pairs)
    row["exact/pp3d"] = row["exact ms CPU"] / row["pp3d ms"]
    if batch:  # as bench_paths: a second call, after the compile
        big = random_pairs(len(v), batch, seed=1)
        jg.shortest_paths(mesh, big[:, 0], big[:, 1], chunk_size=batch, throw=False)
        c0 = time.process_time()
        out = jg.shortest_paths(
            mesh, big[:, 0], big[:, 1], chunk_size=batch, throw=False
        )
        jax.block_until_ready(out.length)
        row[f"batch of {batch} paths/s CPU"] = batch / (time.process_time() - c0)
        row["batch/pp3d throughput"] = row[f"batch of {batch} paths/s CPU"] * (
            row["pp3d ms"] / 1e3
        )
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--queries", type=int, default=20)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--child", nargs=2, metavar=("MESH", "ONE_CORE"))
    args = ap.parse_args(argv)
    if args.child:
        batch = args.batch if args.child[0] == BATCH_MESH else 0
        row = child(args.child[0], args.child[1] == "1", args.queries, batch)
        print(json.dumps(row))
        return 0
    rows = []
    for name in MESHES:
        for one_core in (False, True):
            out = subprocess.run(
                [sys.executable, __file__, "--queries", str(args.queries)]
                + ["--batch", str(args.batch)]
                + ["--child", name, str(int(one_core))],
                capture_output=True,
                text=True,
                check=True,
                cwd=HERE,
            )
            row = json.loads(out.stdout.strip().splitlines()[-1])
            if row:
                rows.append({"mesh": name, **row})
                print(rows[-1], file=sys.stderr, flush=True)
    from bench_paths import markdown  # (imports JAX: not in the children)

    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
