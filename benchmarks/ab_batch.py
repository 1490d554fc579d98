"""A/B of `shortest_paths` (the default method) between two checkouts, each in
its own process: a batch of random vertex pairs (`bench_paths.random_pairs`,
seed 1) in chunks of 256, called twice; the second call is timed (wall and
CPU). Prints one line per run with the sum of the lengths, to compare runs.

    git worktree add /tmp/ab-base <commit>
    python benchmarks/ab_batch.py /tmp/ab-base catenoid      # the 20k catenoid
    python benchmarks/ab_batch.py . catenoid
    python benchmarks/ab_batch.py . airplane.obj --pairs 1000  # pymeshlab's sample

Alternate the two checkouts and run each more than once: timings on the 2-core
machine vary by 10-30 % between runs.
"""

import argparse
import sys
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("checkout", help="the jaxgeo checkout to measure")
    ap.add_argument("mesh", help="catenoid, saddle, or a pymeshlab sample name")
    ap.add_argument("--pairs", type=int, default=1000)
    ap.add_argument("--chunk", type=int, default=256)
    args = ap.parse_args()
    sys.path.insert(0, args.checkout)  # the checkout to measure, before importing it
    sys.path.insert(1, str(Path(__file__).parent))

    import jax
    import numpy as np
    from bench_paths import random_pairs

    import jaxgeo as jg
    from jaxgeo import surfaces

    jax.config.update("jax_enable_x64", True)
    if args.mesh in ("catenoid", "saddle"):
        mesh = jg.Mesh(*getattr(surfaces, args.mesh)(100, 100))
    else:
        from _samples import pymeshlab_sample, referenced

        mesh = referenced(jg.load_mesh(pymeshlab_sample(args.mesh)))
    pairs = random_pairs(mesh.n_vertices, args.pairs, seed=1)

    def run():
        paths = jg.shortest_paths(
            mesh, pairs[:, 0], pairs[:, 1], chunk_size=args.chunk, throw=False
        )
        return jax.block_until_ready(paths)

    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    paths = run()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = args.pairs
    print(
        f"{args.checkout} {args.mesh} {n} pairs: first {first:.1f} s, "
        f"wall {wall:.2f} s ({n / wall:.1f} paths/s), "
        f"CPU {cpu:.2f} s ({n / cpu:.1f} paths/s), "
        f"failed {int(np.sum(paths.status != 0))}, "
        f"sum of lengths {float(np.sum(paths.length)):.9f}"
    )


if __name__ == "__main__":
    main()
