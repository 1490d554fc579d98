"""Speed of jaxgeo against the C++ geodesic libraries, measured in one run.

    pip install -e ".[bench]"
    python benchmarks/bench_paths.py            # writes benchmarks/RESULTS.md
    python benchmarks/bench_paths.py --quick    # smaller meshes, fewer repeats

For an icosphere and a catenoid at about 5k, 20k and 100k faces, the same
vertex-to-vertex queries run through jaxgeo (each method in METHODS: single paths,
and a batch of 1,000 with `shortest_paths`), potpourri3d's
`EdgeFlipGeodesicSolver` and pygeodesic's exact MMP. Times are medians over the
queries after a warm-up call (JIT compilation is timed separately); ratios
jaxgeo/peer come from the same run. It also times the batched all-edges System (16)
solve against the closed form alone on the same edges, and one path on a 1M-face
mesh with the process's peak memory.
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
    """(name, vertices, faces) at about 5k, 20k, 100k faces (quick: 5k, 20k)."""
    sizes = [(4, 50, 52), (5, 100, 100), (6, 224, 224)]
    for sub, n_around, n_height in sizes[: 2 if quick else 3]:
        v, f = surfaces.icosphere(sub)
        yield f"icosphere {len(f) // 1000}k", v, f
        v, f = surfaces.catenoid(n_around, n_height)
        yield f"catenoid {len(f) // 1000}k", v, f


def query_pairs(name: str, v: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """Vertex pairs far apart: on the sphere 60°–150°; on the catenoid from the
    lower ring to the upper ring (across the neck)."""
    rng = np.random.default_rng(seed)
    pairs = []
    if name.startswith("catenoid"):
        lower = np.flatnonzero(np.isclose(v[:, 2], v[:, 2].min()))
        upper = np.flatnonzero(np.isclose(v[:, 2], v[:, 2].max()))
        while len(pairs) < n:
            i, j = rng.choice(lower), rng.choice(upper)
            dth = np.angle(
                np.exp(
                    1j * (np.arctan2(v[j, 1], v[j, 0]) - np.arctan2(v[i, 1], v[i, 0]))
                )
            )
            if abs(dth) < np.radians(100):
                pairs.append((i, j))
    else:
        u = v / np.linalg.norm(v, axis=1, keepdims=True)
        while len(pairs) < n:
            i, j = rng.integers(len(v), size=2)
            ang = np.degrees(np.arccos(np.clip(u[i] @ u[j], -1, 1)))
            if 60 <= ang <= 150:
                pairs.append((i, j))
    return np.array(pairs)


def bench_mesh(name, v, f, n_queries, n_batch, rows, peers):
    mesh = jg.Mesh(v, f)
    pairs = query_pairs(name, v, n_queries)
    row = {"mesh": name, "faces": len(f)}
    for method in METHODS:
        t0 = time.perf_counter()
        jg.shortest_path(mesh, v[pairs[0, 0]], v[pairs[0, 1]], method=method)
        row[f"{method} compile+first s"] = time.perf_counter() - t0
        times = []
        for i, j in pairs:
            t0 = time.perf_counter()
            jax.block_until_ready(
                jg.shortest_path(mesh, v[i], v[j], method=method).length
            )
            times.append(time.perf_counter() - t0)
        row[f"{method} ms"] = 1e3 * statistics.median(times)
    if n_batch:
        big = query_pairs(name, v, n_batch, seed=1)
        p1, p2 = v[big[:, 0]], v[big[:, 1]]
        jg.shortest_paths(mesh, p1[:256], p2[:256], chunk_size=256)  # compile
        t0 = time.perf_counter()
        jg.shortest_paths(mesh, p1, p2, chunk_size=256, throw=False)
        row["laser batch paths/s"] = n_batch / (time.perf_counter() - t0)
    if "pp3d" in peers:
        solver = peers["pp3d"].EdgeFlipGeodesicSolver(v, f)
        solver.find_geodesic_path(int(pairs[0, 0]), int(pairs[0, 1]))
        row["pp3d ms"] = 1e3 * statistics.median(
            [
                _timed(lambda i=i, j=j: solver.find_geodesic_path(int(i), int(j)))
                for i, j in pairs
            ]
        )
        row["pp3d paths/s"] = 1e3 / row["pp3d ms"]
    if "pygeodesic" in peers and len(f) <= 30_000:
        algo = peers["pygeodesic"].PyGeodesicAlgorithmExact(v, f)
        row["pygeodesic ms"] = 1e3 * statistics.median(
            [
                _timed(lambda i=i, j=j: algo.geodesicDistance(int(i), int(j)))
                for i, j in pairs[:3]
            ]
        )
    row["peak RSS MB"] = peak_rss_mb()
    rows.append(row)
    print(row, file=sys.stderr, flush=True)


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


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
    ap.add_argument("--queries", type=int, default=10)
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--no-million", action="store_true")
    ap.add_argument("--output", default=os.path.join(HERE, "RESULTS.md"))
    args = ap.parse_args(argv)
    peers = {}
    for name in ("potpourri3d", "pygeodesic.geodesic"):
        try:
            peers["pp3d" if name == "potpourri3d" else "pygeodesic"] = __import__(
                name, fromlist=["_"]
            )
        except ImportError:
            print(f"{name} not installed: skipped", file=sys.stderr)
    rows: list[dict] = []
    for name, v, f in meshes(args.quick):
        batch = (
            args.batch
            if name.startswith("catenoid") and 15_000 < len(f) < 30_000
            else 0
        )
        bench_mesh(name, v, f, args.queries, batch, rows, peers)
    for r in rows:
        for m in METHODS:
            if "pp3d ms" in r:
                r[f"{m}/pp3d"] = r[f"{m} ms"] / r["pp3d ms"]
            if "pygeodesic ms" in r:
                r[f"{m}/pygeodesic"] = r[f"{m} ms"] / r["pygeodesic ms"]
        if "laser batch paths/s" in r and "pp3d paths/s" in r:
            r["batch/pp3d throughput"] = r["laser batch paths/s"] / r["pp3d paths/s"]
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
        "## Paths (median per query after warm-up; ratios from the same run)",
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
    with open(args.output, "w") as fh:
        fh.write("\n".join(text) + "\n")
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
