"""Cost of a gradient: value vs value-and-gradient of a path length.

    python benchmarks/bench_gradients.py [--repeats 20] [--pairs 5]

On a catenoid of about 5k faces, for a few endpoint pairs across the neck, times
`jax.jit` of `path_length` (trace + replay) and of `jax.value_and_grad` of it with
respect to the vertices and both 3-D endpoints. Compilation is timed separately;
each time is the median over repeats after a warm-up call. Prints a Markdown table
with the ratio (issue 4 asks for value-and-gradient ≤ 5× the value) and the
machine it ran on.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402


def median_time(fn, repeats: int) -> float:
    jax.block_until_ready(fn())  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def compile_time(jitted, *args) -> tuple[float, object]:
    t0 = time.perf_counter()
    compiled = jitted.lower(*args).compile()
    return time.perf_counter() - t0, compiled


def endpoint_pairs(mesh: jg.Mesh, n: int, seed: int = 0) -> list[tuple]:
    """Face centroids near the lower and the upper ring, less than 100° apart."""
    rng = np.random.default_rng(seed)
    centroids = np.asarray(mesh.vertices)[np.asarray(mesh.faces)].mean(axis=1)
    z = centroids[:, 2]
    lower = np.flatnonzero(z < z.min() + 0.1 * np.ptp(z))
    upper = np.flatnonzero(z > z.max() - 0.1 * np.ptp(z))
    angle = np.arctan2(centroids[:, 1], centroids[:, 0])
    pairs = []
    while len(pairs) < n:
        i, j = rng.choice(lower), rng.choice(upper)
        if abs(np.angle(np.exp(1j * (angle[j] - angle[i])))) < np.radians(100):
            pairs.append((centroids[i], centroids[j]))
    return pairs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--pairs", type=int, default=5)
    args = parser.parse_args()

    v, f = surfaces.catenoid(50, 52)  # 5200 faces
    mesh = jg.Mesh(v, f)
    pairs = endpoint_pairs(mesh, args.pairs)

    def length(vertices, p1, p2):
        return jg.path_length(mesh.with_vertices(vertices), p1, p2)

    value = jax.jit(length)
    value_and_grad = jax.jit(jax.value_and_grad(length, argnums=(0, 1, 2)))
    v0 = mesh.vertices
    compile_value, value = compile_time(value, v0, *pairs[0])
    compile_grad, value_and_grad = compile_time(value_and_grad, v0, *pairs[0])

    rows = []
    for p1, p2 in pairs:
        t_value = median_time(lambda p1=p1, p2=p2: value(v0, p1, p2), args.repeats)
        t_grad = median_time(
            lambda p1=p1, p2=p2: value_and_grad(v0, p1, p2), args.repeats
        )
        crossings = int(jg.shortest_path(mesh, p1, p2).count) - 2
        rows.append((crossings, t_value, t_grad))

    print(f"## Value vs value-and-gradient, catenoid {len(f)} faces\n")
    print(
        f"Machine: {platform.platform()}, {platform.processor() or 'cpu'}, "
        f"{os.cpu_count()} CPUs, jax {jax.__version__} "
        f"({jax.devices()[0].platform}), float64; median of {args.repeats} "
        "repeats after a warm-up call.\n"
    )
    print("| pair | crossings | value ms | value+grad ms | ratio |")
    print("| --- | --- | --- | --- | --- |")
    for k, (crossings, t_value, t_grad) in enumerate(rows):
        print(
            f"| {k} | {crossings} | {1e3 * t_value:.2f} | {1e3 * t_grad:.2f} "
            f"| {t_grad / t_value:.2f} |"
        )
    ratios = [t_grad / t_value for _, t_value, t_grad in rows]
    print(
        f"\nMedian ratio {statistics.median(ratios):.2f}, worst {max(ratios):.2f} "
        "(acceptance: ≤ 5). Compile: value "
        f"{compile_value:.1f} s, value-and-grad {compile_grad:.1f} s."
    )


if __name__ == "__main__":
    main()
