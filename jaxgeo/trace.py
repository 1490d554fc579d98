"""The sliding laser ray (sections 4–5 of the paper).

From the current point P of the path, the chord P → point 2 is projected onto the
mesh along the Phong normals: System (16) is solved on a set of candidate edges and
the nearest valid crossing ahead of P (chord parameter t > 0) becomes the next point
of the path; the chord's start slides there and the step repeats until the face of
point 2 is reached.

The loop is a `lax.while_loop` with fixed-capacity buffers, so it compiles once for
a mesh size and `max_points` and runs under `jax.vmap`. It makes discrete choices
(which edge is next), so it is not differentiated; `jaxgeo.replay` recomputes the
crossings differentiably on the edge sequence it found.

The loop's carry is `_State`; a step (`_step`) is three functions of an explicit
context (`_Context`: the mesh, its frame, the normals, the options), a lane's
endpoints (`_Ends`) and the state: `_look_ahead` (the nearest valid crossing of
the chord ahead), `_plan_slide` (a slide along the boundary when there is none)
and `_advance` (the next state).

Boundaries: on an open mesh the chord's projection can leave the mesh (the chord
passes over a hole or outside a free edge), and then no crossing lies ahead. If the
current point is on the boundary, the path slides along it instead: to the end of
a boundary edge through the current point whose direction is closest to the
chord's, provided it is ahead (positive cosine) and not the vertex the path just
left. The slid-to vertex is a `VERTEX` point and the laser ray resumes from it, so
around a hole the path hugs the hole's rim, as a geodesic does. Only when no
boundary edge points ahead (or the point is inside the mesh) does the trace stop
with `Status.NO_CROSSING`. Slides cannot hang the loop: every step appends a point
and the loop ends at `max_points` (`Status.MAX_STEPS`).

Candidates:

- `"local"`: the edges of the faces around P (the face it is in; the two faces of
  its edge; the ring of faces of its vertex), minus the edges through P. The cost of
  a step does not depend on the mesh size, and crossings on the far side of a
  closed surface (the normal lines of a chord pierce both sides) are never seen.
- `"all"`: every edge of the mesh, as in the paper (Steps 2–5). The nearest valid
  crossing ahead is the next point; on a closed surface the far-side crossings are
  about a diameter away and lose to the near-side ones.
"""

from __future__ import annotations

import dataclasses
import numbers
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._errors import JaxgeoError
from ._numerics import eps_of, safe_norm, safe_normalize
from .locate import SurfacePoint, snap
from .mesh import Mesh
from .path import EDGE, FACE, VERTEX, Path, Status, pad_tail, polyline_length
from .projection import param_tolerance, solve_edges


@dataclasses.dataclass(frozen=True)
class TraceOptions:
    """Static options of the sliding laser ray (changing one recompiles once).

    - `candidates`: `"local"` (default) or `"all"` (see the module docstring).
    - `max_points`: capacity of the path buffers, endpoints included.
    - `newton_steps`: Newton iterations allowed per root of System (16); the
      closed-form start needs one or two.
    """

    candidates: Literal["local", "all"] = "local"
    max_points: int = 1024
    newton_steps: int = 8

    def __post_init__(self):
        if self.candidates not in ("local", "all"):
            raise JaxgeoError(
                f"candidates must be 'local' or 'all', not {self.candidates!r}"
            )
        for name, low in (("max_points", 2), ("newton_steps", 1)):
            value = getattr(self, name)
            # bool is an int subclass, but max_points=True is a mistake
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise JaxgeoError(
                    f"{name} must be an integer, got {type(value).__name__} {value!r}"
                )
            if value < low:
                raise JaxgeoError(f"{name} must be at least {low}, got {value}")
            object.__setattr__(self, name, int(value))  # np.int64 → int: hashable


def star_faces(
    mesh: Mesh, kind: Int[Array, ""], index: Int[Array, ""]
) -> Int[Array, " S"]:
    """The faces around a mesh element (a face itself; the faces of an edge; the
    ring of a vertex), padded with −1 to a fixed width."""
    width = max(mesh.vertex_faces.shape[1], 2)

    def pad(a):
        return jnp.concatenate([a, jnp.full(width - a.shape[0], -1, a.dtype)])

    face = pad(jnp.reshape(index, (1,)).astype(mesh.faces.dtype))
    edge = pad(mesh.edge_faces[index])
    vertex = pad(mesh.vertex_faces[index])
    return jnp.where(kind == FACE, face, jnp.where(kind == EDGE, edge, vertex))


def local_candidates(
    mesh: Mesh, kind: Int[Array, ""], index: Int[Array, ""], star: Int[Array, " S"]
) -> tuple[Int[Array, " W"], Bool[Array, " W"]]:
    """The `"local"` candidate edges of a point, each once: the edges of the faces
    around it that do not pass through it. A face point: its face's 3 edges; an
    edge point: the other 4 edges of its 2 faces; a vertex: the rim of its ring,
    the edge opposite the vertex in each face. `star` is
    `star_faces(mesh, kind, index)`. Returns `(edges, live)`, padded to a fixed
    width (`live` False on padding)."""
    width = max(mesh.vertex_faces.shape[1], 6)
    fe = mesh.face_edges[jnp.maximum(star, 0)]  # (S, 3)
    rim = jnp.sum(jnp.where(mesh.faces[jnp.maximum(star, 0)] == index, fe, 0), axis=1)

    def pad(a, fill):
        return jnp.concatenate([a, jnp.full(width - a.shape[0], fill, a.dtype)])

    two = fe[:2].reshape(-1)  # the edges of the first two faces of the star
    two_live = jnp.where(
        kind == FACE, jnp.arange(6) < 3, jnp.repeat(star[:2] >= 0, 3) & (two != index)
    )
    vertex = kind == VERTEX
    cand = jnp.where(vertex, pad(rim, 0), pad(two, 0))
    live = jnp.where(vertex, pad(star >= 0, False), pad(two_live, False))
    return cand.astype(mesh.edges.dtype), live


class _State(eqx.Module):
    """The carry of the trace loop (coordinates in the mesh's frame, `_frame`)."""

    pos: Float[Array, "3"]  # the current point
    kind: Int[Array, ""]  # its kind and element (FACE, EDGE, VERTEX)
    idx: Int[Array, ""]
    prev_kind: Int[Array, ""]  # the previous point's (never stepped back onto)
    prev_idx: Int[Array, ""]
    count: Int[Array, ""]  # points in the buffers
    status: Int[Array, ""]  # −1 while tracing
    steps: Int[Array, ""]  # loop iterations so far (bounded by the step budget)
    anchor: Int[Array, ""]  # slot of the last wrapped vertex (or the start)
    aim: Int[Array, ""]  # the vertex the chord aims at, −1 for point 2
    slide_dir: Int[Array, ""]  # a slide's way round its boundary loop: ±1, 0 none
    slide_origin: Int[Array, ""]  # where that slide began (a full turn stops it)
    no_taut: Int[Array, ""]  # a slide target whose taut aim was blocked, or −1
    pts: Float[Array, "M 3"]
    kinds: Int[Array, " M"]
    elems: Int[Array, " M"]
    params: Float[Array, " M"]
    branch: Bool[Array, " M"]
    aims: Int[Array, " M"]  # per point: the chord's aim when it was found


class _Frame(NamedTuple):
    centre: Float[Array, "3"]
    scale: Float[Array, ""]
    vertices: Float[Array, "V 3"]  # (mesh.vertices − centre) / scale


def _frame(mesh: Mesh) -> _Frame:
    """The mesh's centre (its bounding box's), a power of two near its size, and
    the vertices in that frame.

    The trace works in `(x − centre) / scale`: the mesh is then of size ~1 at the
    origin wherever it sits and however large it is, so the absolute tolerances of
    the Newton polish (on System (16)'s residual, a length) and the rounding of
    every difference are the same for a mesh at the origin and one at site
    coordinates (1e6 m away). The scale is a power of two, so scaling is exact."""
    v = jax.lax.stop_gradient(mesh.vertices)
    lo, hi = jnp.min(v, axis=0), jnp.max(v, axis=0)
    extent = jnp.max(hi - lo)
    extent = jnp.where(extent > 0, extent, 1.0)
    scale = jnp.ldexp(
        jnp.ones((), v.dtype), jnp.round(jnp.log2(extent)).astype(jnp.int32)
    )
    centre = (lo + hi) / 2
    return _Frame(centre, scale, (v - centre) / scale)


#: Loop iterations allowed per buffer slot: a slide pulled taut re-traces from
#: its anchor, so a path may take more steps than it has points.
_STEP_BUDGET = 8


class _Context(eqx.Module):
    """What every lane's steps read and none changes: the mesh, its frame
    (`_frame`), the normals, the options and the tolerances."""

    mesh: Mesh
    frame: _Frame
    normals: Float[Array, "V 3"]
    # A branch: a second valid crossing ahead, farther than this from the chosen
    # one (well above the solver's noise, well below any edge length).
    branch_gap: Float[Array, ""]
    options: TraceOptions = eqx.field(static=True)

    @property
    def verts(self) -> Float[Array, "V 3"]:
        """The vertices in the trace's frame."""
        return self.frame.vertices

    @property
    def tol(self) -> float:
        """Slack on edge and chord parameters (`param_tolerance`)."""
        return param_tolerance(self.mesh.vertices.dtype)

    @property
    def t_ahead(self) -> float:
        """A crossing is ahead when its chord parameter t exceeds this."""
        # The rounding error of t after the Newton polish (a few eps): 1e-9 in
        # float64 (as param_tolerance), 8 eps ≈ 1e-6 in float32. Not
        # param_tolerance in float32 (1e-4): near a vertex with a fan of edges
        # the next crossing can be 1e-4 of the chord away, and float32 traces
        # stopped there with NO_CROSSING (found by the float32 runs of
        # docs/accuracy.md on the twin-peak tent).
        dtype = self.mesh.vertices.dtype
        return self.tol if dtype == jnp.float64 else 8 * eps_of(dtype)

    @property
    def slack(self) -> float:
        """Cosines and angles (dimensionless) closer than this to a threshold
        count as on it: far above the rounding of unit vectors and of a fan's
        angle sum."""
        return 1e3 * eps_of(self.mesh.vertices.dtype)


def _context(
    mesh: Mesh, frame: _Frame, normals: Float[Array, "V 3"], options: TraceOptions
) -> _Context:
    """The `_Context` of a trace; `frame = _frame(mesh)`."""
    gap = 1e-6 * mesh.mean_edge_length / frame.scale
    return _Context(mesh, frame, normals, gap, options)


class _Ends(eqx.Module):
    """One lane's endpoints as its steps need them."""

    p2: Float[Array, "3"]  # point 2 in the frame
    kind1: Int[Array, ""]  # the element point 1 lies on (`snap`)
    idx1: Int[Array, ""]
    target: Int[Array, " S"]  # the faces round point 2's element
    end_face: Int[Array, ""]


def _ends(ctx: _Context, start: SurfacePoint, end: SurfacePoint) -> _Ends:
    """A lane's `_Ends` (computed once, outside the loop)."""
    mesh, (centre, scale, _) = ctx.mesh, ctx.frame
    kind1, idx1 = snap(mesh, start, ctx.tol)
    kind2, idx2 = snap(mesh, end, ctx.tol)
    return _Ends(
        p2=(end.position(mesh) - centre) / scale,
        kind1=kind1,
        idx1=idx1.astype(jnp.int32),
        target=star_faces(mesh, kind2, idx2),
        end_face=jnp.asarray(end.face).astype(jnp.int32),
    )


def _initial_state(
    ctx: _Context,
    start: SurfacePoint,
    ends: _Ends,
    initial_status: Int[Array, ""] | int,
) -> _State:
    """The state before the first step: point 1 in the buffers; tracing when
    `initial_status` is −1, else finished with that status."""
    centre, scale, _ = ctx.frame
    dtype = ctx.mesh.vertices.dtype
    m = ctx.options.max_points
    p1 = (start.position(ctx.mesh) - centre) / scale
    minus1 = jnp.asarray(-1, jnp.int32)
    return _State(
        pos=p1,
        kind=ends.kind1,
        idx=ends.idx1,
        prev_kind=jnp.asarray(FACE, jnp.int32),  # no previous point: touches no edge
        prev_idx=minus1,
        count=jnp.asarray(1, jnp.int32),
        status=jnp.asarray(initial_status, jnp.int32),
        steps=jnp.asarray(0, jnp.int32),
        anchor=jnp.asarray(0, jnp.int32),
        aim=minus1,
        slide_dir=jnp.asarray(0, jnp.int32),
        slide_origin=minus1,
        no_taut=minus1,
        pts=jnp.zeros((m, 3), dtype).at[0].set(p1),
        kinds=jnp.zeros(m, jnp.int32),  # the endpoints are FACE points
        elems=jnp.zeros(m, jnp.int32).at[0].set(jnp.asarray(start.face, jnp.int32)),
        params=jnp.zeros(m, dtype),
        branch=jnp.zeros(m, bool),
        aims=jnp.full(m, -1, jnp.int32),
    )


def _in_star(
    ctx: _Context, cand: Int[Array, " W"], star: Int[Array, " S"]
) -> Bool[Array, " W"]:
    """Candidate edges that are edges of the faces round the current point
    (always, for `"local"` candidates)."""
    if ctx.options.candidates == "local":
        return jnp.ones(cand.shape, bool)
    star_edges = jnp.where(star[:, None] >= 0, ctx.mesh.face_edges[star], -1)
    return jnp.any(cand[:, None] == star_edges.reshape(1, -1), axis=1)


def _touches(
    mesh: Mesh, cand: Int[Array, " W"], kind: Int[Array, ""], idx: Int[Array, ""]
) -> Bool[Array, " W"]:
    """Candidate edges that are the element (kind, idx) or pass through it."""
    return jnp.where(
        kind == EDGE,
        cand == idx,
        (kind == VERTEX) & jnp.any(mesh.edges[cand] == idx, axis=1),
    )


def _candidates(
    ctx: _Context,
    kind: Int[Array, ""],
    idx: Int[Array, ""],
    star: Int[Array, " S"],
    prev_kind: Int[Array, ""],
    prev_idx: Int[Array, ""],
) -> tuple[Int[Array, " W"], Bool[Array, " W"]]:
    """The edges to look for the next crossing on, and which of them count."""
    mesh = ctx.mesh
    if ctx.options.candidates == "local":
        cand, live = local_candidates(mesh, kind, idx, star)
    else:
        # padded edges of a size class have no face (`Mesh.padded`)
        cand = jnp.arange(mesh.n_edges, dtype=mesh.edges.dtype)
        live = mesh.edge_faces[:, 0] >= 0
    # Never step back onto the previous point's edge or through its vertex: on a
    # surface of revolution a chord through the axis has normal projections on
    # both sides, and a path bounced between two ring edges forever.
    behind = _touches(mesh, cand, prev_kind, prev_idx)
    return cand, live & ~_touches(mesh, cand, kind, idx) & ~behind


def _boundary_slide(
    ctx: _Context,
    pos: Float[Array, "3"],
    aim_pos: Float[Array, "3"],
    kind: Int[Array, ""],
    idx: Int[Array, ""],
    star: Int[Array, " S"],
    slide_dir: Int[Array, ""],
    prev_vertex: Int[Array, ""],
) -> tuple[Bool[Array, ""], Int[Array, ""], Int[Array, ""]]:
    """The boundary vertex to slide to when no crossing lies ahead: among the ends
    of the boundary edges through the current point (its vertex's two; its edge;
    a start face's), not the previous point. A slide that continues (`slide_dir` ≠
    0) keeps its way round the boundary loop (+1 along the faces' orientation, −1
    against it) whatever the direction in space (a rim round a hole turns away
    from point 2); a new slide takes the end whose direction is closest to the
    chord's, if it is not behind (cosine ≥ −slack). Returns `(possible, vertex,
    way)`."""
    mesh, verts = ctx.mesh, ctx.verts
    se = mesh.face_edges[jnp.maximum(star, 0)].reshape(-1)
    ends = mesh.edges[se]  # (3S, 2)
    through = jnp.where(
        kind == VERTEX,
        jnp.any(ends == idx, axis=1),
        jnp.where(kind == EDGE, se == idx, True),
    )
    usable = jnp.repeat(star >= 0, 3) & (mesh.edge_faces[se, 1] < 0) & through
    # The head of each boundary edge in its face's orientation (the boundary
    # loop's next vertex after its tail).
    forward = mesh.boundary_next_at(ends[:, 0]) == ends[:, 1]
    head = jnp.where(forward, ends[:, 1], ends[:, 0])
    w = ends.reshape(-1)
    way = jnp.where(w == jnp.repeat(head, 2), 1, -1)
    usable = jnp.repeat(usable, 2) & (w != prev_vertex)
    usable = usable & ~((kind == VERTEX) & (w == idx))
    step_dir = safe_normalize(verts[w] - pos)
    cosine = step_dir @ safe_normalize(aim_pos - pos)
    usable = usable & jnp.where(slide_dir != 0, way == slide_dir, cosine > -ctx.slack)
    best = jnp.argmax(jnp.where(usable, cosine, -jnp.inf))
    return jnp.any(usable), w[best].astype(jnp.int32), way[best].astype(jnp.int32)


def _contains(
    mesh: Mesh, face: Int[Array, ""], kind: Int[Array, ""], idx: Int[Array, ""]
) -> Bool[Array, ""]:
    """Whether the point (kind, idx) lies on the closure of `face`."""
    return jnp.where(
        kind == FACE,
        face == idx,
        jnp.where(
            kind == EDGE,
            jnp.any(mesh.face_edges[face] == idx),
            jnp.any(mesh.faces[face] == idx),
        ),
    )


def _mesh_angle(
    ctx: _Context,
    v: Int[Array, ""],
    out_vertex: Int[Array, ""],
    q: Float[Array, "3"],
    q_kind: Int[Array, ""],
    q_idx: Int[Array, ""],
) -> Float[Array, ""]:
    """The surface's angle at boundary vertex `v` from its boundary edge to
    `out_vertex` round to the direction of the path's previous point `q`: the
    corner angles of the faces of v's fan from that edge's face on (`fan_faces`,
    forward from position 0 when the edge leaves v along the boundary, else back
    from the last), plus the part of `q`'s face up to `q`. At least π means `v` is
    a vertex the path wraps (a geodesic may bend there); below π the path can be
    shortened by cutting across the faces. 0 when the walk never meets `q`."""
    mesh, verts = ctx.mesh, ctx.verts
    pv = verts[v]
    size = mesh.fan_size[v]
    forward = mesh.boundary_next_at(v) == out_vertex
    width = mesh.fan_faces.shape[1]

    def angle(a, b):
        return jnp.arctan2(safe_norm(jnp.cross(a, b)), jnp.dot(a, b))

    def body(j, carry):
        total, done = carry
        pos = jnp.where(forward, j, size - 1 - j)  # the j-th face of the walk
        live = (j < size) & ~done
        p = jnp.clip(pos, 0, width - 1)
        f = jnp.maximum(mesh.fan_faces[v, p], 0)
        # face pos has corners (v, a, b), spokes a = fan_spokes[pos], b = [pos + 1]:
        # the walk enters it across x and leaves across y
        a, b = mesh.fan_spokes[v, p], mesh.fan_spokes[v, p + 1]
        x, y = jnp.where(forward, a, b), jnp.where(forward, b, a)
        here = live & _contains(mesh, f, q_kind, q_idx)
        part = jnp.where(here, angle(verts[x] - pv, q - pv), 0.0)
        whole = jnp.where(live & ~here, angle(verts[x] - pv, verts[y] - pv), 0.0)
        return total + part + whole, done | here

    init = (jnp.zeros((), verts.dtype), jnp.asarray(False))
    total, done = jax.lax.fori_loop(0, width, body, init)
    return jnp.where(done, total, 0.0)


class _Ahead(eqx.Module):
    """What a step sees ahead (`_look_ahead`)."""

    star: Int[Array, " S"]  # the faces round the current point
    aiming: Bool[Array, ""]  # the chord aims at a vertex (`_State.aim`)
    aim_pos: Float[Array, "3"]  # where the chord ends: that vertex or point 2
    reached: Bool[Array, ""]  # the current point shares a face with the aim
    done: Bool[Array, ""]  # … and the aim is point 2
    crossed: Bool[Array, ""]  # a valid crossing lies ahead
    jumped: Bool[Array, ""]  # the nearest one is off the current point's faces
    u: Float[Array, ""]  # the nearest crossing: its edge parameter,
    crossing: Float[Array, "3"]  # its point,
    cross_kind: Int[Array, ""]  # and the element it is on
    cross_idx: Int[Array, ""]
    n_ahead: Int[Array, ""]  # other crossings ahead on the current faces


def _look_ahead(ctx: _Context, ends: _Ends, s: _State) -> _Ahead:
    """Step, part 1: the chord from the current point to its aim, projected on
    the candidate edges (System (16)); the nearest valid crossing ahead."""
    mesh, verts, normals, tol = ctx.mesh, ctx.verts, ctx.normals, ctx.tol
    edges = mesh.edges
    star = star_faces(mesh, s.kind, s.idx)
    aiming = s.aim >= 0
    aim_pos = jnp.where(aiming, verts[jnp.maximum(s.aim, 0)], ends.p2)
    aim_star = jnp.where(
        aiming,
        star_faces(mesh, jnp.asarray(VERTEX), jnp.maximum(s.aim, 0)),
        ends.target,
    )
    reached = jnp.any((star[:, None] == aim_star[None, :]) & (star[:, None] >= 0))
    done = reached & ~aiming  # point 2 reached
    cand, live = _candidates(ctx, s.kind, s.idx, star, s.prev_kind, s.prev_idx)
    e0, e1 = edges[cand, 0], edges[cand, 1]
    cr = solve_edges(
        s.pos,
        aim_pos,
        verts[e0],
        verts[e1],
        normals[e0],
        normals[e1],
        max_steps=ctx.options.newton_steps,
    )
    ok = cr.valid & (cr.t > ctx.t_ahead) & live[:, None]
    dist = jnp.where(ok, jnp.linalg.norm(cr.point - s.pos, axis=-1), jnp.inf)
    best = jnp.argmin(dist)
    c, r = best // 2, best % 2
    crossed = jnp.any(ok)
    # "all" candidates: the nearest crossing ahead of all edges must lie on a face
    # of the current point, or the polyline would leave the surface (the
    # projection jumped across a gap or a fold): then the trace stops.
    jumped = crossed & ~_in_star(ctx, cand[c][None], star)[0]
    u = cr.u[c, r]
    crossing = cr.point[c, r]
    # Branch point (section 6): the face(s) ahead hold a second crossing.
    elsewhere = jnp.linalg.norm(cr.point - crossing, axis=-1) > ctx.branch_gap
    n_ahead = jnp.sum(ok & elsewhere & _in_star(ctx, cand, star)[:, None])
    # Snap to a vertex when the crossing is at an end of its edge.
    at_end = (u <= tol) | (u >= 1 - tol)
    cross_kind = jnp.where(at_end, VERTEX, EDGE)
    cross_idx = jnp.where(at_end, jnp.where(u <= tol, e0[c], e1[c]), cand[c])
    return _Ahead(
        star=star,
        aiming=aiming,
        aim_pos=aim_pos,
        reached=reached,
        done=done,
        crossed=crossed,
        jumped=jumped,
        u=u,
        crossing=crossing,
        cross_kind=cross_kind,
        cross_idx=cross_idx,
        n_ahead=n_ahead,
    )


class _Slide(eqx.Module):
    """A step's boundary slide (`_plan_slide`)."""

    stuck: Bool[Array, ""]  # nothing reached, nothing crossed
    slide: Bool[Array, ""]  # stuck, not aiming, on a boundary edge to slide along
    slide_to: Int[Array, ""]  # the vertex slid to
    way: Int[Array, ""]  # its way round the boundary loop (±1)
    origin: Int[Array, ""]  # where the slide began
    wraps: Bool[Array, ""]  # the current vertex is one the path wraps
    taut: Bool[Array, ""]  # pull taut: back to the anchor, aiming at `slide_to`
    direct: Bool[Array, ""]  # slide straight to `slide_to`
    give_up: Bool[Array, ""]  # aiming at a vertex and blocked


def _plan_slide(ctx: _Context, ends: _Ends, s: _State, ahead: _Ahead) -> _Slide:
    """Step, part 2: with no crossing ahead on the boundary, slide along a
    boundary edge; straight there when the path wraps the current vertex, else
    pulled taut from the anchor."""
    edges = ctx.mesh.edges
    prev_vertex = jnp.where(s.prev_kind == VERTEX, s.prev_idx, -1)
    can_slide, slide_to, slide_way = _boundary_slide(
        ctx, s.pos, ahead.aim_pos, s.kind, s.idx, ahead.star, s.slide_dir, prev_vertex
    )
    stuck = ~ahead.reached & ~ahead.crossed
    slide = stuck & ~ahead.aiming & can_slide
    # Where a new slide starts: the current vertex, or the far end of the current
    # boundary edge; arriving there again means a full turn of the rim.
    other_end = jnp.sum(edges[jnp.maximum(s.idx, 0)]) - slide_to
    here_vertex = jnp.where(
        s.kind == VERTEX, s.idx, jnp.where(s.kind == EDGE, other_end, -1)
    )
    origin = jnp.where(s.slide_dir != 0, s.slide_origin, here_vertex)
    round_the_rim = slide & (slide_to == origin)
    slide = slide & ~round_the_rim
    # Wrap or shortcut (the path must bend only at vertices it wraps): if the
    # surface's angle at the current vertex between the previous point and the
    # slide is below π, the path is pulled taut instead: it goes back to the
    # anchor (the last wrapped vertex, or the start) and aims at `slide_to`.
    q_slot = jnp.maximum(s.count - 2, 0)
    q_kind = jnp.where(s.count - 2 == 0, ends.kind1, s.kinds[q_slot])
    q_idx = jnp.where(s.count - 2 == 0, ends.idx1, s.elems[q_slot])
    bend = _mesh_angle(
        ctx, jnp.maximum(s.idx, 0), slide_to, s.pts[q_slot], q_kind, q_idx
    )
    at_anchor = s.anchor == s.count - 1
    wraps = (s.kind == VERTEX) & (bend >= jnp.pi - ctx.slack)
    taut = slide & ~at_anchor & ~wraps & (slide_to != s.no_taut)
    direct = slide & ~taut
    # Aiming at a vertex and blocked (the rim in between): give the aim up, make
    # the current point the anchor and aim at point 2 again (the slide keeps its
    # way round the rim); the next slide to that vertex goes straight along the
    # rim (no second taut aim).
    give_up = stuck & ahead.aiming
    return _Slide(
        stuck=stuck,
        slide=slide,
        slide_to=slide_to,
        way=slide_way,
        origin=origin,
        wraps=wraps,
        taut=taut,
        direct=direct,
        give_up=give_up,
    )


def _advance(
    ctx: _Context, ends: _Ends, s: _State, ahead: _Ahead, sl: _Slide
) -> _State:
    """Step, part 3: the new state. Appends the next point (point 2, the aimed
    vertex, a crossing or a slide's vertex) or goes back to the anchor to pull
    taut; sets the status when the path is done, stuck or out of room."""
    mesh, verts = ctx.mesh, ctx.verts
    m = ctx.options.max_points
    running = s.status < 0
    full = s.count >= m - 1  # keep one slot for point 2
    failed = ahead.jumped | (sl.stuck & ~ahead.aiming & ~sl.slide)
    out_of_steps = s.steps + 1 >= _STEP_BUDGET * m
    append = running & (
        ahead.done | (~full & ~failed & (ahead.reached | ahead.crossed | sl.direct))
    )
    new_status = jnp.where(
        ahead.done,
        Status.SUCCESS,
        jnp.where(
            failed,
            Status.NO_CROSSING,
            jnp.where(full | out_of_steps, Status.MAX_STEPS, -1),
        ),
    )
    new_status = jnp.where(running, new_status, s.status).astype(jnp.int32)
    moving = running & append & ~ahead.done

    # The appended point: point 2, the aimed vertex, a crossing or a slide.
    to_vertex = ahead.reached | sl.direct
    new_kind = jnp.where(to_vertex, VERTEX, ahead.cross_kind).astype(jnp.int32)
    new_idx = jnp.where(
        ahead.reached, s.aim, jnp.where(sl.direct, sl.slide_to, ahead.cross_idx)
    ).astype(jnp.int32)
    point = jnp.where(new_kind == VERTEX, verts[new_idx], ahead.crossing)
    u = jnp.where(new_kind == VERTEX, 0.0, ahead.u)
    out_point = jnp.where(ahead.done, ends.p2, point)
    out_kind = jnp.where(ahead.done, FACE, new_kind).astype(jnp.int32)
    out_elem = jnp.where(ahead.done, ends.end_face, new_idx)
    out_param = jnp.where(ahead.done, 0.0, u)
    slot = jnp.where(append, s.count, m - 1)

    def keep(buf, val):
        return buf.at[slot].set(jnp.where(append, val, buf[slot]))

    branch_here = ahead.crossed & ~ahead.reached & (s.count > 1) & (ahead.n_ahead > 0)

    # Pulling taut: the loop resumes from the anchor with the slide as its aim.
    back = running & sl.taut & ~full
    a = s.anchor
    a_kind = jnp.where(a == 0, ends.kind1, s.kinds[a])
    a_idx = jnp.where(a == 0, ends.idx1, s.elems[a])
    b_kind = jnp.where(a <= 1, jnp.where(a == 0, FACE, ends.kind1), s.kinds[a - 1])
    b_idx = jnp.where(a <= 1, jnp.where(a == 0, -1, ends.idx1), s.elems[a - 1])

    def pick(new_moving, new_back, old):
        return jnp.where(moving, new_moving, jnp.where(back, new_back, old))

    sliding = sl.direct | sl.taut
    # A slide ends where the laser ray goes on into the mesh: a crossing toward
    # point 2 on an interior edge or vertex (one on the boundary, across a notch
    # of the rim, continues the slide).
    on_boundary = jnp.where(
        ahead.cross_kind == EDGE,
        mesh.edge_faces[ahead.cross_idx, 1] < 0,
        mesh.boundary_next_at(ahead.cross_idx) >= 0,
    )
    new_dir = jnp.where(sliding, sl.way, s.slide_dir)
    new_dir = jnp.where(ahead.crossed & ~ahead.aiming & ~on_boundary, 0, new_dir)
    new_origin = jnp.where(sliding, sl.origin, s.slide_origin)
    upd = running & (moving | back | sl.give_up)
    new_anchor = jnp.where(
        sl.direct & sl.wraps,
        s.count - 1,
        jnp.where(sl.give_up, s.count - 1, s.anchor),
    )
    new_aim = jnp.where(
        ahead.reached | sl.give_up, -1, jnp.where(sl.taut, sl.slide_to, s.aim)
    )
    return _State(
        pos=pick(point, s.pts[a], s.pos),
        kind=pick(new_kind, a_kind, s.kind).astype(jnp.int32),
        idx=pick(new_idx, a_idx, s.idx).astype(jnp.int32),
        prev_kind=pick(s.kind, b_kind, s.prev_kind).astype(jnp.int32),
        prev_idx=pick(s.idx, b_idx, s.prev_idx).astype(jnp.int32),
        count=jnp.where(back, a + 1, s.count + append.astype(jnp.int32)),
        status=new_status,
        steps=s.steps + running.astype(jnp.int32),
        anchor=jnp.where(upd, new_anchor, s.anchor).astype(jnp.int32),
        aim=jnp.where(upd, new_aim, s.aim).astype(jnp.int32),
        slide_dir=jnp.where(upd, new_dir, s.slide_dir).astype(jnp.int32),
        slide_origin=jnp.where(upd, new_origin, s.slide_origin).astype(jnp.int32),
        no_taut=jnp.where(running & sl.give_up, s.aim, s.no_taut).astype(jnp.int32),
        pts=keep(s.pts, out_point),
        kinds=keep(s.kinds, out_kind),
        elems=keep(s.elems, out_elem),
        params=keep(s.params, out_param),
        branch=keep(s.branch, branch_here),
        aims=keep(s.aims, jnp.where(ahead.done, -1, s.aim)),
    )


def _step(ctx: _Context, ends: _Ends, s: _State) -> _State:
    """One iteration of the trace loop: look ahead, plan a slide, advance. A
    no-op once the state's status is set (so a batch can step finished lanes
    with the others)."""
    ahead = _look_ahead(ctx, ends, s)
    return _advance(ctx, ends, s, ahead, _plan_slide(ctx, ends, s, ahead))


def _finish(
    mesh: Mesh,
    frame: _Frame,
    start: SurfacePoint,
    end: SurfacePoint,
    s: _State,
) -> Path:
    """The `Path` of a finished state, back in the mesh's coordinates: vertices and
    endpoints exactly, crossings as centre + scale · point; the length is
    measured in the trace's frame (the same digits wherever the mesh sits)."""
    centre, scale, _ = frame
    length = scale * polyline_length(pad_tail(s.pts, s.count), s.count)
    v = jax.lax.stop_gradient(mesh.vertices)
    pts = jnp.where((s.kinds == VERTEX)[:, None], v[s.elems], centre + scale * s.pts)
    pts = pts.at[0].set(jax.lax.stop_gradient(start.position(mesh)))
    last = jnp.maximum(s.count - 1, 0)
    p2 = jax.lax.stop_gradient(end.position(mesh))
    pts = pts.at[last].set(jnp.where(s.status == Status.SUCCESS, p2, pts[last]))
    return Path(
        points=pad_tail(pts, s.count),
        kinds=s.kinds,
        elements=s.elems,
        params=s.params,
        branch=s.branch,
        count=s.count,
        length=length,
        status=s.status,
    )


def trace(
    mesh: Mesh,
    normals: Float[Array, "V 3"],
    start: SurfacePoint,
    end: SurfacePoint,
    options: TraceOptions = TraceOptions(),
    initial_status: Int[Array, ""] | int = -1,
) -> Path:
    """Trace the sliding laser ray from `start` to `end`.

    **Arguments:**

    - `mesh`, `normals`: the mesh and its Phong vertex normals (eq. 8–9).
    - `start`, `end`: the endpoints on the surface.
    - `options`: a `TraceOptions`.
    - `initial_status`: −1 to trace; a `Status` code to return that status at once
      (used for endpoint checks made under `jit`).

    **Returns:** a `Path`.
    """
    frame = _frame(mesh)
    ctx = _context(mesh, frame, normals, options)
    ends = _ends(ctx, start, end)
    state = _initial_state(ctx, start, ends, initial_status)
    final = jax.lax.while_loop(
        lambda s: s.status < 0, lambda s: _step(ctx, ends, s), state
    )
    return _finish(mesh, frame, start, end, final)


def trace_batch(
    mesh: Mesh,
    normals: Float[Array, "V 3"],
    start: SurfacePoint,
    end: SurfacePoint,
    options: TraceOptions = TraceOptions(),
    initial_status: Int[Array, " B"] | int = -1,
) -> Path:
    """`trace` for a batch of endpoint pairs (`start`, `end` with a leading batch
    axis): the same paths as `jax.vmap(trace)`, faster.

    `jax.vmap` of a `while_loop` whose condition differs between lanes selects
    every carried array between its old and new value at every step: with the path
    buffers (`max_points` slots) that copy cost more than the step itself. Here one
    loop runs a vmapped step until all lanes are done; a finished lane's step is a
    no-op, and a buffer write touches one slot per lane.
    """
    initial = jnp.broadcast_to(
        jnp.asarray(initial_status, jnp.int32), jnp.shape(start.face)
    )
    frame = _frame(mesh)
    ctx = _context(mesh, frame, normals, options)
    ends = jax.vmap(lambda s, e: _ends(ctx, s, e))(start, end)
    state = jax.vmap(lambda s, e, i: _initial_state(ctx, s, e, i))(start, ends, initial)
    step = jax.vmap(lambda e, st: _step(ctx, e, st))
    state = jax.lax.while_loop(
        lambda st: jnp.any(st.status < 0), lambda st: step(ends, st), state
    )
    return jax.vmap(lambda s, e, st: _finish(mesh, frame, s, e, st))(start, end, state)
