"""One process of the multi-process batch tests (tests/test_multiprocess.py).

    python -m tests._multiprocess_worker OUT_DIR PROCESS_ID NUM_PROCESSES PORT ROLE

With NUM_PROCESSES > 1 it joins a JAX cluster whose coordinator (process 0) listens
on 127.0.0.1:PORT; with 1 it runs alone (the reference). Its CPU device count comes
from XLA_FLAGS (--xla_force_host_platform_device_count). ROLE is

- "small": a small batch with one failing row, with `throw=False` and `throw=True`,
  and (in a cluster) a batch that differs on one process;
- "large": a batch streamed in chunks under an address-space cap (`RLIMIT_AS`) of
  3 times its output above what the process holds after compiling;
- "one-shot": the same batch as one chunk under the same cap (by hand, for the
  figures in docs/scaling.md).

All calls use the default method. Results go to OUT_DIR/ROLE-PROCESS_ID.npz and
.json (statuses of the calls, peak memory).
"""

from __future__ import annotations

import json
import resource
import sys
from pathlib import Path

import jax
import numpy as np

#: The small batch: pairs per call, chunk size, path capacity.
SMALL_N, SMALL_CHUNK, SMALL_POINTS = 10, 4, 128
#: The large batch: streamed in chunks of LARGE_CHUNK at the default capacity.
LARGE_N, LARGE_CHUNK, LARGE_POINTS = 2048, 32, 1024
#: The large batch's address-space allowance, in multiples of its output's bytes:
#: streaming measured 1.5-2.5 (the gathered chunks, their concatenation, thread
#: stacks); one chunk of LARGE_N measured 2.8 (its XLA outputs and temporaries,
#: 2.4 for the laser method by XLA's count, then the concatenated copy).
CAP_OUTPUTS = 3.0


def _loopback_gloo() -> None:
    """Bind the gloo CPU collectives to 127.0.0.1. By default gloo binds the address
    the host name resolves to, which on some machines is not loopback. (Private JAX
    API: the CPU backend factory is replaced before the backend exists.)"""
    from jax._src import distributed, xla_bridge
    from jax._src.lib import _jax

    def factory():
        collectives = _jax.make_gloo_tcp_collectives(
            distributed_client=distributed.global_state.client, hostname="127.0.0.1"
        )
        return xla_bridge.make_cpu_client(collectives)

    xla_bridge.register_backend_factory("cpu", factory, priority=0, fail_quietly=False)


def _pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(2, n, 3))
    return tuple(p / np.linalg.norm(p, axis=-1, keepdims=True))


def _memory() -> dict[str, int]:
    """Peak resident set (ru_maxrss) and address space (VmSize, VmPeak), bytes."""
    status = dict(line.split(":", 1) for line in open("/proc/self/status"))
    kib = {k: int(status[k].split()[0]) for k in ("VmSize", "VmPeak")}
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    return {"ru_maxrss": rss * 1024, **{k: v * 1024 for k, v in kib.items()}}


def _save(prefix: str, paths, arrays: dict) -> None:
    """Every array of a `Path` (points, ..., status, and any newer field)."""
    for key, leaf in jax.tree_util.tree_leaves_with_path(paths):
        arrays[prefix + jax.tree_util.keystr(key)] = np.asarray(leaf)


def main(out_dir: str, process_id: int, num_processes: int, port: int, role: str):
    jax.config.update("jax_enable_x64", True)
    if num_processes > 1:
        _loopback_gloo()
        jax.distributed.initialize(
            coordinator_address=f"127.0.0.1:{port}",
            coordinator_bind_address=f"127.0.0.1:{port}",
            num_processes=num_processes,
            process_id=process_id,
            initialization_timeout=60,
            heartbeat_timeout_seconds=30,
        )
    import jaxgeo as jg

    from .helpers import unit_icosphere

    mesh = unit_icosphere(2)
    info = {
        "process_index": jax.process_index(),
        "process_count": jax.process_count(),
        "devices": jax.device_count(),
        "local_devices": jax.local_device_count(),
    }
    arrays: dict[str, np.ndarray] = {}

    if role == "small":
        p1, p2 = _pairs(SMALL_N, 0)
        p1[3] *= 3  # far from the sphere: a FAR_FROM_SURFACE status among successes
        small = dict(chunk_size=SMALL_CHUNK, max_points=SMALL_POINTS)
        _save("small", jg.shortest_paths(mesh, p1, p2, throw=False, **small), arrays)
        try:
            jg.shortest_paths(mesh, p1, p2, **small)
            info["throw"] = None
        except jg.JaxgeoError as e:
            info["throw"] = str(e)
        if num_processes > 1:
            # different pairs on one process: every process must refuse the batch
            q1 = p1.copy()
            if process_id == 1:
                q1[0] = -q1[0]
            try:
                jg.shortest_paths(mesh, q1, p2, throw=False, **small)
                info["mismatch"] = None
            except jg.JaxgeoError as e:
                info["mismatch"] = str(e)
    else:
        p1, p2 = _pairs(LARGE_N, 1)
        large = dict(chunk_size=LARGE_CHUNK, max_points=LARGE_POINTS)
        # compile the streamed chunk (same shapes as below) before the cap is set
        warm = jg.shortest_paths(mesh, p1[:LARGE_CHUNK], p2[:LARGE_CHUNK], **large)
        per_pair = sum(x.nbytes for x in jax.tree.leaves(warm)) // LARGE_CHUNK
        info["output_bytes"] = per_pair * LARGE_N
        info["before"] = _memory()
        # Streaming holds the result twice at most (the gathered chunks and their
        # concatenation) plus one chunk in flight; a single chunk of LARGE_N also
        # needs its XLA output buffers and temporaries (the loop-carried paths).
        cap = info["before"]["VmSize"] + int(CAP_OUTPUTS * info["output_bytes"])
        info["cap"] = cap
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
        if role == "one-shot":
            large["chunk_size"] = LARGE_N
        vm = info["vm_after_chunk"] = []  # VmSize after each chunk
        try:
            paths = jg.shortest_paths(
                mesh,
                p1,
                p2,
                throw=False,
                progress=lambda *_: vm.append(_memory()["VmSize"]),
                **large,
            )
            _save("large", paths, arrays)
            info["error"] = None
        except Exception as e:  # the one-shot's out of memory (XLA or numpy)
            info["error"] = f"{type(e).__name__}: {e}"
        info["after"] = _memory()
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))  # to save the result

    out = Path(out_dir)
    np.savez(out / f"{role}-{process_id}.npz", **arrays)
    (out / f"{role}-{process_id}.json").write_text(json.dumps(info))


if __name__ == "__main__":
    d, pid, n, port, role = sys.argv[1:]
    main(d, int(pid), int(n), int(port), role)
