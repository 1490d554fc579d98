"""Where the exact default stands against potpourri3d on random vertex pairs of a
20k-face catenoid: single-path and batch throughput, in CPU time as well as wall
time (CPU time is what to compare on a shared machine), with the engine's own
counters (flip rounds, corridor length) that explain it.

    python benchmarks/exact_speed.py                  # 30 single paths, a batch of 256
    python benchmarks/exact_speed.py --pairs 10 --batch 64
    python benchmarks/exact_speed.py --mesh bone.ply  # a scan shipped with pymeshlab

Printed, not written to RESULTS.md: the figures go into the notes with the command.
"""

from __future__ import annotations

import argparse
import time

import jax
from _samples import pymeshlab_sample, referenced

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402


def clocks():
    return time.perf_counter(), time.process_time()


def since(t):
    w, c = clocks()
    return w - t[0], c - t[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=30)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--chunk", type=int, default=64)
    ap.add_argument(
        "--mesh",
        default="catenoid",
        help="catenoid (20k faces) or a sample mesh of pymeshlab (bone.ply, cow.obj)",
    )
    ap.add_argument(
        "--starts", type=int, default=None, help="Exact(max_starts=...) (default: its)"
    )
    ap.add_argument("--detours", type=int, default=None, help="Exact(detours=N)")
    ap.add_argument("--detour-rounds", type=int, default=None)
    ap.add_argument("--no-walls", action="store_true", help="Exact(walls=False)")
    args = ap.parse_args()
    import potpourri3d as pp3d

    options = {
        "max_starts": args.starts,
        "detours": args.detours,
        "detour_rounds": args.detour_rounds,
        "walls": False if args.no_walls else None,
    }
    method = jg.Exact(**{k: x for k, x in options.items() if x is not None})
    print(method)

    if args.mesh == "catenoid":
        mesh = jg.Mesh(*surfaces.catenoid(n_around=100, n_height=100))
    else:
        path = pymeshlab_sample(args.mesh)
        if path is None:
            raise SystemExit(f"{args.mesh}: no such sample mesh in pymeshlab")
        mesh = referenced(jg.load_mesh(path))
    print(f"{args.mesh}: {mesh.n_faces} faces, {mesh.n_vertices} vertices")
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    rng = np.random.default_rng(0)
    pairs = rng.integers(0, len(v), (max(args.pairs, args.batch), 2))
    solver = pp3d.EdgeFlipGeodesicSolver(v, f)
    t = clocks()
    for a, b in pairs[: args.batch]:
        solver.find_geodesic_path(int(a), int(b))
    pw, pc = since(t)
    print(
        f"potpourri3d: {1e3 * pc / args.batch:.2f} ms CPU per path "
        f"({args.batch / pc:.0f} paths/s CPU, {args.batch / pw:.0f} wall)"
    )

    t = clocks()
    jg.shortest_path(mesh, int(pairs[0, 0]), int(pairs[0, 1]), method=method)
    print(f"exact: compile + first path {since(t)[0]:.1f} s wall")
    cpu, rounds, corridor = [], [], []
    for a, b in pairs[: args.pairs]:
        t = clocks()
        p = jg.shortest_path(mesh, int(a), int(b), method=method)
        jax.block_until_ready(p.length)
        cpu.append(since(t)[1])
        rounds.append(int(p.stats["iterations"]))
        corridor.append(int(p.stats["corridor_length"]))
    med = 1e3 * float(np.median(cpu))
    ratio = med / (1e3 * pc / args.batch)
    print(
        f"exact single path: median {med:.1f} ms CPU = {ratio:.0f}"
        f"x potpourri3d; flip rounds of the winner mean {np.mean(rounds):.1f} "
        f"(max {max(rounds)}), corridor faces mean {np.mean(corridor):.0f}"
    )

    p1, p2 = pairs[: args.batch, 0], pairs[: args.batch, 1]
    kw = dict(chunk_size=args.chunk, method=method)
    jg.shortest_paths(mesh, p1[: args.chunk], p2[: args.chunk], **kw)
    t = clocks()
    out = jg.shortest_paths(mesh, p1, p2, throw=False, **kw)
    bw, bc = since(t)
    print(
        f"exact batch of {args.batch} (chunks of {args.chunk}): {args.batch / bc:.1f} "
        f"paths/s CPU, {args.batch / bw:.1f} wall = {pc / bc:.3f}"
        f"x potpourri3d's single-query throughput (CPU); failures "
        f"{int(np.sum(out.status != 0))}"
    )


if __name__ == "__main__":
    main()
