"""Starting corridors for the exact engine: graph paths through landmarks, turned
into face corridors (JAX, per query; the forests are built once per mesh, see
`jaxgeo._landmarks`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Int

from .mesh import Mesh


def best_slots(
    mesh: Mesh, vs: Int[Array, ""], vt: Int[Array, ""], k: int
) -> tuple[Int[Array, " k"], Bool[Array, " k"]]:
    """The k landmark slots whose graph path s → landmark → t is shortest, and
    whether each connects s and t (same forest root)."""
    via = mesh.landmark_dist[:, vs] + mesh.landmark_dist[:, vt]
    same = (mesh.landmark_root[:, vs] == mesh.landmark_root[:, vt]) & (
        mesh.landmark_root[:, vs] >= 0
    )
    via = jnp.where(same, via, jnp.inf)
    k = min(k, via.shape[0])
    neg, slots = jax.lax.top_k(-via, k)
    return slots, jnp.isfinite(neg)


def vertex_path(
    mesh: Mesh, slot: Int[Array, ""], vs: Int[Array, ""], vt: Int[Array, ""], cap: int
) -> tuple[Int[Array, " cap"], Int[Array, ""], Bool[Array, ""]]:
    """The forest path of `slot` from vs to vt through their lowest common
    ancestor: vertices (cap,), their number, and False if it exceeds `cap`."""
    pred = mesh.landmark_pred[slot]

    def up(v):
        k = pred[v]
        return jnp.where(k >= 0, mesh.fan_spokes[v, jnp.maximum(k, 0)], v), k >= 0

    def body(s):
        a, b, na, nb, buf_a, buf_b, go_a, go_b = s
        buf_a = jnp.where(go_a, buf_a.at[na].set(a, mode="drop"), buf_a)
        buf_b = jnp.where(go_b, buf_b.at[nb].set(b, mode="drop"), buf_b)
        a2, more_a = up(a)
        b2, more_b = up(b)
        return (
            a2,
            b2,
            na + go_a,
            nb + go_b,
            buf_a,
            buf_b,
            go_a & more_a & (na + 1 < cap),
            go_b & more_b & (nb + 1 < cap),
        )

    empty = jnp.full(cap, -1, jnp.int32)
    init = (vs, vt, 0, 0, empty, empty, True, True)
    init = tuple(jnp.asarray(x) for x in init)
    s = jax.lax.while_loop(lambda s: s[6] | s[7], body, init)
    _, _, na, nb, buf_a, buf_b, _, _ = s
    complete = (pred[buf_a[jnp.maximum(na - 1, 0)]] < 0) & (
        pred[buf_b[jnp.maximum(nb - 1, 0)]] < 0
    )
    # common tail (from the root backwards): its length p
    i = jnp.arange(cap)
    ra = buf_a[jnp.clip(na - 1 - i, 0, cap - 1)]
    rb = buf_b[jnp.clip(nb - 1 - i, 0, cap - 1)]
    same = (ra == rb) & (i < jnp.minimum(na, nb))
    p = jnp.argmin(jnp.concatenate([same, jnp.array([False])]))
    count = na + nb - 2 * p + 1
    j = jnp.arange(cap)
    path = jnp.where(
        j <= na - p,
        buf_a[jnp.clip(j, 0, cap - 1)],
        buf_b[jnp.clip(na + nb - 2 * p - j, 0, cap - 1)],
    )
    ok = complete & (count <= cap) & (p >= 1)
    return jnp.where(j < count, path, -1), count.astype(jnp.int32), ok


def face_fan_position(mesh: Mesh, face, vertex):
    """Position of `face` in the fan of its corner `vertex`."""
    corner = jnp.argmax(mesh.faces[face] == vertex)
    return mesh.corner_fan_pos[face, corner]


def _turn(n, closed, p_from, p_to_ccw, p_to_cw):
    """Faces counted from position p_from round a fan of n faces to p_to_ccw going
    counter-clockwise or to p_to_cw going clockwise (the shorter; an open fan only
    where it does not cross the boundary): (direction ±1, count)."""
    n_ = jnp.maximum(n, 1)
    ccw = jnp.where(closed, (p_to_ccw - p_from) % n_, p_to_ccw - p_from) + 1
    cw = jnp.where(closed, (p_from - p_to_cw) % n_, p_from - p_to_cw) + 1
    ccw_ok = closed | (p_to_ccw >= p_from)
    cw_ok = closed | (p_to_cw <= p_from)
    use_ccw = ccw_ok & (~cw_ok | (ccw <= cw))
    direction = jnp.where(use_ccw, 1, -1).astype(jnp.int32)
    count = jnp.where(use_ccw, ccw, cw).astype(jnp.int32)
    return direction, count, ccw_ok | cw_ok


def corridor_from_vertices(
    mesh: Mesh,
    path: Int[Array, " P"],
    count: Int[Array, ""],
    start_face: Int[Array, ""],
    end_face: Int[Array, ""],
    cap: int,
) -> tuple[Int[Array, " cap"], Int[Array, ""], Bool[Array, ""]]:
    """A face corridor that follows the vertex path (start_face contains path[0],
    end_face path[count − 1]): round each vertex through its fan, the shorter way,
    from the face it was entered by to a face of the next edge."""

    def body(i, s):
        p_e, dirs, counts, starts, ok = s
        v = path[i]
        n = mesh.fan_size[v]
        closed = mesh.fan_closed[v]
        last = i == count - 1
        w = path[jnp.minimum(i + 1, path.shape[0] - 1)]
        q = jnp.argmax(mesh.fan_spokes[v] == w)  # spoke to the next vertex
        has_q = jnp.any(mesh.fan_spokes[v] == w)
        p_end = face_fan_position(mesh, end_face, v)
        to_ccw = jnp.where(
            last, p_end, jnp.where(closed, (q - 1) % jnp.maximum(n, 1), q - 1)
        )
        to_cw = jnp.where(last, p_end, q)
        d, c, turn_ok = _turn(n, closed, p_e, to_ccw, to_cw)
        exit_pos = jnp.where(d > 0, to_ccw, to_cw)
        exit_face = mesh.fan_faces[
            v, jnp.clip(exit_pos, 0, mesh.fan_faces.shape[1] - 1)
        ]
        nxt = face_fan_position(mesh, exit_face, w)
        return (
            jnp.where(last, p_e, nxt),
            dirs.at[i].set(d),
            counts.at[i].set(c),
            starts.at[i].set(p_e),
            ok & turn_ok & (last | has_q),
        )

    m = path.shape[0]
    zeros = jnp.zeros(m, jnp.int32)
    p0 = face_fan_position(mesh, start_face, path[0])
    init = (p0, zeros, zeros, zeros, jnp.asarray(True))
    _, dirs, counts, starts, ok = jax.lax.fori_loop(0, count, body, init)
    live = jnp.arange(m) < count
    # each fan after the first starts with the face the previous one ended on
    contrib = jnp.where(live, counts - (jnp.arange(m) > 0), 0)
    cum = jnp.cumsum(contrib)
    total = cum[-1]
    j = jnp.arange(cap)
    i = jnp.clip(jnp.searchsorted(cum, j, side="right"), 0, m - 1)
    offset = j - (cum[i] - contrib[i]) + (i > 0)
    v = path[i]
    pos = (starts[i] + dirs[i] * offset) % jnp.maximum(mesh.fan_size[v], 1)
    faces = jnp.where(j < total, mesh.fan_faces[v, pos], -1)
    return faces, total.astype(jnp.int32), ok & (total <= cap)
