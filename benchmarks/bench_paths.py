"""Speed of jaxgeo against the C++ geodesic libraries, measured in one run.

    pip install -e ".[bench]"
    python benchmarks/bench_paths.py          # rewrites its part of RESULTS.md
    python benchmarks/bench_paths.py --quick    # 5k/20k meshes, 200-path batches

The protocol of issue 13: **random vertex pairs drawn uniformly** (not
hand-picked long ones, where fixed per-call costs hide), on generated surfaces
(an icosphere and a catenoid at about 5k, 20k and 100k faces, and a 20k-face
saddle: a disc with no cone vertex, where the exact paths are certified) and on
real meshes shipped inside pymeshlab's wheel (`bone.ply`, a CT-scanned bone;
`airplane.obj`, a CAD model; when pymeshlab is installed). Every method of
METHODS runs single paths (`shortest_path`); the default method and the laser
also run a batch of 1,000 (`shortest_paths`, chunks of 256) on the 20k catenoid,
the saddle and `airplane.obj`; potpourri3d's
`EdgeFlipGeodesicSolver.find_geodesic_path` and pygeodesic's exact MMP answer
the same pairs in the same process. Times are CPU time (`time.process_time`, the
fair measure on a shared machine; wall time beside it for batches), medians over
the pairs after a compile call; "compile+first" is the wall time of the first
call on the mesh. Ratios come from the same run. It also times the batched
all-edges System (16) solve against the closed form alone on the same edges, and
one path on a 1M-face mesh with the process's peak memory. It rewrites the part
of RESULTS.md above the line `<!-- end bench_paths -->` and keeps the rest
(other benchmarks' sections).

Linux's default `vm.max_map_count` (65,530) is too small for the compiles of the
81k icosphere (LLVM dies with "Cannot allocate memory"): raise it first, as
`.ci/run` does (`sysctl -w vm.max_map_count=262144`). XLA's CPU thread pool
costs the exact method's single paths a third to a half of their time on this
machine: `bench_threads.py` measures it.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import sys
import time
from collections.abc import Callable

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _samples import pymeshlab_sample, referenced  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402
from jaxgeo.geodesic import METHODS  # noqa: E402
from jaxgeo.normals import vertex_normals  # noqa: E402
from jaxgeo.projection import (  # noqa: E402
    _roots,
    _t_zeta,
    quadratic_coefficients,
    solve_edges,  # noqa: E402
)

HERE = os.path.dirname(os.path.abspath(__file__))
#: Where the part this script writes ends in RESULTS.md.
END_MARK = "<!-- end bench_paths -->"


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def median_time(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def meshes(quick: bool):
    """(name, vertices, faces, batch?): generated surfaces at about 5k, 20k and
    100k faces (quick: 5k, 20k), a 20k-face saddle, then the real meshes found
    in pymeshlab."""
    sizes = [(4, 50, 52), (5, 100, 100), (6, 224, 224)]
    for sub, n_around, n_height in sizes[: 2 if quick else 3]:
        v, f = surfaces.icosphere(sub)
        yield f"icosphere {len(f) // 1000}k", v, f, False
        v, f = surfaces.catenoid(n_around, n_height)
        yield f"catenoid {len(f) // 1000}k", v, f, 15_000 < len(f) < 30_000
    # a cone-free disc, as anticlastic membranes are: certified paths
    v, f = surfaces.saddle(n=100)
    yield f"saddle {len(f) // 1000}k (disc, no cone vertex)", v, f, True
    for name in REAL_MESHES:
        path = pymeshlab_sample(name)
        if path is None:
            print(f"{name}: pymeshlab's sample not found, skipped", file=sys.stderr)
            continue
        mesh = referenced(jg.load_mesh(path))
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        yield f"`{name}` (pymeshlab)", v, f, name == BATCH_REAL


#: Real meshes (pymeshlab's samples) and the one that also runs the batches.
REAL_MESHES = ("bone.ply", "airplane.obj")
BATCH_REAL = "airplane.obj"


def random_pairs(n_vertices: int, n: int, seed: int) -> np.ndarray:
    """n vertex pairs drawn uniformly (distinct ends)."""
    rng = np.random.default_rng(seed)
    pairs = rng.integers(0, n_vertices, (2 * n, 2))
    return pairs[pairs[:, 0] != pairs[:, 1]][:n]


def cpu_median(fn: Callable[[], object], calls) -> float:
    """Median CPU seconds of fn(*c) over the calls."""
    times = []
    for c in calls:
        t0 = time.process_time()
        jax.block_until_ready(fn(*c))
        times.append(time.process_time() - t0)
    return statistics.median(times)


def bench_mesh(name, v, f, n_queries, n_batch, rows, peers):
    mesh = jg.Mesh(v, f)
    pairs = [(int(i), int(j)) for i, j in random_pairs(len(v), n_queries, seed=0)]
    row = {"mesh": name, "faces": len(f)}
    for method in METHODS:
        kw = dict(method=method, throw=False)
        t0 = time.perf_counter()
        jg.shortest_path(mesh, *pairs[0], **kw)
        row[f"{method} compile+first s"] = time.perf_counter() - t0
        row[f"{method} ms"] = 1e3 * cpu_median(
            lambda i, j, kw=kw: jg.shortest_path(mesh, i, j, **kw).length, pairs
        )
        # (a failed path still costs its time; the paper's laser fails on scans)
        row[f"{method} failures"] = sum(
            int(jg.shortest_path(mesh, i, j, **kw).status) != 0 for i, j in pairs
        )
    if "pp3d" in peers:
        solver = peers["pp3d"].EdgeFlipGeodesicSolver(v, f)
        solver.find_geodesic_path(*pairs[0])
        row["pp3d ms"] = 1e3 * cpu_median(solver.find_geodesic_path, pairs)
        row["pp3d paths/s"] = 1e3 / row["pp3d ms"]
    if "pygeodesic" in peers and len(f) <= 30_000:
        algo = peers["pygeodesic"].PyGeodesicAlgorithmExact(v, f)
        row["pygeodesic ms"] = 1e3 * cpu_median(algo.geodesicDistance, pairs[:3])
    if n_batch:
        big = random_pairs(len(v), n_batch, seed=1)
        for method in ("exact", "laser"):
            kw = dict(method=method, chunk_size=256, throw=False)
            jg.shortest_paths(mesh, big[:256, 0], big[:256, 1], **kw)  # compile
            t0, c0 = time.perf_counter(), time.process_time()
            out = jg.shortest_paths(mesh, big[:, 0], big[:, 1], **kw)
            jax.block_until_ready(out.length)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            row[f"{method} batch paths/s CPU"] = n_batch / cpu
            row[f"{method} batch paths/s wall"] = n_batch / wall
            row[f"{method} batch failures"] = int(np.sum(np.asarray(out.status) != 0))
    row["peak RSS MB"] = peak_rss_mb()
    rows.append(row)
    print(row, file=sys.stderr, flush=True)


def bench_all_edges(v, f, repeats):
    """The batched all-edges optimistix solve vs the closed form alone."""
    mesh = jg.Mesh(v, f)
    n = vertex_normals(mesh.vertices, mesh.faces)
    e = mesh.edges
    args = (
        mesh.vertices[0],
        mesh.vertices[len(v) // 2],
        v[e[:, 0]],
        v[e[:, 1]],
        n[e[:, 0]],
        n[e[:, 1]],
    )
    args = tuple(jnp.asarray(a) for a in args)

    def closed(a, b, x1, x2, n1, n2):
        def one(x1, x2, n1, n2):
            c0, c1, c2, s = quadratic_coefficients(a, b, x1, x2, n1, n2)
            r, _ = _roots(c0, c1, c2, s)
            return r, jax.vmap(
                lambda u: _t_zeta(u, a, b - a, x1, x2 - x1, n1, n2 - n1)
            )(r)

        return jax.vmap(one)(x1, x2, n1, n2)

    newton = jax.jit(solve_edges)
    closed = jax.jit(closed)
    jax.block_until_ready(newton(*args))
    jax.block_until_ready(closed(*args))
    t_newton = median_time(lambda: newton(*args), repeats)
    t_closed = median_time(lambda: closed(*args), repeats)
    return {
        "edges": len(e),
        "optimistix ms": 1e3 * t_newton,
        "closed form ms": 1e3 * t_closed,
    }


def bench_million():
    v, f = surfaces.catenoid(720, 700)
    t0 = time.perf_counter()
    mesh = jg.Mesh(v, f)
    build = time.perf_counter() - t0
    i, j = 0, len(v) - 240
    t0 = time.perf_counter()
    path = jg.shortest_path(mesh, v[i], v[j], max_points=4096)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(jg.shortest_path(mesh, v[i], v[j], max_points=4096).length)
    return {
        "faces": len(f),
        "mesh build s": build,
        "first path s (incl. compile)": first,
        "path s": time.perf_counter() - t0,
        "points": int(path.count),
        "peak RSS MB": peak_rss_mb(),
    }


def markdown(rows: list[dict]) -> str:
    keys = list(dict.fromkeys(k for r in rows for k in r))
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        cells = [
            f"{r[k]:.4g}" if isinstance(r.get(k), float) else str(r.get(k, ""))
            for k in keys
        ]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--queries", type=int, default=20)
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--no-million", action="store_true")
    ap.add_argument("--output", default=os.path.join(HERE, "RESULTS.md"))
    args = ap.parse_args(argv)
    load_before = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    peers = {}
    for name in ("potpourri3d", "pygeodesic.geodesic"):
        try:
            peers["pp3d" if name == "potpourri3d" else "pygeodesic"] = __import__(
                name, fromlist=["_"]
            )
        except ImportError:
            print(f"{name} not installed: skipped", file=sys.stderr)
    rows: list[dict] = []
    for name, v, f, batch in meshes(args.quick):
        n_batch = (200 if args.quick else args.batch) if batch else 0
        bench_mesh(name, v, f, args.queries, n_batch, rows, peers)
    for r in rows:
        for m in METHODS:
            if "pp3d ms" in r:
                r[f"{m}/pp3d"] = r[f"{m} ms"] / r["pp3d ms"]
            if "pygeodesic ms" in r:
                r[f"{m}/pygeodesic"] = r[f"{m} ms"] / r["pygeodesic ms"]
            key = f"{m} batch paths/s CPU"
            if key in r and "pp3d paths/s" in r:
                r[f"{m} batch/pp3d throughput"] = r[key] / r["pp3d paths/s"]
    v, f = surfaces.catenoid(100, 100)
    solve = bench_all_edges(v, f, 20)
    solve["ratio"] = solve["optimistix ms"] / solve["closed form ms"]
    million = None if args.no_million or args.quick else bench_million()
    command = " ".join(["python benchmarks/bench_paths.py", *(argv or sys.argv[1:])])
    text = [
        "# Benchmark results",
        "",
        f"Command: `{command}`",
        "",
        f"Machine: {platform.platform()}, {os.cpu_count()} CPUs, Python "
        f"{platform.python_version()}, jax {jax.__version__}, backend "
        f"{jax.default_backend()}, {jax.device_count()} device(s).",
        "",
        f"Load average before the run: {load_before}.",
        "",
        "## Paths (random vertex pairs; median CPU ms per query after the first;"
        " ratios from the same run)",
        "",
        "Peak RSS is the process's peak so far (meshes run in increasing size).",
        "",
        markdown(rows),
        "",
        "## System (16) on every edge of a 20k-face catenoid",
        "",
        markdown([solve]),
    ]
    if million:
        text += ["", "## One path on a 1M-face catenoid", "", markdown([million])]
    text.append(END_MARK)
    kept = ""
    if os.path.exists(args.output):
        old = open(args.output).read()
        if END_MARK in old:
            kept = old.split(END_MARK, 1)[1]
    with open(args.output, "w") as fh:
        fh.write("\n".join(text) + kept.rstrip("\n") + "\n")
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
