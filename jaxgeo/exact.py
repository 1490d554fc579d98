"""The exact polyhedral geodesic, computed inside the compiled program.

**The method** (the wedge flips of Sharp & Crane's FlipOut, 2020, done on a face
corridor of the input mesh). A geodesic of a triangle mesh is a polyline that is
straight in every face it crosses, straight across every edge once its two faces
are unfolded, and passes through a vertex only where the angle on *both* sides of
it is at least π. Given a corridor (faces f_0 … f_{n−1} from the start's face to the
end's, consecutive faces sharing an edge):

1. unfold it into the plane and pull the string: `jaxgeo._sleeve.funnel` gives the
   shortest path inside the corridor and the vertices it wraps;
2. at a wrapped vertex v the path turns by τ, so the angle on the corridor's side is
   π + |τ| and the angle on the other side is Θ(v) − π − |τ| (Θ(v): the sum of v's
   face angles). If that is below π, going round the other side is shorter: the
   corridor's faces round v are replaced by the complementary fan (a *wedge flip*).
   The old path still lies in the new corridor and bends there by less than π, so
   the new string is strictly shorter and the loop cannot cycle. Boundary vertices
   never flip. All flips whose fans do not overlap are made at once;
3. backtracks (f, g, f) are removed and the corridor is trimmed to the last face
   that holds the start and the first that holds the end; repeat until no flip is
   possible (or `max_iterations`).

**Starts.** The loop converges to a locally shortest path in the class of its start. The
starts are graph paths s → landmark → t over vertices and edge midpoints, read from
shortest-path forests built once per mesh (`jaxgeo._landmarks`): the `max_starts`
landmarks that give the shortest graph paths, refined as parallel lanes (`jax.vmap`),
the shortest result kept. Per query there is no graph search: walking a forest costs the
path's length.

**Detours.** Where many vertices round the path are cone or saddle points (scanned
meshes), several locally shortest paths lie a row or two of vertices apart, and the
starts may all flip into the same one. The converged best path is then tried again
from corridors that pass its nearest cone vertices on their other side, one vertex
each (`_detours`), and corridors moved across a whole stretch of one of its walls
(`_wall_flip`), in `detour_rounds` rounds. Each round detours from the best path
found, or, if that path's detours were tried already, from the best other one (the
runner-up): two locally shortest paths may differ at two cone vertices, each of
whose single detours alone gives a longer path.

**Certificate.** Where the endpoints' component has no cone vertex (every interior
angle sum Θ(v) ≥ 2π: flat or saddle-shaped everywhere, as anticlastic membranes
are), each homotopy class holds exactly one locally shortest path (`jaxgeo._curvature`),
so the detours, which stay in their class, are skipped, and a start stops as soon
as another of its class has converged. On a disc there is one class: the first
start to converge ends the search, and `stats.certified` is 1 (the path is
globally shortest). On an annulus the class is the winding, counted by the cut
edges a corridor crosses (`jaxgeo._cuts`); a path of another winding joins the
converged one L* into a closed curve round the annulus, at least its systole, so
where 2 L* is at most a lower bound of the systole (`Mesh.component_systole`) the
other windings' starts stop too and the path is certified. A start is converged
only if its string wraps no vertex by more than a turn (which no wedge flip can
release): such a string is shortest round the vertex, not on the surface.

**Gradients.** The discrete choices (corridor, wrapped vertices) are made under
`stop_gradient`; the length is then recomputed from the live vertices and endpoint
barycentrics by unfolding the final corridor (an associative scan) and summing the
planar distances between wrapped vertices. By the envelope theorem that is the exact
derivative of the minimal length (the crossing parameters are optimal), and the
crossing points are differentiable through the unfolding too.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import _curvature, _sleeve
from ._numerics import corner_angles, dot, last_at_or_before, run_of, safe_norm
from ._starts import best_slots, corridor_from_nodes, face_fan_position, node_path
from .locate import SurfacePoint, snap
from .mesh import Mesh
from .path import EDGE, FACE, VERTEX, Status

__all__ = ["ExactStats", "exact_solve", "vertex_angle_sums"]


class ExactStats(eqx.Module):
    """Diagnostics of one exact solve (as optimistix's `Solution.stats`)."""

    # (leading axes B in a batch of paths)
    iterations: Int[Array, "*B"]  # flip rounds of the winning start
    flips: Int[Array, "*B"]  # wedge flips made by the winning start
    starts: Int[Array, "*B"]  # starts refined
    starts_converged: Int[Array, "*B"]
    corridor_length: Int[Array, "*B"]  # faces in the final corridor
    #: 1 if a lane's corridor outgrew `corridor_capacity` (its path then failed,
    #: or another may be shorter): solve again with a larger capacity. A start
    #: another start of whose class converged does not count: it would have
    #: reached the same path (`jaxgeo._curvature`; 1 of 16 random pairs of a small
    #: catenoid at 24 faces, 8 when it counted)
    outgrew: Int[Array, "*B"]
    #: 1 if the path is certified globally shortest: its component is a disc
    #: with no cone vertex (`jaxgeo._curvature`), where a locally shortest path is the
    #: only one, or an annulus with no cone vertex whose systole is at least twice
    #: the path (`Mesh.component_systole`): a path of another winding is no shorter
    certified: Int[Array, "*B"]


def vertex_angle_sums(vertices: Float[Array, "V 3"], faces: Int[Array, "F 3"]):
    """Θ(v): the sum of the face angles at every vertex (`Mesh.vertex_angle_sums`
    holds it for the mesh's own vertices)."""
    return _curvature.angle_sums(faces, corner_angles(vertices, faces), len(vertices))


def _cut_crossings(mesh: Mesh, corridor, n):
    """The signed count of the cut each portal of a corridor crosses (+1 from
    `edge_faces[e, 0]` to `edge_faces[e, 1]` of a +1 cut edge; 0 off the cut
    and past the corridor's n faces)."""
    edge, *_ = _sleeve.portals(mesh.faces, mesh.face_edges, corridor, n)
    live = jnp.arange(corridor.shape[0]) < n - 1
    forward = corridor == mesh.edge_faces[edge, 0]
    return jnp.where(live, jnp.where(forward, 1, -1) * mesh.edge_cut[edge], 0)


def _winding(mesh: Mesh, corridor, n, s: _End, t: _End):
    """A corridor's class on an annulus: the signed count of the cut edges its
    portals cross, made independent of the faces round each endpoint it begins
    and ends in. Where an endpoint lies on the cut (a vertex or an edge of it),
    corridors of one class may begin on either side; each count is then read
    as if the corridor first turned round the endpoint from a reference face
    (its fan's first, the edge's face 0) to its own first face, and last from its
    own last face back to the reference: `_turn_count`. Round an interior vertex
    the cut is crossed once each way, so the way round does not matter."""
    crossed = jnp.sum(_cut_crossings(mesh, corridor, n))
    last = corridor[jnp.maximum(n - 1, 0)]
    return _turn_count(mesh, s, corridor[0]) + crossed - _turn_count(mesh, t, last)


def _turn_count(mesh: Mesh, end: _End, face):
    """The signed cut crossings from an endpoint's reference face to `face`
    (which holds it), turning round it (`_winding`): a vertex's fan, in order,
    is a corridor."""
    fan = jnp.maximum(mesh.fan_faces[end.index], 0)
    steps = _cut_crossings(mesh, fan, mesh.fan_size[end.index])
    before = jnp.concatenate([jnp.zeros(1, steps.dtype), jnp.cumsum(steps)])
    in_fan = before[face_fan_position(mesh, face, end.index)]
    ef = mesh.edge_faces[end.index]
    on_edge = jnp.where(face == ef[0], 0, mesh.edge_cut[end.index])
    return jnp.where(
        end.kind == VERTEX, in_fan, jnp.where(end.kind == EDGE, on_edge, 0)
    )


# ------------------------------------------------------------------- endpoints


#: A crossing parameter may lie this far outside [0, 1] (rounding of the unfolding,
#: ~1e-13 for corridors of a few hundred faces, far below).
_PORTAL_SLACK = 1e-9


def _snap_tol(dtype) -> float:
    """Barycentric coordinates below this are zero (the point is on an edge or a
    vertex): eps^(2/3), 4e-11 in float64, so snapping moves a point by at most
    that fraction of an edge."""
    return float(jnp.finfo(dtype).eps) ** (2 / 3)


class _End(eqx.Module):
    """An endpoint: the `SurfacePoint` snapped onto the element it lies on, and
    that element as `SurfacePoint.element` reads it (the edge parameter unused)."""

    point: SurfacePoint
    kind: Int[Array, ""]  # FACE, EDGE or VERTEX
    index: Int[Array, ""]

    @property
    def face(self) -> Int[Array, ""]:
        return jnp.asarray(self.point.face)

    @property
    def bary(self) -> Float[Array, " 3"]:
        return jnp.asarray(self.point.bary)


def _end(mesh: Mesh, sp: SurfacePoint) -> _End:
    face, b = jnp.asarray(sp.face), jnp.asarray(sp.bary)
    b = b / jnp.sum(b)
    tol = _snap_tol(b.dtype)
    kind, index = snap(mesh, SurfacePoint(face, b), tol)
    b = jnp.where(b <= tol, 0.0, b)
    return _End(SurfacePoint(face, b / jnp.sum(b)), kind, index)


def _contains(mesh: Mesh, end: _End, faces):
    """Does each face in `faces` hold the endpoint?"""
    ef = mesh.edge_faces[end.index]
    on_vertex = jnp.any(mesh.faces[jnp.maximum(faces, 0)] == end.index, axis=-1)
    return (faces >= 0) & jnp.where(
        end.kind == VERTEX,
        on_vertex,
        jnp.where(
            end.kind == EDGE, (faces == ef[0]) | (faces == ef[1]), faces == end.index
        ),
    )


def _bary_in(mesh: Mesh, end: _End, face):
    """The endpoint's barycentric coordinates in `face` (which must hold it)."""
    same = mesh.faces[face][:, None] == mesh.faces[end.face][None, :]
    return jnp.sum(jnp.where(same, end.bary[None, :], 0.0), axis=1)


def _common_face(mesh: Mesh, s: _End, t: _End):
    """A face holding both endpoints, or −1."""
    cand = jnp.where(
        s.kind == VERTEX,
        mesh.fan_faces[s.index],
        jnp.full(mesh.fan_faces.shape[1], -1, jnp.int32)
        .at[0]
        .set(jnp.where(s.kind == EDGE, mesh.edge_faces[s.index, 0], s.face))
        .at[1]
        .set(jnp.where(s.kind == EDGE, mesh.edge_faces[s.index, 1], -1)),
    )
    hit = _contains(mesh, t, cand) & (cand >= 0)
    return jnp.where(jnp.any(hit), cand[jnp.argmax(hit)], -1)


# ------------------------------------------------------------ corridor edits


def _clean(mesh: Mesh, corridor, n, s: _End, t: _End):
    """For a lane batch: remove backtracks (f, g, f → f), then trim each corridor
    to the last leading face that holds the start and the first trailing face that
    holds the end."""
    corridor, n = _unbacktrack(corridor, n)
    return jax.vmap(lambda c, m, s_, t_: _trim(mesh, c, m, s_, t_))(corridor, n, s, t)


def _unbacktrack(corridor: Int[Array, "L C"], n: Int[Array, " L"]):
    """Remove backtracks f, g, f → f from a lane batch of corridors, in passes of
    all at once. Each f, g, f crosses one edge twice: removing such pairs is the
    free reduction of the corridor's word of edges, whose result does not depend
    on the order (f, g, f, g, f → f either way), so every pass removes all that
    do not overlap (every other one of a run). A pass is a few array operations
    and there are as many as backtracks nest, 0–2 a round (a stack over the
    faces took a loop step per face: 5.5 against 1.5 ms at 256 lanes)."""
    cap = corridor.shape[-1]
    k = jnp.arange(cap)

    def one_pass(c, m):
        prev = c[jnp.maximum(k - 1, 0)]
        nxt = c[jnp.minimum(k + 1, cap - 1)]
        at = (k >= 1) & (k + 1 < m) & (prev == nxt)  # c[k], c[k + 1] can go
        run_start = jax.lax.cummax(jnp.where(at, -1, k)) + 1
        pick = at & ((k - run_start) % 2 == 0)
        drop = pick | jnp.concatenate([jnp.zeros(1, bool), pick[:-1]])
        keep = ~drop & (k < m)
        to = jnp.where(keep, jnp.cumsum(keep, dtype=jnp.int32) - 1, cap)
        out = jnp.full(cap, -1, c.dtype).at[to].set(c, mode="drop")
        return out, jnp.sum(keep, dtype=jnp.int32), jnp.any(pick)

    def cond(st):
        return jnp.any(st[2])

    def body(st):
        c, m, _ = st
        return jax.vmap(one_pass)(c, m)

    lanes = n.shape[0]
    init = (corridor, n.astype(jnp.int32), jnp.ones(lanes, bool))
    corridor, n, _ = jax.lax.while_loop(cond, body, init)
    return corridor, n


def _trim(mesh: Mesh, corridor, n, s: _End, t: _End):
    cap = corridor.shape[0]
    k = jnp.arange(cap)
    live = k < n
    hold_s = _contains(mesh, s, corridor) & live
    hold_t = _contains(mesh, t, corridor) & live
    first_out = jnp.argmin(jnp.concatenate([hold_s, jnp.array([False])]))
    r = jnp.maximum(first_out - 1, 0)
    rev = hold_t[::-1] | (k[::-1] >= n)  # trailing faces (dead slots count as in)
    tail = jnp.argmin(jnp.concatenate([rev, jnp.array([False])]))
    e = jnp.minimum(cap - tail, n - 1)
    e = jnp.where(hold_t[jnp.clip(e, 0, cap - 1)], e, n - 1)
    new_n = e - r + 1
    out = jnp.where(k < new_n, corridor[jnp.clip(k + r, 0, cap - 1)], -1)
    return out, new_n.astype(jnp.int32)


def _flips(mesh: Mesh, theta, corridor, sleeve, pinned, m, tol):
    """The wedge flips to make: for every pinned point, whether to flip it and
    the complementary fan (vertex, first position, direction, face count)."""
    q = jnp.arange(pinned.shape[0])
    inst = jnp.maximum(pinned, 0)
    xy = _sleeve.pins_xy(sleeve, pinned)
    prev = xy[jnp.maximum(q - 1, 0)]
    nxt = xy[jnp.minimum(q + 1, pinned.shape[0] - 1)]
    d_in, d_out = xy - prev, nxt - xy
    tau = jnp.arctan2(_sleeve.cross2d(d_in, d_out), dot(d_in, d_out))
    is_left = sleeve.inst_is_left[inst]
    beta = jnp.pi + jnp.where(is_left, tau, -tau)
    # the string bends round the wall, so the angle on the corridor's side is at
    # least π; below, it went round v by more than 2π and the arctangent wrapped
    # (a U-turn round the wide side of a saddle vertex, seen on the catenoid)
    beta = jnp.where(beta < jnp.pi - tol, beta + 2 * jnp.pi, beta)
    v = sleeve.inst_vertex[inst]
    nv = mesh.fan_size[v]
    a, b = sleeve.inst_first[inst], sleeve.inst_last[inst]
    run = b - a + 2  # corridor faces a … b + 1 hold v
    interior = (q >= 1) & (q <= m - 2)
    shorter = interior & mesh.fan_closed[v] & (theta[v] - beta < jnp.pi - tol)
    fits = (run <= nv) & (b >= a)
    flip = shorter & fits
    # a wrap the loop cannot release: more than a whole turn round v, so the
    # path is locally shortest only round the vertex, not on the surface
    stuck = shorter & ~fits
    p0, d, count = _other_way(mesh, corridor, v, a, b)

    # Fans of consecutive wrapped vertices may share faces (never of others). Two
    # neighbours on one wall share exactly one face, which `_apply_flips` joins;
    # in every chain of other conflicts take every other flip, the rest wait.
    prev_flip = jnp.concatenate([jnp.array([False]), flip[:-1]])
    prev_b = jnp.concatenate([jnp.array([-2], b.dtype), b[:-1]])
    prev_left = jnp.concatenate([jnp.array([False]), is_left[:-1]])
    joined = (a == prev_b + 1) & (is_left == prev_left)
    conflict = flip & prev_flip & (a <= prev_b + 1) & ~joined
    chain_start = jax.lax.cummax(jnp.where(flip & ~conflict, q, -1))
    taken = flip & ((q - chain_start) % 2 == 0)
    return taken, v, a, b, p0, d, count, jnp.any(stuck)


def _other_way(mesh: Mesh, corridor, v, a, b):
    """For vertices v held by corridor faces a … b + 1 (arrays): the fan the other
    way round each, from face a to face b + 1 (first position, direction ±1,
    faces counted with both ends)."""
    cap = corridor.shape[0]
    fa = corridor[jnp.clip(a, 0, cap - 1)]
    fa1 = corridor[jnp.clip(a + 1, 0, cap - 1)]
    fb = corridor[jnp.clip(b + 1, 0, cap - 1)]
    pos = jax.vmap(face_fan_position, in_axes=(None, 0, 0))
    p0, p_next, p1 = pos(mesh, fa, v), pos(mesh, fa1, v), pos(mesh, fb, v)
    nv = jnp.maximum(mesh.fan_size[v], 1)
    d = jnp.where((p_next - p0) % nv == 1, 1, -1)  # the corridor's direction
    return p0, -d, ((p0 - p1) * d) % nv + 1


def _detours(mesh: Mesh, theta, corridor, n, pinned, m, s, t, k: int, tol):
    """k corridors that pass the converged path's nearest walls of positive
    curvature on their other side (one vertex each). Where every vertex round
    the path is a cone point several locally shortest paths exist, and starts
    that all reach the same one cannot tell; a detour starts in the other.
    `pinned`, `m`: the converged path's taut string, as `_refine` left it."""
    sl = _sleeve_of(mesh, corridor, n, s, t)
    cap = corridor.shape[0]
    inst = jnp.arange(cap + 1)
    v = sl.inst_vertex
    a, b = sl.inst_first, sl.inst_last
    # the path segment beside each wall instance, and its distance from it
    first = jnp.where(
        pinned == _sleeve.START,
        -1,
        jnp.where(
            (pinned == _sleeve.END) | (jnp.arange(pinned.shape[0]) >= m),
            n - 1,
            sl.inst_first[jnp.maximum(pinned, 0)],
        ),
    )
    j = jnp.clip(last_at_or_before(first, cap + 1)[a], 0, pinned.shape[0] - 2)
    xy = _sleeve.pins_xy(sl, pinned)
    p, q = xy[j], xy[j + 1]
    w = sl.inst_xy - p
    seg = q - p
    u = jnp.clip(dot(w, seg) / jnp.maximum(dot(seg, seg), 1e-300), 0, 1)
    dist = safe_norm(w - u[:, None] * seg)
    pinned_here = (
        jnp.zeros(cap + 1, bool)
        .at[jnp.maximum(pinned, 0)]
        .set((pinned >= 0) & (jnp.arange(pinned.shape[0]) < m), mode="drop")
    )
    run = b - a + 2
    ok = (
        (inst <= n)
        & (b >= a)
        & mesh.fan_closed[v]
        & (theta[v] < 2 * jnp.pi - tol)
        & (run <= mesh.fan_size[v])
        & ~pinned_here
    )
    _, pick = jax.lax.top_k(jnp.where(ok, -dist, -jnp.inf), k)
    good = ok[pick]
    p0, d, count = _other_way(mesh, corridor, v[pick], a[pick], b[pick])

    def one(vi, ai, bi, pi, di, ci, gi):
        new, new_n, fits = _apply_flips(
            mesh, corridor, n, jnp.array([True]), vi[None], ai[None], bi[None],
            pi[None], di[None], ci[None],
        )  # fmt: skip
        return new, new_n, fits, gi

    return jax.vmap(one)(v[pick], a[pick], b[pick], p0, d, count, good)


#: The wall detours (`_wall_flips`): both walls, each over these stretches of the
#: corridor (fractions of its faces): 8 corridors.
WALL_STRETCHES = ((0.0, 1.0), (0.0, 0.5), (0.5, 1.0), (0.25, 0.75))


def _wall_flips(mesh: Mesh, corridor, n, s: _End, t: _End):
    """`_wall_flip` for both walls over every stretch of `WALL_STRETCHES`:
    corridors (8, C), their lengths, whether each fits."""
    sl = _sleeve_of(mesh, corridor, n, s, t)
    left = jnp.array([left for _ in WALL_STRETCHES for left in (True, False)])
    lo, hi = (
        jnp.array([w[i] for w in WALL_STRETCHES for _ in (True, False)]) for i in (0, 1)
    )
    return jax.vmap(lambda *x: _wall_flip(mesh, corridor, n, sl, s, t, *x))(
        left, lo, hi
    )


def _wall_flip(mesh: Mesh, corridor, n, sl, s: _End, t: _End, left, lo, hi):
    """The corridor (unfolded: `sl`) moved across one of its walls: every vertex
    of the left (or right) wall, between the fractions `lo` and `hi` of its faces,
    whose fan is closed is passed on its other side, all at once (consecutive
    wall vertices' runs share one face, see `_apply_flips`). Where a path's
    homotopy class differs from the shortest one by a row of cone or saddle
    vertices, single-vertex detours each fall back into the old class; this
    start lies beyond the whole row and the flip loop takes it from there."""
    v = sl.inst_vertex
    a, b = sl.inst_first, sl.inst_last
    ends = ((s.kind == VERTEX) & (v == s.index)) | ((t.kind == VERTEX) & (v == t.index))
    ok = (
        (sl.inst_is_left == left)
        & (b >= a)
        & mesh.fan_closed[v]
        & (b - a + 2 <= mesh.fan_size[v])
        & ~ends
        & (a >= lo * n)
        & (b + 1 <= hi * n)
    )
    p0, d, count = _other_way(mesh, corridor, v, a, b)
    new, new_n, fits = _apply_flips(mesh, corridor, n, ok, v, a, b, p0, d, count)
    one = jax.tree.map(lambda x: x[None], (new, new_n, s, t))
    new, new_n = _clean(mesh, *one)
    return new[0], new_n[0], fits & sl.valid


def _apply_flips(mesh: Mesh, corridor, n, taken, v, a, b, p0, d, count):
    """Replace corridor faces a … b + 1 of every taken flip by its fan. The runs
    of taken flips may share one face (b + 1 of one is a of the next: two
    consecutive vertices of one wall); the next fan then starts after it, and
    the backtrack this leaves (…, Y, X, Y, …) is `_clean`'s to remove."""
    cap = corridor.shape[0]
    k = jnp.arange(cap)
    slot = jnp.where(taken, a, cap)
    is_start = jnp.zeros(cap, bool).at[slot].set(True, mode="drop")
    f_v = jnp.zeros(cap, jnp.int32).at[slot].set(v, mode="drop")
    f_p = jnp.zeros(cap, jnp.int32).at[slot].set(p0, mode="drop")
    f_d = jnp.zeros(cap, jnp.int32).at[slot].set(d, mode="drop")
    f_c = jnp.zeros(cap, jnp.int32).at[slot].set(count, mode="drop")
    diff = (
        jnp.zeros(cap + 2, jnp.int32)
        .at[jnp.where(taken, a + 1, cap + 1)]
        .add(1, mode="drop")
        .at[jnp.where(taken, b + 2, cap + 1)]
        .add(-1, mode="drop")
    )
    inside = jnp.cumsum(diff)[:cap] > 0
    skip = (is_start & inside).astype(jnp.int32)  # the shared face is in already
    cnt = jnp.where(k < n, jnp.where(is_start, f_c - skip, jnp.where(inside, 0, 1)), 0)
    cum = jnp.cumsum(cnt)
    total = cum[-1]
    j = jnp.arange(cap)
    src = run_of(cnt, cap)
    off = j - (cum[src] - cnt[src]) + skip[src]
    vv = f_v[src]
    pos = (f_p[src] + f_d[src] * off) % jnp.maximum(mesh.fan_size[vv], 1)
    face = jnp.where(is_start[src], mesh.fan_faces[vv, pos], corridor[src])
    return jnp.where(j < total, face, -1), total, total <= cap


def _pinned_length(sleeve, pinned, m):
    xy = _sleeve.pins_xy(sleeve, pinned)
    seg = safe_norm(xy[1:] - xy[:-1])
    return jnp.sum(jnp.where(jnp.arange(1, pinned.shape[0]) < m, seg, 0.0))


def _sleeve_of(mesh: Mesh, corridor, n, s: _End, t: _End):
    first = corridor[0]
    last = corridor[jnp.maximum(n - 1, 0)]
    return _sleeve.unfold(
        mesh.vertices,
        mesh.faces,
        mesh.face_edges,
        jnp.where(corridor >= 0, corridor, first),
        n,
        _bary_in(mesh, s, first),
        _bary_in(mesh, t, last),
    )


# --------------------------------------------------------------- the flip loop


class _Lane(eqx.Module):  # one lane, or L of them (leading axes)
    corridor: Int[Array, "*L C"]
    n: Int[Array, "*L"]
    pinned: Int[Array, "*L C+2"]  # the taut string's pins (`_sleeve.funnel`)
    m: Int[Array, "*L"]
    length: Float[Array, "*L"]
    iterations: Int[Array, "*L"]
    flips: Int[Array, "*L"]
    status: Int[Array, "*L"]
    done: Bool[Array, "*L"]


#: Windings told apart on an annulus (`_winding`; a start beyond is refined to
#: the end, as on any mesh).
WINDINGS = 4

#: Lane batches up to this size are refined one lane per start; larger ones by a
#: pool of `1/POOL_FRACTION` as many workers (at least this many), each taking the
#: next start when its own has converged (`_refine`). A single pair's 8 starts
#: too: where starts of one class settle each other (no cone vertex), the
#: others mostly need not run at all, and elsewhere 4 lanes at a time cost little
#: more per start than 8 (25 random pairs, CPU per path: 20k catenoid 39 -> 27 ms,
#: `bone.ply` 48 -> 43, `airplane.obj` 100 -> 84; lengths equal to 4e-16).
#: A batch runs on one worker per 8 starts: where a pair's starts share a class
#: (no cone vertex), its first converged start settles the others, and fewer,
#: busier workers do the same work in fewer lane-steps (batches of 256 random
#: pairs, CPU: 20k catenoid 67 -> 99–105 paths/s, compile 76 -> 52–57 s; with
#: cone vertices, where every start runs, `bone.ply` 43.5 -> 38.5 and
#: `airplane.obj` 12.8 -> 12.1; 16 starts per worker: catenoid 67; lengths equal).
POOL_MIN = 4
POOL_FRACTION = 8

#: `POOL_MIN` on a mesh with no cone vertex (`Exact(min_lanes=None)` on a concrete
#: mesh, see `jaxgeo.methods.for_mesh`): there every start's class is known and
#: its first converged start settles the others, so a single pair's loop of one
#: lane runs about one start, where four lanes run four at nearly twice the cost
#: a round (30 random pairs of the 20k catenoid, CPU per path, median: 17.6 /
#: 19.1 → 13.2 / 14.8 ms; lengths identical).
POOL_MIN_CONE_FREE = 1

#: The pool's width shrinks by this factor once its queue is empty and at most
#: that many workers still run (`_refine`).
POOL_SHRINK = 8


def _round(mesh, theta, lane: _Lane, s, t, tol) -> _Lane:
    """One flip round of every lane: unfold, pull the string, flip, clean."""
    active = ~lane.done
    # a finished lane is unfolded as an empty corridor, so that the funnel's
    # loop, which runs as long as its longest lane, and `_unbacktrack`'s passes,
    # which run while any lane has a backtrack, skip it
    live_n = jnp.where(active, lane.n, 0)
    sl = jax.vmap(lambda c, m, s_, t_: _sleeve_of(mesh, c, m, s_, t_))(
        lane.corridor, live_n, s, t
    )
    pinned, m, fun_ok = _sleeve.funnel(sl)
    length = jax.vmap(_pinned_length)(sl, pinned, m)
    taken, v, a, b, p0, d, count, stuck = jax.vmap(
        lambda c, sl_, p, m_: _flips(mesh, theta, c, sl_, p, m_, tol)
    )(lane.corridor, sl, pinned, m)
    n_taken = jnp.sum(taken, axis=-1, dtype=jnp.int32)
    new, new_n, fits = jax.vmap(lambda *x: _apply_flips(mesh, *x))(
        lane.corridor, live_n, taken, v, a, b, p0, d, count
    )
    new, new_n = _clean(mesh, new, new_n, s, t)
    good = sl.valid & fun_ok & (lane.n >= 1)  # (an empty corridor is no path)
    converged = good & (n_taken == 0)
    # a string left wrapping a vertex by more than a turn, which no flip
    # releases, is locally shortest only round it: no path of the surface
    status = jnp.where(
        ~good | (converged & stuck),
        Status.REFINE_FAILED,
        jnp.where(converged, Status.SUCCESS, jnp.where(fits, -1, Status.MAX_STEPS)),
    )
    stop = ~active | (status >= 0)
    return _Lane(
        corridor=jnp.where(stop[:, None], lane.corridor, new).astype(jnp.int32),
        n=jnp.where(stop, lane.n, new_n).astype(jnp.int32),
        pinned=jnp.where(active[:, None], pinned, lane.pinned),
        m=jnp.where(active, m, lane.m),
        length=jnp.where(active, length, lane.length),
        iterations=(lane.iterations + active).astype(jnp.int32),
        flips=lane.flips + jnp.where(stop, 0, n_taken),
        status=jnp.where(active & (status >= 0), status, lane.status).astype(jnp.int32),
        done=lane.done | stop,
    )


def _fresh(corridor, n, status0, dtype) -> _Lane:
    """Lanes about to be refined from `corridor`, `n` (done where status0 ≥ 0)."""
    lanes, cap = corridor.shape
    return _Lane(
        corridor=corridor,
        n=n,
        pinned=jnp.full((lanes, cap + 2), _sleeve.END, jnp.int32),
        m=jnp.zeros(lanes, jnp.int32),
        length=jnp.full(lanes, jnp.inf, dtype),
        iterations=jnp.zeros(lanes, jnp.int32),
        flips=jnp.zeros(lanes, jnp.int32),
        status=jnp.asarray(status0, jnp.int32),
        done=status0 >= 0,
    )


def _won(lane: _Lane, key, n_keys: int, systole=None):
    """Keys (`_refine`) one of whose lanes converged, and with `systole` (per
    pair, whose keys are rows of 2·`WINDINGS` + 1) every key of a pair with a
    converged path at most half of it (`_certified_by_systole`)."""
    idx = jnp.where(key >= 0, key, n_keys)
    ok = lane.status == Status.SUCCESS
    won = jnp.zeros(n_keys, bool).at[idx].max(ok, mode="drop")
    if systole is None:
        return won
    length = jnp.where(ok, lane.length, jnp.inf)
    least = jnp.full(n_keys, jnp.inf, length.dtype).at[idx].min(length, mode="drop")
    least = jnp.min(least.reshape(-1, 2 * WINDINGS + 1), axis=1)
    sure = _certified_by_systole(least, systole)
    return won | jnp.repeat(sure, 2 * WINDINGS + 1)


def _certified_by_systole(length, systole):
    """Is a converged path of `length` on an annulus globally shortest? A path
    of another winding closes with it into a curve winding round the annulus,
    at least its `systole` (a lower bound, `jaxgeo._cuts`): it is at least
    systole − length, no shorter where 2·length ≤ systole (to rounding)."""
    return 2 * length <= systole * (1 - 1e-9)


def _of_won_key(key, won: Bool[Array, " K"]):
    """Whether each start's key (−1: none) is one of the `won` keys (`_won`)."""
    return (key >= 0) & won[jnp.maximum(key, 0)]


def _settle(
    lane: _Lane,
    key,
    n_keys: int,
    won_before: Bool[Array, " K"] | bool = False,
    systole=None,
) -> _Lane:
    """Stop the unfinished lanes whose key (`_refine`) has a converged lane (now
    or, `won_before`, earlier): it is the only locally shortest path of their
    class (`jaxgeo._curvature`), which they would reach again; with `systole`,
    also those of a pair certified by it (`_won`)."""
    won = _won(lane, key, n_keys, systole) | won_before
    stop = _of_won_key(key, won) & ~lane.done
    status = jnp.where(stop, Status.REFINE_FAILED, lane.status).astype(jnp.int32)
    return eqx.tree_at(lambda x: (x.done, x.status), lane, (lane.done | stop, status))


def _refine(
    mesh,
    theta,
    corridor,
    n,
    status0,
    s,
    t,
    max_iterations,
    tol,
    key,
    n_keys: int,
    min_lanes: int | None = None,
    systole=None,
    won_before: Bool[Array, " K"] | bool = False,
):
    """Flip until no wrapped vertex admits a shorter way round, for a batch of
    starts (leading axis T of every argument but `mesh`, `theta`). `key` (T,):
    starts of one key (< `n_keys`) reach the same path, and the others stop
    when one has converged (−1: none), here or before (`won_before`); with
    `systole` (per pair, `_won`), all starts of a pair stop once it is
    certified. `min_lanes`: `POOL_MIN` (None: as the module sets it).

    Starts converge in very different numbers of rounds (on random pairs of the
    20k catenoid 25 on average, up to 62): a loop over all T lanes at once would
    run as long as the slowest. Above `POOL_MIN` starts, a pool of
    W = T/`POOL_FRACTION` worker lanes (at least `POOL_MIN`) runs them instead:
    a worker whose start has converged (or failed) writes its result and takes
    the next start, so the loop costs about the mean number of rounds, T/W
    times, plus one slowest start. That slowest start is then run by a
    narrower loop: once the queue is empty and at most W/`POOL_SHRINK`
    workers still run, the running ones move to a loop that wide (and so on)."""
    dtype = mesh.vertices.dtype
    corridor, n = _clean(mesh, corridor, n, s, t)
    tasks = corridor.shape[0]

    def finished(lane):  # converged, failed, or out of rounds
        return lane.done | (lane.iterations >= max_iterations)

    def result(lane):  # out of rounds: the path is valid but maybe not shortest
        status = jnp.where(lane.done, lane.status, Status.REFINE_FAILED)
        return eqx.tree_at(lambda x: x.status, lane, status.astype(jnp.int32))

    min_lanes = POOL_MIN if min_lanes is None else min_lanes
    if tasks <= min_lanes:
        lane = jax.lax.while_loop(
            lambda lane: jnp.any(~finished(lane)),
            lambda lane: _settle(
                _round(mesh, theta, lane, s, t, tol), key, n_keys, won_before, systole
            ),
            _settle(_fresh(corridor, n, status0, dtype), key, n_keys, won_before),
        )
        return result(lane)

    workers = max(min_lanes, -(-tasks // POOL_FRACTION))
    # the queue: the starts to refine, the first of every key first (its others
    # will mostly be settled by the time they are handed out), then the rest,
    # which are already done
    by_key = jnp.argsort(key, stable=True)
    sorted_key = key[by_key]
    first_of_key = jnp.searchsorted(sorted_key, sorted_key, side="left")
    rank = (
        jnp.zeros(tasks, jnp.int32)
        .at[by_key]
        .set((jnp.arange(tasks) - first_of_key).astype(jnp.int32))
    )
    rank = jnp.where(key >= 0, rank, 0)
    order = jnp.lexsort((rank, status0 >= 0)).astype(jnp.int32)
    live = jnp.sum(status0 < 0, dtype=jnp.int32)

    def load(task):  # the lanes of tasks (T + 1: none, done)
        idx = jnp.minimum(task, tasks - 1)
        lane = _fresh(corridor[idx], n[idx], status0[idx], dtype)
        return eqx.tree_at(lambda x: x.done, lane, lane.done | (task >= tasks))

    def ends(task):
        idx = jnp.minimum(task, tasks - 1)
        return jax.tree.map(lambda x: x[idx], s), jax.tree.map(lambda x: x[idx], t)

    def write(results, lane, task):  # the results of the finished lanes
        slot = jnp.where(finished(lane) & (task < tasks), task, tasks)
        return jax.tree.map(
            lambda r, x: r.at[slot].set(x, mode="drop"), results, result(lane)
        )

    def hand_out(won, next_, out):
        """The queue's next starts whose key has not converged (the others are
        settled: a worker would spend a round loading each), one to each `out`
        worker in order; and where the queue now begins."""
        position = jnp.arange(tasks)
        queued = (position >= next_) & (position < live)
        wanted = queued & ~_of_won_key(key[order], won)
        nth = jnp.cumsum(wanted, dtype=jnp.int32)  # wanted up to each position
        rank = jnp.cumsum(out, dtype=jnp.int32)  # 1, 2, …: the `out` workers
        pick = jnp.searchsorted(nth, rank, side="left").astype(jnp.int32)
        picked = out & (pick < live)
        new_task = jnp.where(picked, order[jnp.minimum(pick, tasks - 1)], tasks)
        handed = jnp.max(jnp.where(picked, pick + 1, next_))
        wanted_left = nth[-1] > jnp.sum(out, dtype=jnp.int32)
        return new_task, jnp.where(wanted_left, handed, live)

    def swap(state, out):
        """Write the finished lanes' results, then hand out the next starts in
        worker order; and the keys won so far."""
        lane, task, next_, results, _ = state
        results = write(results, lane, task)
        won = _won(results, key, n_keys, systole) | won_before
        new_task, next_ = hand_out(won, next_, out)
        task = jnp.where(out, new_task, task)
        lane = jax.tree.map(
            lambda f, x: jnp.where(out.reshape(out.shape + (1,) * (x.ndim - 1)), f, x),
            load(task),
            lane,
        )
        return lane, task, next_, results, won

    def body(state):
        lane, task, next_, results, won = state
        s_w, t_w = ends(task)
        lane = _round(mesh, theta, lane, s_w, t_w, tol)
        # (a pair may have won in this round's lanes or in an earlier result)
        lane = _settle(lane, key[jnp.minimum(task, tasks - 1)], n_keys, won, systole)
        out = finished(lane)
        state = (lane, task, next_, results, won)
        # (most rounds finish no lane: the pool's books are then left as they
        # are, 10 % of a long single path's rounds on the 20k catenoid)
        return jax.lax.cond(jnp.any(out), swap, lambda st, _: st, state, out)

    # The loops of a narrowing pool, W, W/POOL_SHRINK, …: the slowest starts
    # take three times the mean number of rounds, and one loop over all W
    # workers spends its last rounds on finished lanes (a batch of 256 on the
    # 20k catenoid: 36 % of 96 rounds of 512 workers were live)
    widths = [workers]
    while widths[-1] // POOL_SHRINK >= POOL_SHRINK:
        widths.append(widths[-1] // POOL_SHRINK)
    none_won = jnp.zeros(n_keys, bool) | won_before
    task, next_ = hand_out(none_won, 0, jnp.ones(workers, bool))
    results = _fresh(corridor, n, status0, dtype)
    state = (load(task), task, next_, results, none_won)
    for smaller in widths[1:] + [0]:

        def cond(state, smaller=smaller):
            lane, _, next_, _, _ = state
            running = jnp.sum(~finished(lane))
            return (running > smaller) | (next_ < live)

        lane, task, next_, results, won = jax.lax.while_loop(cond, body, state)
        if smaller:  # keep the running lanes (finished ones: written, or none)
            results = write(results, lane, task)
            keep = jnp.argsort(finished(lane), stable=True)[:smaller]
            lane, task = jax.tree.map(lambda x, k=keep: x[k], (lane, task))
            task = jnp.where(finished(lane), tasks, task)
        state = (lane, task, next_, results, won)
    # the starts never handed out, their key having converged, are settled
    return _settle(state[3], key, n_keys, won_before, systole)


def _start(mesh, angles, slot, slot_ok, vs, vt, s, t, cap):
    """A starting corridor from the forest path of `slot` from vertex vs (of the
    start's face) to vt (of the end's face); one lane."""
    path, count, path_ok = node_path(mesh, slot, vs, vt, cap)
    corridor, n, c_ok = corridor_from_nodes(
        mesh, angles, path, count, s.face, t.face, cap
    )
    status0 = jnp.where(
        ~slot_ok, Status.REFINE_FAILED, jnp.where(path_ok & c_ok, -1, Status.MAX_STEPS)
    )
    return corridor, n, status0.astype(jnp.int32)


# ------------------------------------------------------------------ the result


class ExactResult(eqx.Module):
    """Buffers of capacity M (see `jaxgeo.path.Path`), the length and status."""

    points: Float[Array, "M 3"]
    kinds: Int[Array, " M"]
    elements: Int[Array, " M"]
    params: Float[Array, " M"]
    count: Int[Array, ""]
    length: Float[Array, ""]
    status: Int[Array, ""]
    stats: ExactStats


def _assemble(mesh: Mesh, corridor, n, s: _End, t: _End, start, end, cap_points):
    """Points, kinds, elements, params and length of the string in the frozen
    corridor, differentiable in the vertices and the endpoints' barycentrics."""
    sl = _sleeve_of(mesh, corridor, n, s, t)
    one = jax.tree.map(lambda x: x[None], jax.lax.stop_gradient(sl))
    pinned, m, _ = jax.tree.map(lambda x: x[0], _sleeve.funnel(one))
    length = _pinned_length(sl, pinned, m)
    cap = corridor.shape[0]
    q = jnp.arange(pinned.shape[0])
    inst = jnp.maximum(pinned, 0)
    first = jnp.where(
        pinned == _sleeve.START,
        -1,
        jnp.where((pinned == _sleeve.END) | (q >= m), n - 1, sl.inst_first[inst]),
    )
    k = jnp.arange(cap)
    j = jnp.clip(last_at_or_before(first, cap), 0, pinned.shape[0] - 2)
    pj = pinned[j]
    at_vertex = (j >= 1) & (j <= m - 2) & (k <= sl.inst_last[jnp.maximum(pj, 0)])
    portal = k < n - 1
    emit = portal & (~at_vertex | (k == sl.inst_first[jnp.maximum(pj, 0)]))
    xy = _sleeve.pins_xy(sl, pinned)
    P, Q = xy[j], xy[j + 1]
    lxy, rxy = _sleeve.portal_xy(sl)
    dq = Q - P
    den = _sleeve.cross2d(lxy - rxy, dq)
    tt = _sleeve.cross2d(P - rxy, dq) / jnp.where(den != 0, den, 1.0)
    # a taut string crosses every portal between its ends (to rounding); one that
    # does not is a failed solve, never a path
    inside = ~emit | at_vertex | ((tt > -_PORTAL_SLACK) & (tt < 1 + _PORTAL_SLACK))
    tt = jnp.clip(tt, 0.0, 1.0)
    v = mesh.vertices
    cross3 = (1 - tt)[:, None] * v[sl.right] + tt[:, None] * v[sl.left]
    vert = sl.inst_vertex[jnp.maximum(pj, 0)]
    pts = jnp.where(at_vertex[:, None], v[vert], cross3)
    edge = sl.edge
    u = jnp.where(mesh.edges[edge, 0] == sl.right, tt, 1 - tt)
    kinds = jnp.where(at_vertex, VERTEX, EDGE)
    elems = jnp.where(at_vertex, vert, edge)
    params = jnp.where(at_vertex, 0.0, u)

    slot = jnp.where(emit, jnp.cumsum(emit), cap_points)  # 1 … : after the start
    count = jnp.sum(emit) + 2

    def scatter(buf, x):
        return buf.at[slot].set(x, mode="drop")

    dtype = v.dtype
    P3 = scatter(jnp.zeros((cap_points, 3), dtype), pts)
    K = scatter(jnp.zeros(cap_points, jnp.int32), kinds)
    E = scatter(jnp.zeros(cap_points, jnp.int32), elems)
    U = scatter(jnp.zeros(cap_points, dtype), params)
    last = jnp.minimum(count - 1, cap_points - 1)
    P3 = P3.at[0].set(start).at[last].set(end)
    K = K.at[0].set(FACE).at[last].set(FACE)
    E = E.at[0].set(s.face).at[last].set(t.face)
    U = U.at[0].set(0.0).at[last].set(0.0)
    # the unused tail repeats the end point
    tail = jnp.arange(cap_points) > last
    P3 = jnp.where(tail[:, None], end, P3)
    return P3, K, E, U, count, length, jnp.all(inside)


def exact_solve(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    *,
    max_points: int,
    max_starts: int = 8,
    max_iterations: int | None = None,
    corridor_capacity: int | None = None,
    detours: int = 16,
    detour_rounds: int = 2,
    walls: bool = True,
    min_lanes: int | None = None,
) -> ExactResult:
    """The exact polyhedral geodesics from `start[i]` to `end[i]` for a batch of
    endpoint pairs (leading axis B of `start.face`, `start.bary`, …; see the module
    docstring). All B × `max_starts` starts are refined as lanes of one compiled
    loop. jit/vmap/grad-compatible; `status` says whether each path succeeded.

    **Arguments:** `max_points`: capacity of the result's buffers; `max_starts`:
    landmark starts refined per pair; `max_iterations`: flip rounds at most (None:
    the corridor capacity, at least 256: a start crosses the rows of vertices
    between it and the geodesic one per round, and finer meshes have more rows;
    a 1M-face catenoid's pair took 423);
    `corridor_capacity`: faces a corridor may hold (default `max_points`; a pair
    any of whose lanes outgrew it has `stats.outgrew` set, see
    `jaxgeo.methods.first_attempts`); `detours`: after the starts, refine this
    many corridors that pass the best path's nearest cone vertices on their other
    side (`_detours`), and with `walls` 8 more that pass a whole stretch of one of
    its walls on the other side (`_wall_flip`), in `detour_rounds` rounds, each
    from the best path so far (or the runner-up, once the best one's detours
    were tried); `min_lanes`: the flip loop's lanes at least (None: `POOL_MIN`;
    see `POOL_MIN_CONE_FREE`).

    **Returns:** an `ExactResult` with a leading batch axis.
    """
    cap = min(corridor_capacity or max_points, max_points)
    if max_iterations is None:
        max_iterations = max(256, cap)
    dtype = mesh.vertices.dtype
    tol = _curvature.cone_tolerance(dtype)
    s, t = (
        jax.vmap(lambda p: _end(mesh, p))(start),
        jax.vmap(lambda p: _end(mesh, p))(end),
    )
    sg = jax.lax.stop_gradient
    smesh = sg(mesh)
    ss, ts = sg(s), sg(t)
    # (computed with the mesh: `jaxgeo._curvature`)
    angles, theta = smesh.corner_angles, smesh.vertex_angle_sums

    def graph_vertex(e: _End):
        return smesh.faces[e.face, jnp.argmax(e.bary)]

    vs, vt = jax.vmap(graph_vertex)(ss), jax.vmap(graph_vertex)(ts)
    slots, slot_ok = jax.vmap(lambda a, b: best_slots(smesh, a, b, max_starts))(vs, vt)
    n_pairs, k = slots.shape

    def lanes_of(x):  # (B, ...) → (B·k, ...)
        return jnp.repeat(x, k, axis=0)

    # cone-free components: the detours cannot find a shorter path, and two
    # starts of one class reach the same one (`jaxgeo._curvature`)
    component = smesh.face_component[ss.point.face]
    no_detours = smesh.component_cone_free[component]
    disc = no_detours & smesh.component_disc[component]
    annulus = no_detours & smesh.component_annulus[component]
    known = disc | annulus
    # (a cone-free annulus's path at most half its systole is the shortest)
    systole = jnp.where(annulus, smesh.component_systole[component], 0)

    def settled(length):  # a converged path of `length` is globally shortest
        return disc | (annulus & _certified_by_systole(length, systole))

    s_l, t_l = jax.tree.map(lanes_of, ss), jax.tree.map(lanes_of, ts)
    n_keys = n_pairs * (2 * WINDINGS + 1)
    lanes = n_pairs * k
    unused = (
        jnp.full((lanes, cap), -1, jnp.int32),
        jnp.zeros(lanes, jnp.int32),
        jnp.full(lanes, Status.REFINE_FAILED, jnp.int32),
    )
    no_keys = jnp.full(lanes, -1, jnp.int32)

    def starts_of(lo, hi, open_):
        """The start corridors of the slots lo … hi − 1 of every open pair (the
        other lanes unused), and their keys: their pair and winding, where the
        class is known (windings beyond ±WINDINGS: none). One slot of every pair
        at a time: the loop's body is the one compiled start of every phase."""

        def one_slot(j, built):
            (corridor, n, status0), key = built
            one = jnp.arange(n_pairs)
            # (pyright misreads *args of unknown length followed by more arguments)
            c, m, st = jax.vmap(lambda *x: _start(smesh, angles, *x, cap))(  # pyright: ignore[reportCallIssue]
                slots[:, j], slot_ok[:, j] & open_, vs, vt, ss, ts
            )
            winding = jax.vmap(lambda *x: _winding(smesh, *x))(c, m, ss, ts)
            kj = jnp.where(
                known & (jnp.abs(winding) <= WINDINGS),
                one * (2 * WINDINGS + 1) + winding + WINDINGS,
                -1,
            )
            rows = one * k + j
            return (
                corridor.at[rows].set(c),
                n.at[rows].set(m),
                status0.at[rows].set(st),
            ), key.at[rows].set(kj.astype(jnp.int32))

        return jax.lax.fori_loop(lo, hi, one_slot, (unused, no_keys))

    # Phase 0 refines the k starts of every pair; then each of `detour_rounds`
    # rounds takes the detours of the best path so far, k at a time. All phases
    # run through one `_refine` inside a fori_loop: it is the bulk of the program,
    # and compiled once instead of once per phase (a third of the compile time).
    # With `min_lanes` 1 (meshes with no cone vertex, `POOL_MIN_CONE_FREE`) a
    # phase before it refines the first start of every pair alone, and phase 0
    # the others of the pairs it did not settle (certified, `settled`): most
    # single paths then build one start rather than k (20k catenoid: 0.6 ms
    # against 1.9, and the refinement of the other starts' corridors).
    first_alone = min_lanes == 1
    p0 = 1 if first_alone else 0
    n_walls = 2 * len(WALL_STRETCHES)
    cone_chunks = -(-detours // k) if detours else 0
    chunks = cone_chunks + (-(-n_walls // k) if walls else 0)
    phases = p0 + 1 + chunks * detour_rounds

    def walls_of(c, m_, a, b):  # padded to whole chunks with unused corridors
        corridor, n, fits = _wall_flips(smesh, c, m_, a, b)
        pad = -n_walls % k
        corridor = jnp.concatenate([corridor, jnp.broadcast_to(c, (pad,) + c.shape)])
        n = jnp.concatenate([n, jnp.full(pad, m_)])
        fits = jnp.concatenate([fits, jnp.zeros(pad, bool)])
        return corridor, n, fits, jnp.arange(n_walls + pad) < n_walls

    def detours_of(win: _Lane, fresh):
        parts = []
        if cone_chunks:
            parts.append(
                jax.vmap(
                    lambda c, m_, p, pm, a, b: _detours(
                        smesh, theta, c, m_, p, pm, a, b, cone_chunks * k, tol
                    )
                )(win.corridor, win.n, win.pinned, win.m, ss, ts)
            )
        if walls:
            parts.append(jax.vmap(walls_of)(win.corridor, win.n, ss, ts))
        corridor, n, fits, valid = (jnp.concatenate(x, axis=1) for x in zip(*parts))
        status0 = jnp.where(
            valid,
            jnp.where(fits, -1, Status.MAX_STEPS),
            Status.REFINE_FAILED,  # fewer candidate cones than detours
        )
        cone = jnp.arange(chunks * k)
        used = (cone < detours) | (cone >= cone_chunks * k)  # walls: `valid`
        # no detours of a pair none of whose starts converged: its `win` is the
        # empty placeholder, whose "detours" would be empty corridors
        used = used & (win.status == Status.SUCCESS)[:, None]
        # nor of a path whose detours were tried already (no runner-up either):
        # the round would repeat one already run (measured on random pairs of a
        # 20k-face catenoid, no cone vertices, so never a runner-up: 14 ms of a
        # 140 ms path, and 57 of the batch's ~400 trips)
        used = used & fresh[:, None] & ~no_detours[:, None]
        status0 = jnp.where(used, status0, Status.REFINE_FAILED)
        return corridor, n, status0.astype(jnp.int32)

    def phase(p, carry):
        win, alt, expanded, found, outgrew, converged, first_status, keys, pending = (
            carry
        )
        won, grew_keys = keys
        starting = p <= p0
        if first_alone:  # phase 0: the first slot; then the others, if open
            open_ = ~(found & settled(win.length))
            more = jnp.where(starting & jnp.any(open_), k, 1)
            built = starts_of(
                jnp.where(p == 0, 0, 1), jnp.where(p == 0, 1, more), open_
            )
        else:
            built = starts_of(0, jnp.where(p == 0, k, 0), jnp.ones(n_pairs, bool))
        q = p - p0  # the detour phases: 1, 2, …
        j = (q - 1) % max(chunks, 1)
        if chunks:
            # detour from the best path, or where its detours were tried already
            # (no detour of them was shorter), from the runner-up: two locally
            # shortest paths may differ at two cone vertices, neither of whose
            # single detours is shorter than the best
            rnd = (q - 1) // chunks
            both = jax.tree.map(lambda x, y: jnp.stack([x, y], axis=1), win, alt)
            fresh = jnp.stack(
                [~_seen(win.length, expanded), jnp.ones(n_pairs, bool)], 1
            )
            src, src_fresh = _shortest(both, fresh)  # (win if neither qualifies)
            start_round = (q >= 1) & (j == 0)
            pending = jax.lax.cond(
                start_round, lambda: detours_of(src, src_fresh), lambda: pending
            )
            expanded = jnp.where(
                start_round & (jnp.arange(expanded.shape[1]) == rnd)[None],
                src.length[:, None],
                expanded,
            )
        part = jax.tree.map(
            lambda x: jax.lax.dynamic_slice_in_dim(x, j * k, k, axis=1).reshape(
                (n_pairs * k,) + x.shape[2:]
            ),
            pending,
        )
        corridor, n, status0 = jax.tree.map(
            lambda a, b: jnp.where(starting, a, b), built[0], part
        )
        lane_key = jnp.where(starting, built[1], -1)
        lanes = _refine(
            smesh,
            theta,
            corridor,
            n,
            status0,
            s_l,
            t_l,
            max_iterations,
            tol,
            lane_key,
            n_keys,
            min_lanes,
            systole,
            won,
        )
        # a lane that outgrew the capacity matters unless a lane of its key
        # converged, in this phase or a later one: that is the path it would
        # have reached (`jaxgeo._curvature`; or its pair is certified by the
        # systole: it is no shorter). Keyed lanes are counted at the end.
        won = won | _won(lanes, lane_key, n_keys, systole)
        grew = lanes.status == Status.MAX_STEPS
        keyed = jnp.where(grew & (lane_key >= 0), lane_key, n_keys)
        grew_keys = grew_keys.at[keyed].set(True, mode="drop")
        grew = (grew & (lane_key < 0)).reshape(n_pairs, k)
        lanes = jax.tree.map(lambda x: x.reshape((n_pairs, k) + x.shape[1:]), lanes)
        ok = jnp.any(lanes.status == Status.SUCCESS, axis=1)
        every = jax.tree.map(
            lambda x, y, z: jnp.concatenate([x[:, None], y[:, None], z], axis=1),
            win,
            alt,
            lanes,
        )
        win, _ = _shortest(every)
        other = ~_seen(every.length, win.length[:, None, None]) & ~_seen(
            every.length, expanded[:, None, :]
        )
        alt, any_alt = _shortest(every, other)
        alt = eqx.tree_at(
            lambda x: x.status,
            alt,
            jnp.where(any_alt, alt.status, Status.REFINE_FAILED).astype(jnp.int32),
        )
        good = lanes.status == Status.SUCCESS
        return (
            win,
            alt,
            expanded,
            found | ok,
            outgrew | jnp.any(grew, axis=1),
            converged + jnp.where(starting, jnp.sum(good, axis=1, dtype=jnp.int32), 0),
            jnp.where(p == 0, lanes.status[:, 0], first_status),
            (won, grew_keys),
            pending,
        )

    no_win = _Lane(
        corridor=jnp.full((n_pairs, cap), -1, jnp.int32),
        n=jnp.zeros(n_pairs, jnp.int32),
        pinned=jnp.full((n_pairs, cap + 2), _sleeve.END, jnp.int32),
        m=jnp.zeros(n_pairs, jnp.int32),
        length=jnp.full(n_pairs, jnp.inf, dtype),
        iterations=jnp.zeros(n_pairs, jnp.int32),
        flips=jnp.zeros(n_pairs, jnp.int32),
        status=jnp.full(n_pairs, Status.REFINE_FAILED, jnp.int32),
        done=jnp.ones(n_pairs, bool),
    )
    no = jnp.zeros(n_pairs, bool)
    width = max(chunks, 1) * k  # (with no detours, one unused chunk)
    pending = (
        jnp.full((n_pairs, width, cap), -1, jnp.int32),
        jnp.zeros((n_pairs, width), jnp.int32),
        jnp.full((n_pairs, width), Status.REFINE_FAILED, jnp.int32),
    )
    expanded = jnp.full((n_pairs, max(detour_rounds, 1)), jnp.inf, dtype)
    init = (
        no_win,
        no_win,
        expanded,
        no,
        no,
        jnp.zeros(n_pairs, jnp.int32),
        no.astype(jnp.int32),
        (jnp.zeros(n_keys, bool), jnp.zeros(n_keys, bool)),
    )
    # (no detour phase at all where no pair takes detours, and no phase once
    # every pair is settled: a cone-free pair's first start alone, mostly)
    n_phases = jnp.where(jnp.all(no_detours), p0 + 1, phases)

    def more(state):
        p, carry = state
        win, found = carry[0], carry[3]
        return (p < n_phases) & ~jnp.all(found & settled(win.length))

    _, carry = jax.lax.while_loop(
        more, lambda st: (st[0] + 1, phase(*st)), (0, init + (pending,))
    )
    win, _, _, found, outgrew, converged, first_status, keys, _ = carry
    won, grew_keys = keys
    outgrew = outgrew | jnp.any((grew_keys & ~won).reshape(n_pairs, -1), axis=1)
    status = jnp.where(found, Status.SUCCESS, first_status)
    certified = found & settled(win.length)
    stats = ExactStats(
        iterations=win.iterations,
        flips=win.flips,
        starts=jnp.sum(slot_ok, axis=1, dtype=jnp.int32),
        starts_converged=converged,
        corridor_length=win.n,
        # (a certified pair's path is the shortest whichever lanes outgrew)
        outgrew=(outgrew & ~certified).astype(jnp.int32),
        certified=certified.astype(jnp.int32),
    )
    # (pyright misreads *args of unknown length followed by more arguments)
    return jax.vmap(lambda *a: _finish(mesh, *a, max_points))(  # pyright: ignore[reportCallIssue]
        start, end, s, t, win.corridor, win.n, status, stats
    )


def _shortest(lanes: _Lane, mask: Bool[Array, "P L"] | bool = True):
    """Per pair (axis 0), the shortest successful lane (axis 1) among `mask`, and
    whether any succeeded. Lengths equal to rounding (`_seen`) are a tie, which
    the first such lane wins: two equally short paths (a symmetric mesh) are
    told apart by lane order, not by the last bits of a sum, which differ with
    the width of the loop that refined them (a pair alone or in a batch)."""
    good = (lanes.status == Status.SUCCESS) & mask
    length = jnp.where(good, lanes.length, jnp.inf)
    least = jnp.min(length, axis=1, keepdims=True)
    best = jnp.argmax(good & _seen(length, least[..., None]), axis=1)
    rows = jnp.arange(good.shape[0])
    return jax.tree.map(lambda x: x[rows, best], lanes), jnp.any(good, axis=1)


def _seen(length, lengths):
    """Is `length` one of `lengths` (last axis), to rounding? The same locally
    shortest path, reached from two corridors, has the same length to ~1e-15."""
    close = jnp.abs(length[..., None] - lengths) <= 1e-12 * jnp.abs(length[..., None])
    return jnp.any(close & jnp.isfinite(lengths), axis=-1)


def _finish(mesh, start, end, s, t, corridor, n, status, stats, max_points):
    """One pair's result from its winning corridor (differentiable)."""
    smesh = jax.lax.stop_gradient(mesh)
    ss, ts = jax.lax.stop_gradient((s, t))
    p_start, p_end = start.position(mesh), end.position(mesh)
    P3, K, E, U, count, length, inside = _assemble(
        mesh, corridor, n, s, t, p_start, p_end, max_points
    )
    # a face holding both endpoints: the straight segment is globally shortest
    direct = _common_face(smesh, ss, ts) >= 0
    idx = jnp.arange(max_points)
    P3 = jnp.where(direct, jnp.where((idx >= 1)[:, None], p_end, p_start), P3)
    K = jnp.where(direct, FACE, K)
    E = jnp.where(direct, jnp.where(idx >= 1, t.face, s.face), E)
    U = jnp.where(direct, 0.0, U)
    count = jnp.where(direct, 2, count)
    length = jnp.where(direct, safe_norm(p_end - p_start), length)
    status = jnp.where(
        ~inside & (status == Status.SUCCESS), Status.REFINE_FAILED, status
    )
    status = jnp.where(direct, Status.SUCCESS, status)
    ok = status == Status.SUCCESS
    status = jnp.where(ok & (count > max_points), Status.MAX_STEPS, status)
    zero = jnp.zeros((), jnp.int32)
    stats = jax.tree.map(lambda x: jnp.where(direct, zero, x), stats)
    # (the straight segment is as short as the chord: certified)
    stats = eqx.tree_at(
        lambda x: (x.corridor_length, x.certified),
        stats,
        (
            jnp.where(direct, 1, stats.corridor_length),
            jnp.where(direct, 1, stats.certified),
        ),
    )
    return ExactResult(
        points=P3,
        kinds=K,
        elements=E,
        params=U,
        count=count.astype(jnp.int32),
        length=length,
        status=status.astype(jnp.int32),
        stats=stats,
    )
