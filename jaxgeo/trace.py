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
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._errors import JaxgeoError
from ._numerics import eps_of, safe_normalize
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


def _lane(
    mesh: Mesh,
    normals: Float[Array, "V 3"],
    start: SurfacePoint,
    end: SurfacePoint,
    options: TraceOptions,
    initial_status: Int[Array, ""] | int,
):
    """One path's trace as `(initial state, step)`; `step` is a no-op once the
    state's status is set (so a batch can step finished lanes with the others)."""
    dtype = mesh.vertices.dtype
    m = options.max_points
    tol = param_tolerance(dtype)
    # A crossing is ahead when its chord parameter t exceeds the rounding error of
    # t after the Newton polish (a few eps): 1e-9 in float64 (as param_tolerance),
    # 8 eps ≈ 1e-6 in float32. Not param_tolerance in float32 (1e-4): near a vertex
    # with a fan of edges the next crossing can be 1e-4 of the chord away, and
    # float32 traces stopped there with NO_CROSSING (found by the float32 runs of
    # docs/accuracy.md on the twin-peak tent).
    t_ahead = tol if dtype == jnp.float64 else 8 * eps_of(dtype)
    verts, edges = mesh.vertices, mesh.edges
    p1, p2 = start.position(mesh), end.position(mesh)
    kind1, idx1 = snap(mesh, start, tol)
    idx1 = idx1.astype(jnp.int32)
    kind2, idx2 = snap(mesh, end, tol)
    target = star_faces(mesh, kind2, idx2)
    # A branch: a second valid crossing ahead, farther than this from the chosen
    # one (well above the solver's noise, well below any edge length).
    branch_gap = 1e-6 * mesh.mean_edge_length
    slide_margin = 1e3 * eps_of(dtype)

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
            cand, live = all_edges, jnp.ones(all_edges.shape, bool)
        # Never step back onto the previous point's edge or through its vertex: on
        # a surface of revolution a chord through the axis has normal projections
        # on both sides, and a path bounced between two ring edges forever.
        behind = touches(cand, prev_kind, prev_idx)
        return cand, live & ~touches(cand, kind, idx) & ~behind

    def boundary_slide(pos, kind, idx, star, came_from):
        """The boundary vertex to slide to when no crossing lies ahead: among the
        ends of the boundary edges through the current point (its vertex's two; its
        edge; a start face's), the one whose direction from the current point is
        closest to the chord's, if that direction is ahead (positive cosine) and
        the vertex is not the one the path just came from. Returns
        `(possible, vertex)`."""
        se = mesh.face_edges[jnp.maximum(star, 0)].reshape(-1)
        ends = edges[se]  # (3S, 2)
        through = jnp.where(
            kind == VERTEX,
            jnp.any(ends == idx, axis=1),
            jnp.where(kind == EDGE, se == idx, True),
        )
        usable = jnp.repeat(star >= 0, 3) & (mesh.edge_faces[se, 1] < 0) & through
        w = ends.reshape(-1)
        usable = jnp.repeat(usable, 2) & (w != came_from)
        usable = usable & ~((kind == VERTEX) & (w == idx))
        step_dir = safe_normalize(verts[w] - pos)
        cosine = step_dir @ safe_normalize(p2 - pos)
        # "Ahead" with a margin well above rounding of the unit vectors.
        usable = usable & (cosine > slide_margin)
        best = jnp.argmax(jnp.where(usable, cosine, -jnp.inf))
        return jnp.any(usable), w[best].astype(jnp.int32)

    def step(state):
        (pos, kind, idx, came_from, prev_kind, prev_idx, count, status) = state[:8]
        (pts, kinds, elems, params, branch) = state[8:]
        running = status < 0
        star = star_faces(mesh, kind, idx)
        reached = jnp.any((star[:, None] == target[None, :]) & (star[:, None] >= 0))
        cand, live = candidates(kind, idx, star, prev_kind, prev_idx)
        e0, e1 = edges[cand, 0], edges[cand, 1]
        cr = solve_edges(
            pos,
            p2,
            verts[e0],
            verts[e1],
            normals[e0],
            normals[e1],
            max_steps=options.newton_steps,
        )
        ok = cr.valid & (cr.t > t_ahead) & live[:, None]
        dist = jnp.linalg.norm(cr.point - pos, axis=-1)
        dist = jnp.where(ok, dist, jnp.inf)
        best = jnp.argmin(dist)
        c, r = best // 2, best % 2
        crossed = jnp.any(ok)
        u = cr.u[c, r]
        point = cr.point[c, r]
        # No crossing ahead on the boundary: slide along a boundary edge instead.
        slide, slide_to = boundary_slide(pos, kind, idx, star, came_from)
        follow = ~crossed & slide
        found = crossed | slide
        # Branch point (section 6): the face(s) ahead hold a second crossing.
        elsewhere = jnp.linalg.norm(cr.point - point, axis=-1) > branch_gap
        n_ahead = jnp.sum(ok & elsewhere & in_star(cand, star)[:, None])
        # Snap to a vertex when the crossing is at an end of its edge.
        new_kind = jnp.where((u <= tol) | (u >= 1 - tol), VERTEX, EDGE)
        vertex = jnp.where(u <= tol, e0[c], e1[c])
        new_idx = jnp.where(new_kind == VERTEX, vertex, cand[c]).astype(jnp.int32)
        new_kind = new_kind.astype(jnp.int32)
        new_kind = jnp.where(follow, VERTEX, new_kind).astype(jnp.int32)
        vertex = jnp.where(follow, slide_to, vertex)
        new_idx = jnp.where(follow, slide_to, new_idx).astype(jnp.int32)
        point = jnp.where(new_kind == VERTEX, verts[vertex], point)
        u = jnp.where(new_kind == VERTEX, 0.0, u)
        n_ahead = jnp.where(follow, 0, n_ahead)

        full = count >= m - 1  # keep one slot for point 2
        new_status = jnp.where(
            ~running,
            status,
            jnp.where(
                reached,
                Status.SUCCESS,
                jnp.where(
                    ~found, Status.NO_CROSSING, jnp.where(full, Status.MAX_STEPS, -1)
                ),
            ),
        ).astype(jnp.int32)
        append = running & (reached | (found & ~full))
        out_point = jnp.where(reached, p2, point)
        out_kind = jnp.where(reached, FACE, new_kind).astype(jnp.int32)
        out_elem = jnp.where(reached, end.face.astype(jnp.int32), new_idx).astype(
            jnp.int32
        )
        out_param = jnp.where(reached, 0.0, u)
        slot = jnp.where(append, count, m - 1)
        keep = lambda buf, val: buf.at[slot].set(jnp.where(append, val, buf[slot]))  # noqa: E731
        pts = keep(pts, out_point)
        kinds = keep(kinds, out_kind)
        elems = keep(elems, out_elem)
        params = keep(params, out_param)
        branch = keep(branch, (~reached) & (count > 1) & (n_ahead > 0))
        moving = running & ~reached & found & ~full
        return (
            jnp.where(moving, point, pos),
            jnp.where(moving, new_kind, kind),
            jnp.where(moving, new_idx, idx),
            # the vertex the path leaves (a slide may not return to it at once)
            jnp.where(moving, jnp.where(kind == VERTEX, idx, -1), came_from),
            jnp.where(moving, kind, prev_kind),
            jnp.where(moving, idx, prev_idx),
            count + append.astype(jnp.int32),
            new_status,
            pts,
            kinds,
            elems,
            params,
            branch,
        )

    pts = jnp.zeros((m, 3), dtype).at[0].set(p1)
    kinds = jnp.zeros(m, jnp.int32)  # the endpoints are FACE points
    elems = jnp.zeros(m, jnp.int32).at[0].set(start.face.astype(jnp.int32))
    params = jnp.zeros(m, dtype)
    branch = jnp.zeros(m, bool)
    state = (
        p1,
        kind1,
        idx1,
        jnp.asarray(-1, jnp.int32),
        jnp.asarray(FACE, jnp.int32),  # no previous point: a face touches no edge
        jnp.asarray(-1, jnp.int32),
        jnp.asarray(1, jnp.int32),
        jnp.asarray(initial_status, jnp.int32),
        pts,
        kinds,
        elems,
        params,
        branch,
    )
    return state, step


def _finish(state) -> Path:
    count, status, pts, kinds, elems, params, branch = state[6:]
    pts = pad_tail(pts, count)
    return Path(
        points=pts,
        kinds=kinds,
        elements=elems,
        params=params,
        branch=branch,
        count=count,
        length=polyline_length(pts, count),
        status=status,
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
    state, step = _lane(mesh, normals, start, end, options, initial_status)
    return _finish(jax.lax.while_loop(lambda s: s[7] < 0, step, state))


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
    initial = jnp.broadcast_to(jnp.asarray(initial_status, jnp.int32), start.face.shape)

    def lanes(s, e, i):
        return _lane(mesh, normals, s, e, options, i)

    state = jax.vmap(lambda s, e, i: lanes(s, e, i)[0])(start, end, initial)

    def body(state):
        return jax.vmap(lambda s, e, i, st: lanes(s, e, i)[1](st))(
            start, end, initial, state
        )

    state = jax.lax.while_loop(lambda st: jnp.any(st[7] < 0), body, state)
    return jax.vmap(_finish)(state)
