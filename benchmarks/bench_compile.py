"""Compile time and size classes: what the first path on a new mesh costs.

    python benchmarks/bench_compile.py             # prints a markdown section
    python benchmarks/bench_compile.py --method smooth

Each phase runs in a new Python process, with the persistent compilation cache in
a fresh temporary directory:

(a) cold: a new 20k-face catenoid (`surfaces.catenoid(100, 100)`): the mesh build
    (`Mesh.__init__`, of which the landmark forests, timed again on their own), the
    padding to its size class, and the first path, split by JAX's compile events
    into tracing (Python → jaxpr), lowering (jaxpr → StableHLO) and the XLA compile;
(b) a second, different mesh of the same size class (a 21.6k-face cone tent) in
    the same process: its first path (target ≤ 1 s: no compile at all);
(c) a new process with the cache of (a) on disk: the catenoid's first path (no
    XLA compile: tracing, lowering and a cache read).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import defaultdict

EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
    "/jax/compilation_cache/cache_retrieval_time_sec": "cache read",
}

P1, P2 = [1.0, 0.0, -0.5], [-0.5, 0.866, 0.5]  # on the catenoid (README)


def _phase(name: str, cache: str, method: str) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.monitoring
    import numpy as np

    import jaxgeo as jg
    from jaxgeo import surfaces
    from jaxgeo._landmarks import landmark_forests

    jg.enable_compilation_cache(cache)
    seen: dict[str, float] = defaultdict(float)

    def listen(event, duration, **kw):
        if event in EVENTS:
            solver = "_solve_one" in str(kw.get("fun_name", ""))
            seen[EVENTS[event] + ("" if solver else " (other)")] += duration

    jax.monitoring.register_event_duration_secs_listener(listen)

    def timed(f):
        seen.clear()
        t = time.perf_counter()
        out = f()
        return out, time.perf_counter() - t, dict(seen)

    out: dict = {}
    v, f = surfaces.catenoid(n_around=100, n_height=100)
    mesh, out["build_s"], _ = timed(lambda: jg.Mesh(v, f))
    out["faces"] = mesh.n_faces
    out["class"] = list(mesh.size_class)
    comp = np.zeros(mesh.n_vertices, int)  # the catenoid: one component
    edges, face_edges = np.asarray(mesh.edges), np.asarray(mesh.face_edges)
    _, out["landmarks_s"], _ = timed(
        lambda: landmark_forests(np.asarray(v), np.asarray(f), edges, face_edges, comp)
    )
    _, out["pad_s"], _ = timed(mesh.padded)
    path, out["first_s"], out["first_parts"] = timed(
        lambda: jg.shortest_path(mesh, P1, P2, method=method)
    )
    out["length"] = float(path.length)
    _, out["again_s"], _ = timed(lambda: jg.shortest_path(mesh, P2, P1, method=method))
    if name == "cold":
        tv, tf = surfaces.cone_tent(n_around=120, n_radial=90)
        tent, out["second_build_s"], _ = timed(lambda: jg.Mesh(tv, tf))
        out["second_faces"] = tent.n_faces
        out["second_class"] = list(tent.size_class)
        w = np.asarray(tent.vertices)
        a, b = w[5], w[len(w) * 3 // 4 + 60]  # rim to near the peak ring
        path, out["second_first_s"], out["second_parts"] = timed(
            lambda: jg.shortest_path(tent, a, b, method=method)
        )
        out["second_status"] = path.outcome.name
    return out


def _run(name: str, cache: str, method: str) -> dict:
    cmd = [sys.executable, __file__, "--phase", name, "--cache", cache]
    res = subprocess.run(
        cmd + ["--method", method], capture_output=True, text=True, check=True
    )
    return json.loads(res.stdout.strip().splitlines()[-1])


def _parts(parts: dict) -> str:
    return ", ".join(f"{k} {v:.2f}" for k, v in sorted(parts.items())) or "none"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="exact")
    ap.add_argument("--phase", help=argparse.SUPPRESS)
    ap.add_argument("--cache", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.phase:
        print(json.dumps(_phase(args.phase, args.cache, args.method)))
        return
    import jax

    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="jaxgeo-bench-cache-") as cache:
        cold = _run("cold", cache, args.method)
        warm = _run("warm", cache, args.method)
    load1 = os.getloadavg()
    lines = [
        f"## Compile time and size classes (`method={args.method!r}`)",
        "",
        f"Command: `python benchmarks/bench_compile.py --method {args.method}`",
        "",
        f"Machine: {platform.platform()}, {os.cpu_count()} CPUs, jax "
        f"{jax.__version__}; load average {load0[0]:.1f} before, "
        f"{load1[0]:.1f} after (shared machine: compile times scale with it).",
        "",
        "| phase | mesh | faces | size class (V, F, E, B, K) | mesh build s | "
        "first path s | of which (s) | next path s |",
        "|---|---|---|---|---|---|---|---|",
        f"| (a) cold cache | catenoid 100×100 | {cold['faces']} | "
        f"{tuple(cold['class'])} | {cold['build_s']:.2f} (landmarks "
        f"{cold['landmarks_s']:.2f}, padding {cold['pad_s']:.3f}) | "
        f"{cold['first_s']:.2f} | {_parts(cold['first_parts'])} | "
        f"{cold['again_s']:.3f} |",
        f"| (b) same process, same class | cone tent 120×90 | "
        f"{cold['second_faces']} | {tuple(cold['second_class'])} | "
        f"{cold['second_build_s']:.2f} | {cold['second_first_s']:.3f} | "
        f"{_parts(cold['second_parts'])} | |",
        f"| (c) new process, persistent cache | catenoid 100×100 | "
        f"{warm['faces']} | {tuple(warm['class'])} | {warm['build_s']:.2f} | "
        f"{warm['first_s']:.2f} | {_parts(warm['first_parts'])} | "
        f"{warm['again_s']:.3f} |",
        "",
        '"of which": JAX\'s compile events during the first call, for the solver '
        '(`_solve_one`) and other small functions ("(other)"): trace = Python → '
        "jaxpr, lower = jaxpr → StableHLO, compile = XLA (or the persistent cache's "
        "read of its result); the rest is running the path and Python. "
        f"Second mesh's path: {cold['second_status']}.",
    ]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
