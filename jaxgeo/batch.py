"""Many geodesics at once: `shortest_paths`, chunked, vmapped and sharded.

A batch of endpoint pairs is cut into chunks of a fixed size (the last one padded),
so every chunk has the same shape and the solver compiles once; a batch smaller
than a chunk gets the next power of two ≥ its size instead (`chunk_size_for`).
Each chunk runs through the same pipeline as a single path (`geodesic.solve`), its
pairs as lanes of one compiled loop. With several devices, each chunk's batch axis
is split across them with `jax.sharding` (the mesh is replicated); the chunk size
is rounded up to a multiple of the device count. Pairs are solved in the order
of their chord `|p2 - p1|` (`_by_chord`) and returned in the order given.
"""

from __future__ import annotations

import itertools
import zlib
from collections.abc import Callable
from functools import partial
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec
from jaxtyping import ArrayLike

from ._checks import check_batch_options, check_point_batch
from ._errors import JaxgeoError
from .geodesic import as_surface_point, checked_method, solve
from .locate import DEFAULT_MAX_DISTANCE, SurfacePoint
from .mesh import Mesh
from .methods import Method, first_attempts
from .normals import Weighting
from .path import Path, Status

#: Endpoints located together by `jax.lax.map` in `_solve_chunk`.
_LOCATE_BATCH = 4


@eqx.filter_jit
def _solve_chunk(mesh, p1, p2, v1, v2, max_distance, method, max_points):
    # Locating scans every face's bounding sphere once per point. Vmapped over a
    # whole chunk its (chunk, faces) temporaries leave the cache: 256 points on a
    # 20k-face mesh took 123 ms vmapped, 76 ms as `lax.map` in groups of 4.
    # Rows with a vertex index (v ≥ 0, its position in p) start at the vertex:
    # one compiled function serves points, indices and a mix of both.
    def locate_all(points, vertex):
        sp, d = jax.lax.map(
            lambda p: as_surface_point(mesh, p), points, batch_size=_LOCATE_BATCH
        )
        at = jax.vmap(lambda i: SurfacePoint.vertex(mesh, i))(jnp.maximum(vertex, 0))
        by_index = vertex >= 0
        sp = jax.tree.map(
            lambda a, b: jnp.where(by_index.reshape((-1,) + (1,) * (a.ndim - 1)), a, b),
            at,
            sp,
        )
        return sp, jnp.where(by_index, 0.0, d)

    (start, d1), (end, d2) = locate_all(p1, v1), locate_all(p2, v2)
    # leaves as numpy afterwards: nothing differentiates them, so no replay
    return solve(mesh, start, end, d1, d2, max_distance, method, max_points, False)


def _as_rows(mesh: Mesh, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A checked batch of endpoints as (3-D points `(N, 3)`, vertex indices `(N,)`,
    −1 where the row is a point): vertex rows carry their vertex's position."""
    if x.ndim == 1:
        return np.asarray(mesh.vertices)[x], x.astype(np.int32)
    return x, np.full(x.shape[0], -1, np.int32)


#: How long a process waits for the others to finish compiling a chunk (ms).
_BARRIER_MS = 30 * 60 * 1000


_barriers = itertools.count()  # every process counts its calls alike


def _wait_for_all_processes() -> None:
    """A barrier through JAX's coordination service, before a collective. Gloo
    gives a collective 30 s for every process to join, and a process may still be
    compiling the solver long after another reached the gather (seen on 2 shared
    cores: `Gloo context initialization failed: DEADLINE_EXCEEDED`)."""
    from jax._src import distributed  # the barrier has no public API yet

    client = distributed.global_state.client
    if client is not None:
        client.wait_at_barrier(f"jaxgeo-{next(_barriers)}", _BARRIER_MS)


def _gather(x) -> np.ndarray:
    """A (possibly globally sharded) array as numpy on this process."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)


def _check_same_on_all_processes(mesh: Mesh, a: np.ndarray, b: np.ndarray) -> None:
    """Raise on every process if the processes were given different meshes or
    pairs: each solves only its own shards of its own copy, so a mismatch would
    give a silently mixed result. One small all-gather of checksums."""
    from jax.experimental import multihost_utils

    parts = (a, b, np.asarray(mesh.vertices), np.asarray(mesh.faces))
    # (an ndarray is a buffer; numpy's stubs say so only for Python >= 3.12)
    sums = np.array([zlib.crc32(np.ascontiguousarray(x)) for x in parts], np.uint32)  # pyright: ignore[reportArgumentType]
    every = np.asarray(multihost_utils.process_allgather(sums))  # (processes, 4)
    differ = np.flatnonzero(np.any(every != every[0], axis=1))
    if differ.size:
        raise JaxgeoError(
            "shortest_paths across processes needs the same mesh, p1 and p2 on "
            f"every process; process(es) {differ.tolist()} differ from process 0"
        )


def _device_sharding() -> NamedSharding | None:
    devices = jax.devices()
    if len(devices) < 2:
        return None
    grid = jax.sharding.Mesh(np.asarray(devices), ("batch",))
    return NamedSharding(grid, PartitionSpec("batch"))


#: rows solved again per compiled call when they outgrew a cheaper attempt
RETRY_CHUNK = 32


def _set_rows(rows: np.ndarray, x, y):
    """`x` (numpy, rows of a chunk) with `rows` replaced by `y`."""
    x = np.array(x, copy=True)
    x[rows] = y
    return x


def _padded(p1, p2, v1, v2, real: int):
    """A chunk's rows `(p1, p2, v1, v2)` whose rows past the first `real` (padding,
    copies of a real row) end where they start: a path of length zero builds no
    start, where the copy could be the chunk's slowest path (a retried sub-chunk
    of one long pair padded with 31 copies of it took 3.3 s instead of 0.5; 20k
    catenoid)."""
    pad = np.arange(p1.shape[0]) >= real
    return p1, jnp.where(pad[:, None], p1, p2), v1, jnp.where(pad, v1, v2)


def _by_chord(pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
    """The order in which to solve the rows with 3-D endpoints `pa`, `pb`: by
    their chord's length. A chunk's compiled loop runs until its slowest start
    has converged, and its workers idle meanwhile (`exact._refine`); pairs of
    like length in one chunk make its tail shorter. 1,000 random pairs in chunks
    of 256, CPU paths/s: 20k catenoid 85-87 → 93-94, `airplane.obj` 13.6 →
    15.1 (`benchmarks/RESULTS.md`, session 26); the lengths are identical."""
    return np.argsort(np.linalg.norm(pb - pa, axis=1), kind="stable")


def chunk_size_for(n: int, chunk_size: int | np.integer) -> int:
    """The chunk size for a batch of `n` pairs: `chunk_size`, or for a smaller
    batch the next power of two ≥ `n` (capped at `chunk_size`), so that a small
    batch does not solve `chunk_size` lanes of padding and the compiled sizes stay
    a small set (1, 2, 4, …, `chunk_size`)."""
    return min(int(chunk_size), 1 << max(n - 1, 0).bit_length())


def shortest_paths(
    mesh: Mesh,
    p1: ArrayLike,
    p2: ArrayLike,
    *,
    method: Method = "exact",
    candidates: Literal["local", "all"] | None = None,
    max_points: int | np.integer = 1024,
    normals: Weighting | None = None,
    max_distance: float = DEFAULT_MAX_DISTANCE,
    chunk_size: int | np.integer = 256,
    shard: bool = True,
    throw: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Geodesics between the rows of `p1` and `p2`, each `(N, 3)` 3-D points or
    an integer array `(N,)` of vertex indices.

    **Arguments:** as `shortest_path`, and

    - `chunk_size`: pairs solved per compiled call (bounds memory: about
      `chunk_size · max_points` path entries at a time). A batch smaller than
      `chunk_size` runs in one chunk of the next power of two ≥ N instead. Repeated
      calls with the same options compile at most once per size 1, 2, 4, …,
      `chunk_size`, whatever N is.
    - `shard`: split each chunk across all devices (`jax.devices()`) when there are
      several.
    - `throw`: raise `JaxgeoError` naming the failed rows, once the whole batch
      is solved, if any path is not complete (the result is numpy: nothing here
      is traced, so this is always the eager check). With `throw=False` check
      `paths.status` (`paths.outcomes`, a list of `Status`); failed rows have
      NaN `length`.
    - `progress`: called as `progress(done, total)` after each chunk.

    **Returns:** a `Path` whose arrays (its endpoints `start` and `end` too)
    have a leading batch axis of length N.
    """
    m, max_points = checked_method(
        mesh, method, candidates, max_points, normals, max_distance, throw
    )
    check_batch_options(chunk_size, shard, progress)
    a, b = check_point_batch("p1", p1, mesh), check_point_batch("p2", p2, mesh)
    if a.shape[0] != b.shape[0]:
        raise JaxgeoError(
            f"p1 and p2 must have the same shape (or one (N, 3) and one (N,)), got "
            f"{a.shape} and {b.shape}"
        )
    if chunk_size < 1:
        raise JaxgeoError(f"chunk_size must be positive, got {chunk_size}")
    n = a.shape[0]
    if n == 0:
        raise JaxgeoError("empty batch: p1 and p2 have no rows")
    if jax.process_count() > 1:
        _check_same_on_all_processes(mesh, a, b)
    chunk_size = chunk_size_for(n, chunk_size)
    sharding = _device_sharding() if shard else None
    if sharding is not None:
        n_dev = sharding.mesh.size
        chunk_size = -(-chunk_size // n_dev) * n_dev
    dtype = mesh.vertices.dtype
    (pa, va), (pb, vb) = _as_rows(mesh, a), _as_rows(mesh, b)
    order = _by_chord(pa, pb)
    pa, pb, va, vb = pa[order], pb[order], va[order], vb[order]
    limit = jnp.asarray(max_distance, dtype)  # an array: no recompile per value
    padded = mesh.padded()  # padded to its size class: compiled once per class
    attempts = first_attempts(m, max_points)
    # on one process without sharding, only the rows that outgrew an attempt
    # are solved again (in sub-chunks of fixed size: one compile per size);
    # else the whole chunk again with `m` (the same decision on every process)
    rows_only = sharding is None and jax.process_count() == 1
    pieces = []
    for start in range(0, n, chunk_size):
        stop = min(start + chunk_size, n)
        idx = np.minimum(np.arange(start, start + chunk_size), n - 1)  # then `_padded`
        p1, p2, v1, v2 = _padded(pa[idx], pb[idx], va[idx], vb[idx], stop - start)
        chunk = [
            jnp.asarray(p1, dtype),
            jnp.asarray(p2, dtype),
            jnp.asarray(v1),
            jnp.asarray(v2),
        ]
        if sharding is not None:
            chunk = [jax.device_put(x, sharding) for x in chunk]

        def run(method, chunk=chunk, k=stop - start):
            # (pyright misreads *args of unknown length followed by more arguments)
            paths = _solve_chunk(padded, *chunk, limit, method, max_points)  # pyright: ignore[reportCallIssue]
            if jax.process_count() > 1:
                jax.block_until_ready(paths)
                _wait_for_all_processes()
            return jax.tree.map(lambda y: _gather(y)[:k], paths)

        # a cheaper first attempt where one exists; the pairs that outgrew it
        # again (gathered stats: the same decision on every process)
        piece = run(attempts[0]) if attempts else None
        if piece is not None and rows_only:
            size = min(RETRY_CHUNK, chunk_size)
            for method in [*attempts[1:], m]:
                rows = np.flatnonzero(np.asarray(piece.stats.get("outgrew", 0)))
                for r0 in range(0, rows.size, size):
                    sub = rows[r0 : r0 + size]
                    pad = np.concatenate([sub, np.full(size - sub.size, sub[-1])])
                    rows_in = _padded(*[x[pad] for x in chunk], sub.size)
                    again = run(method, list(rows_in), sub.size)
                    piece = jax.tree.map(partial(_set_rows, sub), piece, again)
        elif piece is None or np.any(piece.stats.get("outgrew", 0)):
            piece = run(m)
        pieces.append(piece)
        if progress is not None:
            progress(stop, n)
    back = np.argsort(order)  # to the order given
    out = jax.tree.map(lambda *xs: np.concatenate(xs)[back], *pieces)
    if throw:
        failed = np.flatnonzero(out.status != Status.SUCCESS)
        if failed.size:
            codes = sorted({Status(int(s)).name for s in out.status[failed]})
            raise JaxgeoError(
                f"{failed.size} of {n} paths failed ({', '.join(codes)}) at rows "
                f"{failed[:10].tolist()}"
                + (" …" if failed.size > 10 else "")
                + f"; first: {Status(int(out.status[failed[0]])).message}"
            )
    return out
