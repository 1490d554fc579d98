"""A/B of the exact engine between two checkouts, in separate processes, on the
20k-face catenoid: 30 random vertex pairs one by one (CPU time per path,
median and mean; the mean includes compiles of larger capacities) and a batch
of 256 (`shortest_paths`, chunk 256: the first call with its compiles, then
again). Writes the lengths to compare the two runs.

    git worktree add /tmp/ab-head <commit>
    python benchmarks/ab_exact_attempts.py /tmp/ab-head /tmp/ab_A.pkl
    python benchmarks/ab_exact_attempts.py . /tmp/ab_B.pkl
"""

import sys, time, pickle

sys.path.insert(0, sys.argv[1])
import jax

jax.config.update("jax_enable_x64", True)
import numpy as np, jaxgeo as jg
from jaxgeo import surfaces

sys.path.insert(0, "/work/main/benchmarks")
from bench_paths import random_pairs

mesh = jg.Mesh(*surfaces.catenoid(100, 100))
v = np.asarray(mesh.vertices)
pairs = random_pairs(len(v), 30, seed=0)
jg.shortest_path(mesh, int(pairs[0, 0]), int(pairs[0, 1]))
L, T = [], []
for a, b in pairs:
    c0 = time.process_time()
    p = jg.shortest_path(mesh, int(a), int(b), throw=False)
    T.append(time.process_time() - c0)
    L.append(float(p.length))
big = random_pairs(len(v), 256, seed=1)
t0 = time.process_time()
out = jg.shortest_paths(mesh, big[:, 0], big[:, 1], chunk_size=256, throw=False)
first = time.process_time() - t0
t0 = time.process_time()
out = jg.shortest_paths(mesh, big[:, 0], big[:, 1], chunk_size=256, throw=False)
c = time.process_time() - t0
print(
    jg.__file__,
    f"single median {1e3 * np.median(T):.1f} mean {1e3 * np.mean(T):.1f} ms; batch first {first:.1f} s, again {c:.1f} s = {256 / c:.2f} paths/s; failures {int(np.sum(out.status != 0))}",
    flush=True,
)
pickle.dump((np.array(L), np.asarray(out.length)), open(sys.argv[2], "wb"))
