"""Batches of paths: chunked vmap equals single calls, no recompilation for new
batch sizes or distance limits, sharding across (forced) host devices equals the
unsharded result."""

import logging
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import jaxgeo as jg

from .helpers import unit_icosphere

MESH = unit_icosphere(2)


def _pairs(n, seed):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(2, n, 3))
    return p / np.linalg.norm(p, axis=-1, keepdims=True)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_batch_equals_single_paths():
    p1, p2 = _pairs(7, 0)
    paths = jg.shortest_paths(MESH, p1, p2, chunk_size=4)
    assert paths.points.shape == (7, 1024, 3)
    for i in range(7):
        single = jg.shortest_path(MESH, p1[i], p2[i])
        n = int(single.count)
        assert n == int(paths.count[i])
        # The batch runs one loop over all lanes (`trace_batch`); lanes that finish
        # early must be left as they were: same elements, points to rounding.
        np.testing.assert_array_equal(paths.kinds[i, :n], single.kinds[:n])
        np.testing.assert_array_equal(paths.elements[i, :n], single.elements[:n])
        np.testing.assert_allclose(paths.points[i], single.points, rtol=0, atol=1e-12)
        np.testing.assert_allclose(paths.length[i], float(single.length), rtol=1e-12)


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_new_batch_sizes_do_not_recompile(caplog):
    p1, p2 = _pairs(9, 1)
    jg.shortest_paths(MESH, p1, p2, chunk_size=4)  # compiles
    jg.shortest_path(MESH, p1[0], p2[0])
    with jax.log_compiles(True), caplog.at_level(logging.WARNING):
        caplog.clear()
        jg.shortest_paths(MESH, p1[:5], p2[:5], chunk_size=4)
        jg.shortest_paths(MESH, p1[:3], p2[:3], chunk_size=4)
        # nor does a new max_distance (an array argument, not a static one)
        jg.shortest_paths(MESH, p1, p2, chunk_size=4, max_distance=2)
        jg.shortest_path(MESH, p1[1], p2[1], max_distance=2)
    compiles = [r for r in caplog.records if "Compiling" in r.getMessage()]
    assert not compiles, [r.getMessage()[:120] for r in compiles]


def test_chunk_size_from_the_batch():
    """A batch smaller than `chunk_size` runs in a chunk of the next power of two
    ≥ its size (capped at `chunk_size`): the compiled sizes are 1, 2, 4, …"""
    from jaxgeo.batch import chunk_size_for

    assert [chunk_size_for(n, 256) for n in (1, 2, 3, 4, 5, 30, 129, 256)] == [
        1, 2, 4, 4, 8, 32, 256, 256
    ]  # fmt: skip
    assert chunk_size_for(10**6, 256) == 256
    assert chunk_size_for(70, 100) == 100  # capped, also when not a power of two
    sizes = {chunk_size_for(n, 256) for n in range(1, 1000)}
    assert sizes == {2**k for k in range(9)}


def test_small_batch_does_not_pay_for_the_padding(caplog):
    """3 pairs with the default `chunk_size` (256) run as one chunk of 4: the
    executable compiled for `chunk_size=4` is reused (no compile), and the rows
    equal the padded run's (a 4-chunk with 1 padded lane, and the second chunk of a
    batch of 7 in chunks of 4, 3 padded lanes) bit for bit: lanes are independent."""
    p1, p2 = _pairs(7, 0)
    padded = jg.shortest_paths(MESH, p1, p2, chunk_size=4)
    with jax.log_compiles(True), caplog.at_level(logging.WARNING):
        caplog.clear()
        head = jg.shortest_paths(MESH, p1[:3], p2[:3])
        tail = jg.shortest_paths(MESH, p1[4:], p2[4:])
    compiles = [r for r in caplog.records if "Compiling" in r.getMessage()]
    assert not compiles, [r.getMessage()[:120] for r in compiles]
    assert head.points.shape == (3, 1024, 3)
    for got, rows in ((head, slice(0, 3)), (tail, slice(4, 7))):
        for want, have in zip(
            jax.tree.leaves(jax.tree.map(lambda x, r=rows: x[r], padded)),
            jax.tree.leaves(got),
        ):
            np.testing.assert_array_equal(have, want)


def _spy_on_chunks(monkeypatch) -> list:
    """The rows (p1, p2, v1, v2) of every chunk `shortest_paths` solves."""
    from jaxgeo import batch

    seen = []
    solve_chunk = batch._solve_chunk

    def spy(mesh, p1, p2, v1, v2, *rest):
        seen.append(tuple(np.asarray(x) for x in (p1, p2, v1, v2)))
        return solve_chunk(mesh, p1, p2, v1, v2, *rest)

    monkeypatch.setattr(batch, "_solve_chunk", spy)
    return seen


def _chord(p1, p2):
    return np.linalg.norm(p2 - p1, axis=-1)


def test_padding_rows_are_empty_paths(monkeypatch):
    """The rows that pad a chunk to its compiled size end where they start (a
    path of length zero, which builds no start), not copies of a real row, which
    may be the slowest path of the chunk. The real rows are passed unchanged."""
    seen = _spy_on_chunks(monkeypatch)
    p1, p2 = _pairs(7, 0)
    jg.shortest_paths(MESH, p1, p2, chunk_size=4)  # chunks of 4 and 3 + 1 pad
    chunks = [c for c in seen if c[0].shape[0] == 4]
    assert len(chunks) >= 2
    q1, q2, _, w2 = chunks[1]
    last = np.argsort(_chord(p1, p2), kind="stable")[4:]  # (rows by chord)
    np.testing.assert_array_equal(q1[:3], p1[last])
    np.testing.assert_array_equal(q2[:3], p2[last])
    np.testing.assert_array_equal(q2[3], q1[3])  # the padding row: zero length
    assert w2[3] == -1  # (points, not vertex indices)


def test_rows_are_solved_by_chord_and_returned_as_given(monkeypatch):
    """Chunks get the pairs in the order of their chord (pairs of like length
    together: a shorter tail for each chunk's loop); the result has the order of
    the input, whatever order it came in."""
    seen = _spy_on_chunks(monkeypatch)
    p1, p2 = _pairs(7, 0)
    paths = jg.shortest_paths(MESH, p1, p2, chunk_size=4)
    chords = np.concatenate([_chord(c[0], c[1]) for c in seen[:2]])[:7]
    assert np.all(np.diff(chords) >= 0)
    flip = np.arange(7)[::-1]
    again = jg.shortest_paths(MESH, p1[flip], p2[flip], chunk_size=4)
    np.testing.assert_array_equal(again.length, paths.length[flip])
    np.testing.assert_array_equal(again.start.face, paths.start.face[flip])
    np.testing.assert_array_equal(again.points, paths.points[flip])


@pytest.mark.mistyped
def test_bad_batches_raise():
    p1, p2 = _pairs(3, 2)
    with pytest.raises(jg.JaxgeoError, match="same shape"):
        jg.shortest_paths(MESH, p1, p2[:2])
    with pytest.raises(jg.JaxgeoError, match=r"shape \(N, 3\)"):
        jg.shortest_paths(MESH, p1[:, :2], p2[:, :2])
    bad = p1.copy()
    bad[1, 0] = np.nan
    with pytest.raises(jg.JaxgeoError, match="NaN"):
        jg.shortest_paths(MESH, bad, p2)
    far = p1 * 3
    with pytest.raises(
        jg.JaxgeoError, match=r"3 of 3 paths failed \(FAR_FROM_SURFACE\)"
    ):
        jg.shortest_paths(MESH, far, p2, chunk_size=4)
    out = jg.shortest_paths(MESH, far, p2, chunk_size=4, throw=False)
    assert np.all(out.status == jg.Status.FAR_FROM_SURFACE)


SHARDED = textwrap.dedent(
    """
    import jax, numpy as np
    jax.config.update("jax_enable_x64", True)
    assert jax.device_count() == 4, jax.devices()
    import jaxgeo as jg
    from tests.helpers import unit_icosphere
    mesh = unit_icosphere(2)
    rng = np.random.default_rng(0)
    p = rng.normal(size=(2, 10, 3))
    p /= np.linalg.norm(p, axis=-1, keepdims=True)
    a = jg.shortest_paths(mesh, p[0], p[1], chunk_size=4)
    b = jg.shortest_paths(mesh, p[0], p[1], chunk_size=4, shard=False)
    np.testing.assert_array_equal(a.count, b.count)
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=1e-14)
    print("sharded ok")
    """
)


@pytest.mark.slow  # 4 host devices in a subprocess compile again: ~23 s cold
def test_sharded_batch_equals_unsharded():
    """Four forced host devices (the flag must be set before JAX starts, hence a
    subprocess); the batch axis is split across them."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run(
        [sys.executable, "-c", SHARDED],
        env=env,
        cwd=root,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "sharded ok" in out.stdout


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_symmetric_catenoid_pair_through_the_axis_completes():
    """Endpoints point-symmetric about the catenoid's centre: the chord runs through
    the axis, where every normal line meets it. The trace once bounced between two
    ring edges until MAX_STEPS (and held up its whole vmapped chunk)."""
    from jaxgeo import surfaces

    v, f = surfaces.catenoid()
    mesh = jg.Mesh(v, f)
    low = np.flatnonzero(np.isclose(v[:, 2], v[:, 2].min()))
    a = v[low[7]]
    b = a * np.array([-1.0, -1.0, -1.0])  # on the upper ring, opposite side
    path = jg.shortest_path(mesh, a, b)
    assert int(path.status) == jg.Status.SUCCESS
    assert int(path.count) < 4 * np.sqrt(mesh.n_faces)


@pytest.mark.slow  # compiles three corridor capacities, batch and single: ~60 s
def test_pairs_that_outgrow_a_cheaper_attempt_are_solved_again(monkeypatch):
    """The exact engine tries cheaper corridor capacities first
    (`methods.FIRST_CAPACITIES`); a pair whose corridor outgrew one is solved
    again by the next (a batch: only those rows, in sub-chunks of
    `batch.RETRY_CHUNK`; a single path: the first attempt, then the full
    capacity). Shrunk here to 24 and 32 faces so that pairs of a
    small icosphere outgrow both (10 and 5 of 12): every result equals the one
    solved at the full capacity directly (the same corridors, padded
    differently: lengths to rounding, 1e-12 relative)."""
    from jaxgeo import batch, methods

    p1, p2 = _pairs(12, 2)
    direct = jg.shortest_paths(
        MESH, p1, p2, chunk_size=16, method=jg.Exact(corridor_capacity=1024)
    )
    small = jg.shortest_paths(
        MESH, p1, p2, chunk_size=16, method=jg.Exact(corridor_capacity=24),
        throw=False,
    )  # fmt: skip
    # the test means something: pairs outgrow the smallest capacity
    assert 3 <= int(np.sum(small.stats["outgrew"])) < 12
    monkeypatch.setattr(methods, "FIRST_CAPACITIES", (24, 32))
    monkeypatch.setattr(batch, "RETRY_CHUNK", 4)
    retried = jg.shortest_paths(MESH, p1, p2, chunk_size=16)
    assert np.all(retried.status == 0) and not np.any(retried.stats["outgrew"])
    np.testing.assert_allclose(retried.length, direct.length, rtol=1e-12)
    np.testing.assert_array_equal(retried.count, direct.count)
    for i in np.flatnonzero(small.stats["outgrew"])[:2]:
        single = jg.shortest_path(MESH, p1[i], p2[i])
        np.testing.assert_allclose(float(single.length), direct.length[i], rtol=1e-12)
