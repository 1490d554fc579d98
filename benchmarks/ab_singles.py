"""Single exact paths of one checkout, for A/B runs one checkout after the other:
30 random vertex pairs (`bench_paths.random_pairs`, seed 0), each timed as the
least CPU time of 3 calls; prints the compile + first call, the median and mean
ms per path and the sum of the lengths (equal sums: the same paths).

    git worktree add /tmp/ab-base <commit>
    python benchmarks/ab_singles.py /tmp/ab-base catenoid   # or saddle, a file
    python benchmarks/ab_singles.py . catenoid
"""

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, sys.argv[1])  # the checkout to measure, before importing it
sys.path.insert(1, str(Path(__file__).parent))

import jax  # noqa: E402
import numpy as np  # noqa: E402
from bench_paths import random_pairs, referenced  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402

jax.config.update("jax_enable_x64", True)


def mesh_of(name: str) -> jg.Mesh:
    if name == "catenoid":
        return jg.Mesh(*surfaces.catenoid(100, 100))
    if name == "saddle":
        return jg.Mesh(*surfaces.saddle(n=100))
    return referenced(jg.load_mesh(name))


def main() -> None:
    mesh = mesh_of(sys.argv[2])
    pairs = [(int(i), int(j)) for i, j in random_pairs(mesh.n_vertices, 30, seed=0)]
    t0 = time.perf_counter()
    jg.shortest_path(mesh, *pairs[0])
    print(f"compile + first {time.perf_counter() - t0:.1f} s")
    times, total = [], 0.0
    for i, j in pairs:
        best = np.inf
        for _ in range(3):
            c0 = time.process_time()
            path = jg.shortest_path(mesh, i, j)
            jax.block_until_ready(path.length)
            best = min(best, time.process_time() - c0)
        times.append(1e3 * best)
        total += float(path.length)
    print(
        f"median {statistics.median(times):.2f} mean {statistics.mean(times):.2f} ms"
        f" per path, sum of lengths {total:.9f}"
    )


if __name__ == "__main__":
    main()
