"""Starting corridors for the exact engine: graph paths through landmarks, turned
into face corridors (JAX, per query; the forests of the graph of vertices and edge
midpoints are built once per mesh, see `jaxgeo._landmarks`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._numerics import run_of
from .mesh import Mesh


def best_slots(
    mesh: Mesh, vs: Int[Array, ""], vt: Int[Array, ""], k: int
) -> tuple[Int[Array, " k"], Bool[Array, " k"]]:
    """The k landmark slots whose graph path s → landmark → t is shortest, and
    whether each connects s and t (both reach the slot's landmark)."""
    via = mesh.landmark_dist[:, vs] + mesh.landmark_dist[:, vt]
    k = min(k, via.shape[0])
    neg, slots = jax.lax.top_k(-via, k)
    return slots, jnp.isfinite(neg)


def _parent(mesh: Mesh, slot, node):
    """The node one step towards the landmark of `slot` (−1 at the landmark)."""
    x = node // 2
    pv = mesh.landmark_pred_vertex[slot, jnp.minimum(x, mesh.n_vertices - 1)]
    pe = mesh.landmark_pred_edge[slot, jnp.minimum(x, mesh.n_edges - 1)]
    return jnp.where(node % 2 == 1, pe, pv)


def node_path(
    mesh: Mesh, slot: Int[Array, ""], vs: Int[Array, ""], vt: Int[Array, ""], cap: int
) -> tuple[Int[Array, " cap"], Int[Array, ""], Bool[Array, ""]]:
    """The forest path of `slot` from vertex vs to vertex vt through their lowest
    common ancestor, as graph nodes (2·v: vertex v, 2·e + 1: midpoint of edge e):
    nodes (cap,), their number, and False if it exceeds `cap`."""

    def body(s):
        a, b, na, nb, buf_a, buf_b, go_a, go_b = s
        buf_a = jnp.where(go_a, buf_a.at[na].set(a, mode="drop"), buf_a)
        buf_b = jnp.where(go_b, buf_b.at[nb].set(b, mode="drop"), buf_b)
        a2, b2 = _parent(mesh, slot, a), _parent(mesh, slot, b)
        return (
            jnp.where(a2 >= 0, a2, a),
            jnp.where(b2 >= 0, b2, b),
            na + go_a,
            nb + go_b,
            buf_a,
            buf_b,
            go_a & (a2 >= 0) & (na + 1 < cap),
            go_b & (b2 >= 0) & (nb + 1 < cap),
        )

    empty = jnp.full(cap, -1, jnp.int32)
    init = (2 * vs, 2 * vt, 0, 0, empty, empty, True, True)
    init = (
        tuple(jnp.asarray(x, jnp.int32) for x in init[:4])
        + init[4:6]
        + (
            jnp.asarray(True),
            jnp.asarray(True),
        )
    )
    s = jax.lax.while_loop(lambda s: s[6] | s[7], body, init)
    _, _, na, nb, buf_a, buf_b, _, _ = s
    complete = (_parent(mesh, slot, buf_a[jnp.maximum(na - 1, 0)]) < 0) & (
        _parent(mesh, slot, buf_b[jnp.maximum(nb - 1, 0)]) < 0
    )
    # common tail (from the root backwards): its length p
    i = jnp.arange(cap)
    ra = buf_a[jnp.clip(na - 1 - i, 0, cap - 1)]
    rb = buf_b[jnp.clip(nb - 1 - i, 0, cap - 1)]
    same = (ra == rb) & (i < jnp.minimum(na, nb))
    p = jnp.argmin(jnp.concatenate([same, jnp.array([False])]))
    count = na + nb - 2 * p + 1
    path = jnp.where(
        i <= na - p,
        buf_a[jnp.clip(i, 0, cap - 1)],
        buf_b[jnp.clip(na + nb - 2 * p - i, 0, cap - 1)],
    )
    ok = complete & (count <= cap) & (p >= 1)
    return jnp.where(i < count, path, -1), count.astype(jnp.int32), ok


def face_fan_position(mesh: Mesh, face, vertex):
    """Position of `face` in the fan of its corner `vertex`."""
    corner = jnp.argmax(mesh.faces[face] == vertex)
    return mesh.corner_fan_pos[face, corner]


def _turn(n, closed, p_from, p_to_ccw, p_to_cw, fan_angle):
    """Faces counted from position p_from round a fan of n faces to p_to_ccw going
    counter-clockwise or to p_to_cw going clockwise: (direction ±1, count, whether
    either way exists). The way with the smaller angle at the vertex (`fan_angle`:
    the corner angle of each fan face; the first and last face count half, as the
    path's segments cut them) is taken: the string pulled taut through it cuts
    the corner shorter, and the choice does not depend on the direction the path
    is walked (a count of faces does, at ties). An open fan is turned only where
    the way does not cross the boundary."""
    n_ = jnp.maximum(n, 1)
    ccw = jnp.where(closed, (p_to_ccw - p_from) % n_, p_to_ccw - p_from) + 1
    cw = jnp.where(closed, (p_from - p_to_cw) % n_, p_from - p_to_cw) + 1
    ccw_ok = closed | (p_to_ccw >= p_from)
    cw_ok = closed | (p_to_cw <= p_from)
    k = jnp.arange(fan_angle.shape[0])
    off_ccw = jnp.where(closed, (k - p_from) % n_, k - p_from)
    off_cw = jnp.where(closed, (p_from - k) % n_, p_from - k)
    width = fan_angle.shape[0]
    first = fan_angle[jnp.clip(p_from, 0, width - 1)]

    def angle(off, count, p_to):
        inside = (off >= 0) & (off < count) & (k < n)
        last = fan_angle[jnp.clip(p_to, 0, width - 1)]
        return jnp.sum(jnp.where(inside, fan_angle, 0.0)) - 0.5 * (first + last)

    smaller = angle(off_ccw, ccw, p_to_ccw) <= angle(off_cw, cw, p_to_cw)
    use_ccw = ccw_ok & (~cw_ok | smaller)
    direction = jnp.where(use_ccw, 1, -1).astype(jnp.int32)
    count = jnp.where(use_ccw, ccw, cw).astype(jnp.int32)
    return direction, count, ccw_ok | cw_ok


def _face_of_edge_with(mesh: Mesh, e, v):
    """The face of edge e that has corner v (−1 if none)."""
    ef = mesh.edge_faces[e]
    has = jnp.any(mesh.faces[jnp.maximum(ef, 0)] == v, axis=1) & (ef >= 0)
    return jnp.where(has[0], ef[0], jnp.where(has[1], ef[1], -1))


def _common_face(mesh: Mesh, e1, e2):
    """The face of both edges e1 and e2 (−1 if none)."""
    a, b = mesh.edge_faces[e1], mesh.edge_faces[e2]
    hit = (a[:, None] == b[None, :]) & (a[:, None] >= 0)
    return jnp.where(hit[0].any(), a[0], jnp.where(hit[1].any(), a[1], -1))


def corridor_from_nodes(
    mesh: Mesh,
    corner_angles: Float[Array, "F 3"],
    path: Int[Array, " P"],
    count: Int[Array, ""],
    start_face: Int[Array, ""],
    end_face: Int[Array, ""],
    cap: int,
) -> tuple[Int[Array, " cap"], Int[Array, ""], Bool[Array, ""]]:
    """A face corridor that follows a graph path (`node_path`; its first and last
    nodes are vertices of start_face and end_face): round each vertex through its
    fan, the way of the smaller angle (`corner_angles` of the mesh), from the face
    it was entered by to a face of the next segment; across each midpoint's edge
    into the face of the next segment."""
    width = mesh.fan_faces.shape[1]

    def body(i, s):
        c, runs_v, runs_p, runs_d, runs_n, runs_f, ok = s
        node = path[i]
        nxt = path[jnp.minimum(i + 1, path.shape[0] - 1)]
        last = i == count - 1
        x, y = node // 2, nxt // 2
        at_vertex, to_vertex = node % 2 == 0, nxt % 2 == 0
        # the face of the segment node → nxt, where it is one face
        seg_face = jnp.where(
            at_vertex,
            _face_of_edge_with(mesh, y, x),  # vertex → midpoint
            jnp.where(
                to_vertex,
                _face_of_edge_with(mesh, x, y),  # midpoint → vertex
                _common_face(mesh, x, y),  # midpoint → midpoint
            ),
        )
        # at a vertex: turn round its fan
        v = jnp.where(at_vertex, x, 0)
        n = mesh.fan_size[v]
        closed = mesh.fan_closed[v]
        p_e = face_fan_position(mesh, c, v)
        q = jnp.argmax(mesh.fan_spokes[v] == y)  # spoke to the next vertex
        along = to_vertex & jnp.any(mesh.fan_spokes[v] == y)
        p_seg = face_fan_position(mesh, jnp.maximum(seg_face, 0), v)
        p_end = face_fan_position(mesh, end_face, v)
        to_ccw = jnp.where(
            last,
            p_end,
            jnp.where(
                to_vertex, jnp.where(closed, (q - 1) % jnp.maximum(n, 1), q - 1), p_seg
            ),
        )
        to_cw = jnp.where(last, p_end, jnp.where(to_vertex, q, p_seg))
        fan = mesh.fan_faces[v]
        corner = jnp.argmax(mesh.faces[jnp.maximum(fan, 0)] == v, axis=1)
        fan_angle = jnp.where(fan >= 0, corner_angles[jnp.maximum(fan, 0), corner], 0)
        d, cnt, turn_ok = _turn(n, closed, p_e, to_ccw, to_cw, fan_angle)
        exit_pos = jnp.where(d > 0, to_ccw, to_cw)
        exit_face = mesh.fan_faces[v, jnp.clip(exit_pos, 0, width - 1)]
        skip = (i > 0).astype(jnp.int32)  # the face entered by is in already
        vertex_ok = turn_ok & (last | along | (~to_vertex & (seg_face >= 0)))
        # at a midpoint: across its edge, unless the next segment is in this face
        ef = mesh.edge_faces[x]
        mid_ok = (
            ~last & (seg_face >= 0) & ((c == ef[0]) | (c == ef[1]))
            & ((seg_face == ef[0]) | (seg_face == ef[1]))
        )  # fmt: skip
        return (
            jnp.where(at_vertex, exit_face, seg_face),
            runs_v.at[i].set(jnp.where(at_vertex, v, -1)),
            runs_p.at[i].set(p_e + d * skip),
            runs_d.at[i].set(d),
            runs_n.at[i].set(jnp.where(at_vertex, cnt - skip, seg_face != c)),
            runs_f.at[i].set(seg_face),
            ok & jnp.where(at_vertex, vertex_ok, mid_ok),
        )

    m = path.shape[0]
    zeros = jnp.zeros(m, jnp.int32)
    init = (jnp.asarray(start_face, jnp.int32), zeros, zeros, zeros, zeros, zeros)
    init = init + (jnp.asarray(True),)
    _, runs_v, runs_p, runs_d, runs_n, runs_f, ok = jax.lax.fori_loop(
        0, count, body, init
    )
    contrib = jnp.where(jnp.arange(m) < count, runs_n, 0)
    cum = jnp.cumsum(contrib)
    total = cum[-1]
    j = jnp.arange(cap)
    i = jnp.minimum(run_of(contrib, cap), m - 1)
    offset = j - (cum[i] - contrib[i])
    v = jnp.maximum(runs_v[i], 0)
    pos = (runs_p[i] + runs_d[i] * offset) % jnp.maximum(mesh.fan_size[v], 1)
    face = jnp.where(runs_v[i] >= 0, mesh.fan_faces[v, pos], runs_f[i])
    faces = jnp.where(j < total, face, -1)
    return faces, total.astype(jnp.int32), ok & (total <= cap) & (count >= 1)
