"""The strip repair of `method="smooth"` as fixed-shape JAX: vertex contacts of a
solved strip, the two ways round each contact's vertex fan, and candidate strips
with contacts released to a side (`jaxgeo.smooth.smooth_path` solves them).

A strip is a node buffer in the format of `Path`: `kinds` (0 endpoint, 1 edge
crossing, 2 vertex), `elements`, `params` (u on the edge, flat point
(1 − u)·V[edges[e, 0]] + u·V[edges[e, 1]]), `count` live nodes, node 0 the start
and node `count − 1` the end. Every function here is a pure function of arrays
of static shape, so it runs under `jit` and `vmap`; none is differentiated (the
repair picks the strip; the length's gradient comes from the final solve).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .locate import SurfacePoint
from .mesh import Mesh
from .path import EDGE, VERTEX

#: Rounding tolerance on the unfolded segment's parameter λ ∈ [0, 1]: when the
#: next node is the far end of an arc edge (two vertex contacts in a row) the line
#: ends exactly on that edge, at λ = 1 to rounding, and must count as crossing it.
_UNFOLD_TOL = 1e-9
#: Where the unfolded straight line misses an arc edge (the release goes the long
#: way round), the crossing starts this far along the edge from the vertex.
_NEAR_VERTEX = 0.02


def collapse(
    mesh: Mesh,
    kinds: Int[Array, " M"],
    elements: Int[Array, " M"],
    params: Float[Array, " M"],
    count: Int[Array, ""],
) -> tuple[Int[Array, " M"], Int[Array, " M"], Float[Array, " M"], Int[Array, ""]]:
    """Crossings pulled onto an end of their edge (u = 0 or 1, where the solver
    holds them) become vertex nodes, and runs of nodes at one vertex one node."""
    m = kinds.shape[0]
    idx = jnp.arange(m)
    inner = (idx > 0) & (idx < count - 1)
    ends = mesh.edges[jnp.clip(elements, 0, mesh.n_edges - 1)]
    at_lo, at_hi = params <= 0.0, params >= 1.0
    to_vertex = inner & (kinds == EDGE) & (at_lo | at_hi)
    kinds = jnp.where(to_vertex, VERTEX, kinds)
    elements = jnp.where(to_vertex, jnp.where(at_lo, ends[:, 0], ends[:, 1]), elements)
    params = jnp.where(to_vertex, 0.0, params)
    is_v = inner & (kinds == VERTEX)
    repeat = is_v & jnp.roll(is_v, 1) & (elements == jnp.roll(elements, 1))
    keep = (idx < count) & ~repeat
    slot = jnp.where(keep, jnp.cumsum(keep) - 1, m)  # m: dropped
    out_k = jnp.zeros_like(kinds).at[slot].set(kinds, mode="drop")
    out_e = jnp.zeros_like(elements).at[slot].set(elements, mode="drop")
    out_u = jnp.zeros_like(params).at[slot].set(params, mode="drop")
    return out_k, out_e, out_u, jnp.sum(keep).astype(count.dtype)


def _exit_edge(mesh: Mesh, face, v, direction):
    """The edge at vertex v of `face` that the walk round v leaves by: direction 0
    the edge (v, next corner after v's successor), direction 1 the other. With the
    mesh consistently oriented, one direction turns the same way round every
    vertex."""
    corners = mesh.faces[face]
    i = jnp.argmax(corners == v)
    # the edge opposite corner k joins the other two corners
    opposite = jnp.where(direction == 0, (i + 1) % 3, (i + 2) % 3)
    return mesh.face_edges[face, opposite]


def fan_arc(
    mesh: Mesh, v: Int[Array, ""], f_in: Int[Array, ""], f_out: Int[Array, ""]
) -> tuple[Int[Array, "2 K"], Int[Array, "2 K"], Int[Array, " 2"], Bool[Array, " 2"]]:
    """The edges of v's fan crossed walking from face f_in to f_out, each way
    round: `(edges, faces, n, ok)`, where `edges[d, :n[d]]` are the edges in order
    and `faces[d, t]` the face before `edges[d, t]` (so f_in first); `ok[d]` is
    False where the walk meets the boundary (an open fan has one way) or never
    reaches f_out. K is the mesh's largest valence.

    Read from the mesh's fan tables (`Mesh.fan_faces`, `jaxgeo._fans`): way 0
    runs counter-clockwise (fan positions up), way 1 clockwise. Past the step
    that arrives or meets the boundary, the rows hold 0; a walk that never
    arrives goes K steps (round a closed fan again)."""
    k = max(mesh.vertex_faces.shape[1], 1)
    size = mesh.fan_size[v]
    closed = mesh.fan_closed[v]
    start = mesh.corner_fan_pos[f_in, jnp.argmax(mesh.faces[f_in] == v)]
    same = f_in == f_out
    t = jnp.arange(k)

    def face_at(pos):
        """The face at fan position `pos` (round a closed fan), −1 off an open
        one."""
        pos = jnp.where(closed, jnp.mod(pos, jnp.maximum(size, 1)), pos)
        inside = (pos >= 0) & (pos < size)
        return jnp.where(inside, mesh.fan_faces[v, jnp.clip(pos, 0, k - 1)], -1)

    def walk(direction):
        way = 1 - 2 * direction
        faces = face_at(start + way * t)  # the face before edge t
        nxt = face_at(start + way * (t + 1))  # the face after it
        exits = jax.vmap(lambda f: _exit_edge(mesh, f, v, direction))
        edges = exits(jnp.maximum(faces, 0))
        stop = (nxt == f_out) | (nxt < 0)  # arrived, or met the boundary
        first = jnp.argmax(stop)
        walked = ~same & (jnp.cumsum(stop) - stop == 0)  # up to the first stop
        arrived = ~same & jnp.any(stop) & (nxt[first] == f_out)
        edges = jnp.where(walked, edges, 0).astype(jnp.int32)
        faces = jnp.where(walked, faces, 0).astype(jnp.int32)
        n = jnp.where(arrived, first + 1, 0).astype(jnp.int32)
        return edges, faces, n, same | arrived

    return jax.vmap(walk)(jnp.arange(2))


def _flat_nodes(
    mesh: Mesh, start: SurfacePoint, end: SurfacePoint, kinds, elements, u, count
):
    """Flat 3-D positions of the nodes, `(M, 3)`."""
    v = mesh.vertices
    e = mesh.edges[jnp.clip(elements, 0, mesh.n_edges - 1)]
    on_edge = (1 - u[:, None]) * v[e[:, 0]] + u[:, None] * v[e[:, 1]]
    at_vertex = v[jnp.clip(elements, 0, mesh.n_vertices - 1)]
    inner = jnp.where((kinds == VERTEX)[:, None], at_vertex, on_edge)
    idx = jnp.arange(kinds.shape[0])[:, None]
    return jnp.where(
        idx <= 0,
        start.position(mesh),
        jnp.where(idx >= count - 1, end.position(mesh), inner),
    )


def node_arcs(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    kinds: Int[Array, " M"],
    elements: Int[Array, " M"],
    params: Float[Array, " M"],
    count: Int[Array, ""],
    seg_faces: Int[Array, " M-1"],
) -> tuple[
    Int[Array, "M 2 K"], Float[Array, "M 2 K"], Int[Array, "M 2"], Bool[Array, "M 2"]
]:
    """For every node (meaningful at vertex nodes), both arcs of its vertex's fan
    between the faces of the segments before and after it (`fan_arc`), with the
    crossings' starting parameters from the unfolded straight line between its
    neighbours (`unfolded_params`)."""
    m = kinds.shape[0]
    idx = jnp.arange(m)
    pos = _flat_nodes(mesh, start, end, kinds, elements, params, count)
    f_in = seg_faces[jnp.clip(idx - 1, 0, m - 2)]
    f_out = seg_faces[jnp.clip(idx, 0, m - 2)]
    v = jnp.clip(elements, 0, mesh.n_vertices - 1)
    a = pos[jnp.clip(idx - 1, 0, m - 1)]
    b = pos[jnp.clip(idx + 1, 0, m - 1)]
    is_v = (kinds == VERTEX) & (idx > 0) & (idx < count - 1)
    # non-vertex nodes get a harmless vertex of their own segment's face
    v = jnp.where(is_v, v, mesh.faces[jnp.maximum(f_out, 0), 0])
    f_in = jnp.where(is_v, f_in, f_out)

    def one(v, f_in, f_out, a, b):
        edges, faces, n, ok = fan_arc(mesh, v, f_in, f_out)
        u = jax.vmap(unfolded_params, in_axes=(None, None, 0, 0, 0, None, None, None))(
            mesh, v, edges, faces, n, f_out, a, b
        )
        return edges, u, n, ok

    edges, u, n, ok = jax.vmap(one)(v, f_in, f_out, a, b)
    return edges, u, n, ok & is_v[:, None]


def unfolded_params(
    mesh: Mesh,
    v: Int[Array, ""],
    edges: Int[Array, " K"],
    faces: Int[Array, " K"],
    n: Int[Array, ""],
    f_out: Int[Array, ""],
    a: Float[Array, "3"],
    b: Float[Array, "3"],
) -> Float[Array, " K"]:
    """Parameters where the segment a → b, unfolded into the plane with the faces
    of v's fan along the arc (`fan_arc`), crosses the arc's edges; `_NEAR_VERTEX`
    from v where it misses, and kept 1e-3 inside the edge."""
    verts = mesh.vertices
    k = edges.shape[0]
    ends = mesh.edges[edges]  # (K, 2)
    other = jnp.where(ends[:, 0] == v, ends[:, 1], ends[:, 0])
    live = jnp.arange(k) < n

    def corner(face):  # the face's angle at v
        c = mesh.faces[face]
        i = jnp.argmax(c == v)
        d1 = verts[c[(i + 1) % 3]] - verts[v]
        d2 = verts[c[(i + 2) % 3]] - verts[v]
        return jnp.arctan2(jnp.linalg.norm(jnp.cross(d1, d2)), d1 @ d2)

    # the ray of edge t lies at angle φ_t: φ_0 = 0, then the corners of the faces
    # between consecutive arc edges
    between = jax.vmap(corner)(faces)  # faces[t] lies between edges t-1 and t
    phi = jnp.cumsum(jnp.where(live & (jnp.arange(k) > 0), between, 0.0))
    last = jnp.maximum(n - 1, 0)

    def place(p, face, w, angle, sign):
        """2-D image of point p of `face`, whose edge (v, w) lies at `angle`; the
        face's other edge at v at angle + sign·corner."""
        c = mesh.faces[face]
        x = jnp.sum(jnp.where((c != v) & (c != w), c, 0))
        d1, d2 = verts[w] - verts[v], verts[x] - verts[v]
        g = jnp.stack([d1, d2])  # (2, 3)
        gram = g @ g.T
        rhs = g @ (p - verts[v])
        det = gram[0, 0] * gram[1, 1] - gram[0, 1] ** 2
        s = (gram[1, 1] * rhs[0] - gram[0, 1] * rhs[1]) / det
        t = (gram[0, 0] * rhs[1] - gram[0, 1] * rhs[0]) / det
        t2 = angle + sign * corner(face)
        return s * jnp.linalg.norm(d1) * jnp.stack(
            [jnp.cos(angle), jnp.sin(angle)]
        ) + t * jnp.linalg.norm(d2) * jnp.stack([jnp.cos(t2), jnp.sin(t2)])

    a2 = place(a, faces[0], other[0], 0.0, -1.0)
    b2 = place(b, f_out, other[last], phi[last], 1.0)

    def crossing(e_other, angle):
        ray = jnp.stack([jnp.cos(angle), jnp.sin(angle)])
        # a2 + λ·(b2 − a2) = μ·ray
        mat = jnp.stack([b2 - a2, -ray], axis=1)
        det = mat[0, 0] * mat[1, 1] - mat[0, 1] * mat[1, 0]
        lam = (-a2[0] * mat[1, 1] + a2[1] * mat[0, 1]) / det
        mu = (-a2[1] * mat[0, 0] + a2[0] * mat[1, 0]) / det
        hit = (lam > -_UNFOLD_TOL) & (lam < 1 + _UNFOLD_TOL) & (mu > 0)
        hit = hit & jnp.isfinite(lam) & jnp.isfinite(mu)
        length = jnp.linalg.norm(verts[e_other] - verts[v])
        return jnp.clip(jnp.where(hit, mu / length, _NEAR_VERTEX), 1e-3, 1 - 1e-3)

    t = jax.vmap(crossing)(other, phi)
    return jnp.where(ends[:, 0] == v, t, 1 - t)


def release(
    kinds: Int[Array, " M"],
    elements: Int[Array, " M"],
    params: Float[Array, " M"],
    count: Int[Array, ""],
    side: Int[Array, " M"],
    arc_edges: Int[Array, "M 2 K"],
    arc_params: Float[Array, "M 2 K"],
    arc_n: Int[Array, "M 2"],
    arc_ok: Bool[Array, "M 2"],
) -> tuple[
    Int[Array, " M"],
    Int[Array, " M"],
    Float[Array, " M"],
    Int[Array, ""],
    Bool[Array, ""],
]:
    """The strip with each vertex node j where `side[j]` ≥ 0 replaced by the
    crossings of its fan's arc on that side (a node whose arc is empty or does not
    exist stays). Also returns whether the result fits the buffer and released
    anything."""
    m = kinds.shape[0]
    idx = jnp.arange(m)
    s = jnp.clip(side, 0, 1)
    n_arc = jnp.take_along_axis(arc_n, s[:, None], axis=1)[:, 0]
    ok = jnp.take_along_axis(arc_ok, s[:, None], axis=1)[:, 0]
    inner = (idx > 0) & (idx < count - 1)
    freed = inner & (kinds == VERTEX) & (side >= 0) & ok & (n_arc > 0)
    width = jnp.where(idx < count, jnp.where(freed, n_arc, 1), 0)
    stop = jnp.cumsum(width)
    begin = stop - width
    total = stop[-1]
    src = jnp.clip(jnp.searchsorted(stop, idx, side="right"), 0, m - 1)
    within = jnp.clip(idx - begin[src], 0, arc_edges.shape[2] - 1)
    f = freed[src]
    pick_e = arc_edges[src, s[src], within]
    pick_u = arc_params[src, s[src], within]
    live = idx < total
    out_k = jnp.where(live, jnp.where(f, EDGE, kinds[src]), EDGE)
    out_e = jnp.where(live, jnp.where(f, pick_e, elements[src]), 0)
    out_u = jnp.where(live, jnp.where(f, pick_u, params[src]), 0.0)
    fits = total <= m
    return (
        out_k,
        out_e,
        out_u,
        jnp.minimum(total, m).astype(count.dtype),
        fits & jnp.any(freed),
    )
