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


class _State(NamedTuple):
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


def _lane(
    mesh: Mesh,
    frame: _Frame,
    normals: Float[Array, "V 3"],
    start: SurfacePoint,
    end: SurfacePoint,
    options: TraceOptions,
    initial_status: Int[Array, ""] | int,
):
    """One path's trace as `(initial state, step)`; `step` is a no-op once the
    state's status is set (so a batch can step finished lanes with the others).
    `frame = _frame(mesh)`: the trace runs in the mesh's centred, scaled frame."""
    dtype = mesh.vertices.dtype
    m = options.max_points
    budget = _STEP_BUDGET * m
    tol = param_tolerance(dtype)
    # A crossing is ahead when its chord parameter t exceeds the rounding error of
    # t after the Newton polish (a few eps): 1e-9 in float64 (as param_tolerance),
    # 8 eps ≈ 1e-6 in float32. Not param_tolerance in float32 (1e-4): near a vertex
    # with a fan of edges the next crossing can be 1e-4 of the chord away, and
    # float32 traces stopped there with NO_CROSSING (found by the float32 runs of
    # docs/accuracy.md on the twin-peak tent).
    t_ahead = tol if dtype == jnp.float64 else 8 * eps_of(dtype)
    centre, scale, verts = frame
    edges, faces = mesh.edges, mesh.faces
    p1 = (start.position(mesh) - centre) / scale
    p2 = (end.position(mesh) - centre) / scale
    kind1, idx1 = snap(mesh, start, tol)
    idx1 = idx1.astype(jnp.int32)
    kind2, idx2 = snap(mesh, end, tol)
    target = star_faces(mesh, kind2, idx2)
    # A branch: a second valid crossing ahead, farther than this from the chosen
    # one (well above the solver's noise, well below any edge length).
    branch_gap = 1e-6 * mesh.mean_edge_length / scale
    # Cosines and angles (dimensionless) closer than this to a threshold count as
    # on it: far above the rounding of unit vectors and of a fan's angle sum.
    slack = 1e3 * eps_of(dtype)
    fan_width = mesh.vertex_faces.shape[1]
    boundary_edge = mesh.edge_faces[:, 1] < 0
    is_boundary_vertex = mesh.is_boundary_vertex

    if options.candidates == "all":
        all_edges = jnp.arange(mesh.n_edges, dtype=edges.dtype)

    def in_star(cand, star):
        if options.candidates == "local":
            return jnp.ones(cand.shape, bool)
        star_edges = jnp.where(star[:, None] >= 0, mesh.face_edges[star], -1)
        return jnp.any(cand[:, None] == star_edges.reshape(1, -1), axis=1)

    def touches(cand, kind, idx):
        """Candidate edges that are the element (kind, idx) or pass through it."""
        return jnp.where(
            kind == EDGE,
            cand == idx,
            (kind == VERTEX) & jnp.any(edges[cand] == idx, axis=1),
        )

    def candidates(kind, idx, star, prev_kind, prev_idx):
        if options.candidates == "local":
            cand, live = local_candidates(mesh, kind, idx, star)
        else:
            # padded edges of a size class have no face (`Mesh.padded`)
            cand, live = all_edges, mesh.edge_faces[:, 0] >= 0
        # Never step back onto the previous point's edge or through its vertex: on
        # a surface of revolution a chord through the axis has normal projections
        # on both sides, and a path bounced between two ring edges forever.
        behind = touches(cand, prev_kind, prev_idx)
        return cand, live & ~touches(cand, kind, idx) & ~behind

    def boundary_slide(pos, aim_pos, kind, idx, star, slide_dir, prev_vertex):
        """The boundary vertex to slide to when no crossing lies ahead: among the
        ends of the boundary edges through the current point (its vertex's two; its
        edge; a start face's), not the previous point. A slide that continues
        (`slide_dir` ≠ 0) keeps its way round the boundary loop (+1 along the
        faces' orientation, −1 against it) whatever the direction in space (a rim
        round a hole turns away from point 2); a new slide takes the end whose
        direction is closest to the chord's, if it is not behind (cosine ≥
        −slack). Returns `(possible, vertex, edge, way)`."""
        se = mesh.face_edges[jnp.maximum(star, 0)].reshape(-1)
        ends = edges[se]  # (3S, 2)
        through = jnp.where(
            kind == VERTEX,
            jnp.any(ends == idx, axis=1),
            jnp.where(kind == EDGE, se == idx, True),
        )
        usable = jnp.repeat(star >= 0, 3) & (mesh.edge_faces[se, 1] < 0) & through
        # The head of each boundary edge in its face's orientation.
        corners = faces[mesh.edge_faces[se, 0]]  # (3S, 3)
        ia = jnp.argmax(corners == ends[:, :1], axis=1)
        ib = jnp.argmax(corners == ends[:, 1:], axis=1)
        head = jnp.where((ib - ia) % 3 == 1, ends[:, 1], ends[:, 0])
        w = ends.reshape(-1)
        way = jnp.where(w == jnp.repeat(head, 2), 1, -1)
        usable = jnp.repeat(usable, 2) & (w != prev_vertex)
        usable = usable & ~((kind == VERTEX) & (w == idx))
        step_dir = safe_normalize(verts[w] - pos)
        cosine = step_dir @ safe_normalize(aim_pos - pos)
        usable = usable & jnp.where(slide_dir != 0, way == slide_dir, cosine > -slack)
        best = jnp.argmax(jnp.where(usable, cosine, -jnp.inf))
        return (
            jnp.any(usable),
            w[best].astype(jnp.int32),
            se[best // 2],
            way[best].astype(jnp.int32),
        )

    def contains(face, kind, idx):
        """Whether the point (kind, idx) lies on the closure of `face`."""
        return jnp.where(
            kind == FACE,
            face == idx,
            jnp.where(
                kind == EDGE,
                jnp.any(mesh.face_edges[face] == idx),
                jnp.any(faces[face] == idx),
            ),
        )

    def mesh_angle(v, out_edge, out_vertex, q, q_kind, q_idx):
        """The surface's angle at boundary vertex `v` from the boundary edge to
        `out_vertex` round to the direction of the path's previous point `q`: the
        corner angles of the faces of the fan between them (walked from the
        boundary edge's face), plus the part of `q`'s face up to `q`. At least π
        means `v` is a vertex the path wraps (a geodesic may bend there); below π
        the path can be shortened by cutting across the faces."""
        pv = verts[v]

        def angle(a, b):
            return jnp.arctan2(safe_norm(jnp.cross(a, b)), jnp.dot(a, b))

        def body(_, carry):
            face, x, total, done = carry
            live = (face >= 0) & ~done
            f = jnp.maximum(face, 0)
            corners = faces[f]
            y = (jnp.sum(corners) - v - x).astype(x.dtype)  # the third corner
            here = live & contains(f, q_kind, q_idx)
            part = jnp.where(here, angle(verts[x] - pv, q - pv), 0.0)
            whole = jnp.where(live & ~here, angle(verts[x] - pv, verts[y] - pv), 0.0)
            across = mesh.face_edges[f, jnp.argmax(corners == x)]  # edge (v, y)
            pair = mesh.edge_faces[across]
            nxt = jnp.where(pair[0] == f, pair[1], pair[0])
            return nxt.astype(face.dtype), y, total + part + whole, done | here

        first = mesh.edge_faces[out_edge, 0]
        init = (
            first,
            out_vertex.astype(jnp.int32),
            jnp.zeros((), dtype),
            jnp.asarray(False),
        )
        _, _, total, done = jax.lax.fori_loop(0, fan_width, body, init)
        return jnp.where(done, total, 0.0)

    def step(s: _State) -> _State:
        running = s.status < 0
        star = star_faces(mesh, s.kind, s.idx)
        aiming = s.aim >= 0
        aim_pos = jnp.where(aiming, verts[jnp.maximum(s.aim, 0)], p2)
        aim_star = jnp.where(
            aiming, star_faces(mesh, jnp.asarray(VERTEX), jnp.maximum(s.aim, 0)), target
        )
        reached = jnp.any((star[:, None] == aim_star[None, :]) & (star[:, None] >= 0))
        done = reached & ~aiming  # point 2 reached
        cand, live = candidates(s.kind, s.idx, star, s.prev_kind, s.prev_idx)
        e0, e1 = edges[cand, 0], edges[cand, 1]
        cr = solve_edges(
            s.pos,
            aim_pos,
            verts[e0],
            verts[e1],
            normals[e0],
            normals[e1],
            max_steps=options.newton_steps,
        )
        ok = cr.valid & (cr.t > t_ahead) & live[:, None]
        dist = jnp.where(ok, jnp.linalg.norm(cr.point - s.pos, axis=-1), jnp.inf)
        best = jnp.argmin(dist)
        c, r = best // 2, best % 2
        crossed = jnp.any(ok)
        # "all" candidates: the nearest crossing ahead of all edges must lie on a
        # face of the current point, or the polyline would leave the surface (the
        # projection jumped across a gap or a fold): then the trace stops.
        jumped = crossed & ~in_star(cand[c][None], star)[0]
        u = cr.u[c, r]
        crossing = cr.point[c, r]
        # Branch point (section 6): the face(s) ahead hold a second crossing.
        elsewhere = jnp.linalg.norm(cr.point - crossing, axis=-1) > branch_gap
        n_ahead = jnp.sum(ok & elsewhere & in_star(cand, star)[:, None])
        # Snap to a vertex when the crossing is at an end of its edge.
        at_end = (u <= tol) | (u >= 1 - tol)
        cross_kind = jnp.where(at_end, VERTEX, EDGE)
        cross_idx = jnp.where(at_end, jnp.where(u <= tol, e0[c], e1[c]), cand[c])

        # No crossing ahead on the boundary: slide along a boundary edge instead.
        prev_vertex = jnp.where(s.prev_kind == VERTEX, s.prev_idx, -1)
        can_slide, slide_to, slide_edge, slide_way = boundary_slide(
            s.pos, aim_pos, s.kind, s.idx, star, s.slide_dir, prev_vertex
        )
        stuck = ~reached & ~crossed
        slide = stuck & ~aiming & can_slide
        # Where a new slide starts: the current vertex, or the far end of the
        # current boundary edge; arriving there again means a full turn of the rim.
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
        q_kind = jnp.where(s.count - 2 == 0, kind1, s.kinds[q_slot])
        q_idx = jnp.where(s.count - 2 == 0, idx1, s.elems[q_slot])
        bend = mesh_angle(
            jnp.maximum(s.idx, 0), slide_edge, slide_to, s.pts[q_slot], q_kind, q_idx
        )
        at_anchor = s.anchor == s.count - 1
        wraps = (s.kind == VERTEX) & (bend >= jnp.pi - slack)
        taut = slide & ~at_anchor & ~wraps & (slide_to != s.no_taut)
        direct = slide & ~taut
        # Aiming at a vertex and blocked (the rim in between): give the aim up, make
        # the current point the anchor and aim at point 2 again (the slide keeps its
        # way round the rim); the next
        # slide to that vertex goes straight along the rim (no second taut aim).
        give_up = stuck & aiming

        full = s.count >= m - 1  # keep one slot for point 2
        failed = jumped | (stuck & ~aiming & ~slide)
        out_of_steps = s.steps + 1 >= budget
        append = running & (done | (~full & ~failed & (reached | crossed | direct)))
        new_status = jnp.where(
            done,
            Status.SUCCESS,
            jnp.where(
                failed,
                Status.NO_CROSSING,
                jnp.where(full | out_of_steps, Status.MAX_STEPS, -1),
            ),
        )
        new_status = jnp.where(running, new_status, s.status).astype(jnp.int32)
        moving = running & append & ~done

        # The appended point: point 2, the aimed vertex, a crossing or a slide.
        to_vertex = reached | direct
        new_kind = jnp.where(to_vertex, VERTEX, cross_kind).astype(jnp.int32)
        new_idx = jnp.where(
            reached, s.aim, jnp.where(direct, slide_to, cross_idx)
        ).astype(jnp.int32)
        point = jnp.where(new_kind == VERTEX, verts[new_idx], crossing)
        u = jnp.where(new_kind == VERTEX, 0.0, u)
        out_point = jnp.where(done, p2, point)
        out_kind = jnp.where(done, FACE, new_kind).astype(jnp.int32)
        out_elem = jnp.where(done, jnp.asarray(end.face).astype(jnp.int32), new_idx)
        out_param = jnp.where(done, 0.0, u)
        slot = jnp.where(append, s.count, m - 1)

        def keep(buf, val):
            return buf.at[slot].set(jnp.where(append, val, buf[slot]))

        branch_here = crossed & ~reached & (s.count > 1) & (n_ahead > 0)

        # Pulling taut: the loop resumes from the anchor with the slide as its aim.
        back = running & taut & ~full
        a = s.anchor
        a_kind = jnp.where(a == 0, kind1, s.kinds[a])
        a_idx = jnp.where(a == 0, idx1, s.elems[a])
        b_kind = jnp.where(a <= 1, jnp.where(a == 0, FACE, kind1), s.kinds[a - 1])
        b_idx = jnp.where(a <= 1, jnp.where(a == 0, -1, idx1), s.elems[a - 1])

        def pick(new_moving, new_back, old):
            return jnp.where(moving, new_moving, jnp.where(back, new_back, old))

        sliding = direct | taut
        # A slide ends where the laser ray goes on into the mesh: a crossing toward
        # point 2 on an interior edge or vertex (one on the boundary, across a
        # notch of the rim, continues the slide).
        on_boundary = jnp.where(
            cross_kind == EDGE,
            boundary_edge[cross_idx],
            is_boundary_vertex[cross_idx],
        )
        new_dir = jnp.where(sliding, slide_way, s.slide_dir)
        new_dir = jnp.where(crossed & ~aiming & ~on_boundary, 0, new_dir)
        new_origin = jnp.where(sliding, origin, s.slide_origin)
        upd = running & (moving | back | give_up)
        new_anchor = jnp.where(
            direct & wraps, s.count - 1, jnp.where(give_up, s.count - 1, s.anchor)
        )
        new_aim = jnp.where(reached | give_up, -1, jnp.where(taut, slide_to, s.aim))
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
            no_taut=jnp.where(running & give_up, s.aim, s.no_taut).astype(jnp.int32),
            pts=keep(s.pts, out_point),
            kinds=keep(s.kinds, out_kind),
            elems=keep(s.elems, out_elem),
            params=keep(s.params, out_param),
            branch=keep(s.branch, branch_here),
            aims=keep(s.aims, jnp.where(done, -1, s.aim)),
        )

    minus1 = jnp.asarray(-1, jnp.int32)
    state = _State(
        pos=p1,
        kind=kind1,
        idx=idx1,
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
    return state, step


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
    state, step = _lane(mesh, frame, normals, start, end, options, initial_status)
    final = jax.lax.while_loop(lambda s: s.status < 0, step, state)
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

    def lanes(s, e, i):
        return _lane(mesh, frame, normals, s, e, options, i)

    state = jax.vmap(lambda s, e, i: lanes(s, e, i)[0])(start, end, initial)

    def body(state):
        return jax.vmap(lambda s, e, i, st: lanes(s, e, i)[1](st))(
            start, end, initial, state
        )

    state = jax.lax.while_loop(lambda st: jnp.any(st.status < 0), body, state)
    return jax.vmap(lambda s, e, st: _finish(mesh, frame, s, e, st))(start, end, state)
