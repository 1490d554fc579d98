"""A/B of the exact engine between two checkouts, in separate processes, on the
20k-face catenoid: 30 random vertex pairs one by one (CPU time per path,
median and mean; the mean includes compiles of larger capacities) and a batch
of 256 (`shortest_paths`, chunk 256: the first call with its compiles, then
again). Writes the lengths, to compare the two runs.

    git worktree add /tmp/ab-head <commit>
    python benchmarks/ab_exact_attempts.py /tmp/ab-head /tmp/ab_A.pkl
    python benchmarks/ab_exact_attempts.py . /tmp/ab_B.pkl
"""

import pickle
import sys
import time
from pathlib import Path

sys.path.insert(0, sys.argv[1])  # the checkout to measure, before importing it
sys.path.insert(1, str(Path(__file__).parent))

import jax  # noqa: E402
import numpy as np  # noqa: E402
from bench_paths import random_pairs  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402

jax.config.update("jax_enable_x64", True)


def cpu(f, *args, **kwargs):
    t0 = time.process_time()
    out = f(*args, **kwargs)
    return out, time.process_time() - t0


def main() -> None:
    mesh = jg.Mesh(*surfaces.catenoid(100, 100))
    n = mesh.n_vertices
    pairs = random_pairs(n, 30, seed=0)
    jg.shortest_path(mesh, int(pairs[0, 0]), int(pairs[0, 1]))  # compile
    lengths, times = [], []
    for a, b in pairs:
        p, t = cpu(jg.shortest_path, mesh, int(a), int(b), throw=False)
        lengths.append(float(p.length))
        times.append(t)
    big = random_pairs(n, 256, seed=1)

    def batch():
        return jg.shortest_paths(
            mesh, big[:, 0], big[:, 1], chunk_size=256, throw=False
        )

    _, first = cpu(batch)
    out, again = cpu(batch)
    print(
        f"{jg.__file__}: single median {1e3 * np.median(times):.1f} ms, mean "
        f"{1e3 * np.mean(times):.1f} ms; batch first {first:.1f} s, again "
        f"{again:.1f} s = {256 / again:.2f} paths/s; failures "
        f"{int(np.sum(out.status != 0))}",
        flush=True,
    )
    with open(sys.argv[2], "wb") as f:
        pickle.dump((np.array(lengths), np.asarray(out.length)), f)


if __name__ == "__main__":
    main()
