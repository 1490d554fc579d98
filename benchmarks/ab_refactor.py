"""A/B: is the restructured package (issue 16) slower than before it?

Runs the same measurement on two source trees, each in a fresh interpreter with
`PYTHONPATH` pointing at it, alternating A, B, A, B, ... so that a load on the
shared machine falls on both alike. Per tree and method (`laser`, `exact`,
`smooth`) on `surfaces.catenoid(n_around=48, n_height=24)` in float64, with no
compilation cache: the CPU time (`time.process_time`, all threads) of the first
`shortest_path` (compile + one path), then the median CPU time per path over
`--pairs` random vertex pairs (seed 0), each blocked until ready.

Command (A = commit 65448fd, before this session's mesh.py and smooth.py
splits; B = the branch head):

    git worktree add /tmp/ab-before 65448fd
    . /work/venv/bin/activate
    python benchmarks/ab_refactor.py --before /tmp/ab-before --after . --rounds 2
    git worktree remove /tmp/ab-before

Prints one row per method: both trees' medians over the rounds and B/A.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

METHODS = ("laser", "exact", "smooth")


def worker(pairs: int) -> None:
    """One tree's measurement (the tree is whatever `jaxgeo` imports)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_enable_compilation_cache", False)
    import numpy as np

    import jaxgeo as jg
    from jaxgeo import surfaces

    mesh = jg.Mesh(*surfaces.catenoid(n_around=48, n_height=24))
    rng = np.random.default_rng(0)
    ij = rng.choice(mesh.n_vertices, size=(pairs + 1, 2), replace=True)
    ij = ij[ij[:, 0] != ij[:, 1]]
    out = {"jaxgeo": os.path.dirname(jg.__file__)}
    for method in METHODS:
        t0 = time.process_time()
        p = jg.shortest_path(mesh, int(ij[0, 0]), int(ij[0, 1]), method=method)
        jax.block_until_ready(p)
        first = time.process_time() - t0
        times = []
        for a, b in ij[1:]:
            t0 = time.process_time()
            p = jg.shortest_path(mesh, int(a), int(b), method=method)
            jax.block_until_ready(p)
            times.append(time.process_time() - t0)
        out[method] = {"first": first, "per_path": statistics.median(times)}
    print(json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", help="source tree A (holds jaxgeo/)")
    ap.add_argument("--after", help="source tree B (holds jaxgeo/)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--pairs", type=int, default=10)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.pairs)
        return
    trees = {"A": os.path.abspath(args.before), "B": os.path.abspath(args.after)}
    runs: dict[str, list[dict]] = {"A": [], "B": []}
    for r in range(args.rounds):
        for name in ("A", "B") if r % 2 == 0 else ("B", "A"):
            env = dict(os.environ, PYTHONPATH=trees[name])
            cmd = [sys.executable, __file__, "--worker", "--pairs", str(args.pairs)]
            res = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if res.returncode:
                sys.exit(f"{name} failed:\n{res.stderr}")
            run = json.loads(res.stdout.strip().splitlines()[-1])
            assert run["jaxgeo"] == os.path.join(trees[name], "jaxgeo"), run
            runs[name].append(run)
            print(f"round {r} {name}: {json.dumps(run)}", flush=True)
    print(
        "\n| method | compile + first path A / B (s) | per path A / B (ms) "
        "| B/A per path |"
    )
    print("|---|---|---|---|")
    for m in METHODS:
        f = {k: statistics.median(x[m]["first"] for x in runs[k]) for k in runs}
        t = {k: statistics.median(x[m]["per_path"] for x in runs[k]) for k in runs}
        print(
            f"| {m} | {f['A']:.1f} / {f['B']:.1f} | {1e3 * t['A']:.1f} / "
            f"{1e3 * t['B']:.1f} | {t['B'] / t['A']:.2f} |"
        )


if __name__ == "__main__":
    main()
