"""Geodesics on the smooth surface the Phong normals define.

The surface is the Phong tessellation of the mesh with shape factor α (default ½,
see `jaxgeo._phong`). A path is given by a strip: a sequence of nodes, the start
point, then crossings of mesh edges (or contacts with mesh vertices), then the end
point. Consecutive nodes share a face; between them the path is the straight
segment in that face's barycentric coordinates, lifted by the Phong map Φ. A
crossing of edge e = (a, b) at parameter u lies at Φ((1 − u)·a + u·b), on the
lifted edge curve, which both faces of e share, so the path is continuous.

The vertex normals are eq. (8)–(9) (or another weighting) at interior vertices.
At boundary vertices the fan is one-sided and eq. (8)–(9) is O(h) off, which
tilts the Phong surface along the boundary by O(h²), no better than the flat
mesh; there they are replaced by the normal of a local quadratic fit, O(h²)
(`phong_normals`, `jaxgeo.normals.fit_boundary_normals`). On the catenoid suite,
whose pairs mostly end on the rings, this takes the median error at level 4 from
1.2e-6 to 3.1e-7.

The length L(u) = Σ_s ∫₀¹ |dΦ_s/dt| dt (Gauss–Legendre per segment) is minimised
over the crossing parameters u ∈ [0, 1]ⁿ. Segment s depends on u_s and u_{s+1}
only, so the Hessian is tridiagonal; the minimiser is a projected, damped
(Levenberg–Marquardt) Newton method: (H + λ·I)·δ = −g on the free variables, a
step is accepted when it shortens the path (or, within rounding of L, lowers the
gradient), λ shrinks on success and grows on failure. Parameters at a bound whose
gradient pushes outwards are held there (the path touches that vertex). Iterations
continue until the projected gradient is below `gtol`·(mean edge length), about
1e-12 by default.

Strip repair (`smooth_shortest_path`, eager): a crossing pulled onto an end of its
edge means the path touches a vertex; runs of such crossings become one vertex
node, and the path is released to either side of the vertex's fan (all contacts
together, or one at a time), started on the unfolded straight line; the shortest
result wins, until nothing changes. `smooth_path` is the same repair as
fixed-shape JAX (jit, vmap, grad; no host callback): the candidate strips of a
round (as it is, all contacts to side 0, all to side 1, each of the first
`max_single` contacts alone to either side) are solved in parallel under `vmap`
in a `lax.while_loop` over rounds (`jaxgeo._smooth_repair` builds them).

Differentiation. At the solution L is stationary in the free u (and the bounds do
not depend on the mesh), so by the envelope theorem dL/dθ = ∂L/∂θ at fixed u* for
every input θ (vertices, normals through the vertices, endpoints). The solver runs
on `stop_gradient` inputs and the optimal u* is `stop_gradient`-ed; the length is
then re-evaluated from the live inputs. The crossing points' derivatives are
likewise partial derivatives at fixed u* (not the total derivative of the
crossings).

This module is the entry points and their results; the strip and its length are
`jaxgeo._smooth_strip`, the Newton solver `jaxgeo._smooth_newton`, the eager
repair's host-side unfolding `jaxgeo._smooth_unfold`, the normals
`jaxgeo.normals.phong_normals` (re-exported here).
"""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._phong import phong_point
from ._smooth_newton import minimise
from ._smooth_strip import build_strip, lengths
from ._smooth_unfold import fan_arcs, unfolded_crossings, vertex_fan
from .locate import SurfacePoint
from .mesh import Mesh
from .normals import Weighting, phong_normals
from .path import EDGE, FACE, VERTEX

__all__ = [
    "SmoothPath",
    "phong_normals",
    "phong_point",
    "SmoothResult",
    "smooth_geodesic",
    "smooth_path",
    "smooth_shortest_path",
]


class SmoothPath(eqx.Module):
    """A geodesic of the Phong surface on a fixed strip.

    Buffers have a fixed capacity `M` (nodes, endpoints included); the first
    `count` are the path, the rest repeat the end point.

    - `points`: `(M, 3)` the nodes on the smooth surface.
    - `kinds`: `(M,)` 0 endpoint, 1 edge crossing, 2 vertex (as in `Path`).
    - `elements`: `(M,)` face (endpoints), edge or vertex index.
    - `params`: `(M,)` u on the edge for crossings,
      flat point (1 − u)·V[edges[e, 0]] + u·V[edges[e, 1]].
    - `faces`: `(M − 1,)` the face each segment runs in.
    - `count`, `length`.
    - `converged`: the projected gradient reached `gtol`.
    - `grad_norm`: max-norm of the projected gradient dL/du at the end, leaving
      out crossings whose Newton step is below the rounding of u.
    - `hit_vertex`: some crossing sits at an end of its edge with the gradient
      pushing outwards: the smooth geodesic wants to leave the strip there (see
      `smooth_shortest_path(..., repair=True)`), or it really wraps the vertex.
    - `valid_strip`: every pair of consecutive nodes shares a face.
    - `iterations`: Newton iterations taken.
    """

    points: Float[Array, "M 3"]
    kinds: Int[Array, " M"]
    elements: Int[Array, " M"]
    params: Float[Array, " M"]
    faces: Int[Array, " M-1"]
    count: Int[Array, ""]
    length: Float[Array, ""]
    converged: Bool[Array, ""]
    grad_norm: Float[Array, ""]
    hit_vertex: Bool[Array, ""]
    valid_strip: Bool[Array, ""]
    iterations: Int[Array, ""]


# ----------------------------------------------------------------------- entry point

#: An endpoint this close (in barycentric coordinates) to an edge or vertex lies
#: in every face round it when the strip's faces are chosen.
_SNAP_TOL = 1e-12


def smooth_geodesic(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    elements: Int[ArrayLike, " n"],
    params: Float[ArrayLike, " n"],
    kinds: Int[ArrayLike, " n"] | None = None,
    *,
    count: Int[ArrayLike, ""] | None = None,
    alpha: float = 0.5,
    normals: Weighting | Float[Array, "V 3"] = "uniform",
    boundary: Literal["fit", "keep"] = "fit",
    n_quad: int = 4,
    gtol: float = 1e-12,
    max_steps: int = 200,
) -> SmoothPath:
    """The geodesic of the Phong surface through a fixed strip of edges.

    **Arguments:**

    - `mesh`, `start`, `end`: the mesh and the endpoints (`SurfacePoint`s).
    - `elements`: `(n,)` the crossed edges in order (or vertices, see `kinds`);
      for instance `Path.elements[1 : count - 1]` of a laser or exact path.
    - `params`: `(n,)` initial parameters u on those edges (ignored for vertices).
    - `kinds`: `(n,)` 1 = edge crossing (default), 2 = a vertex the path passes
      through (held fixed: the vertex lies on the smooth surface).
    - `count`: the number of live entries of `elements` (default all); the rest
      is padding, so one compiled shape serves paths of different lengths.
    - `alpha`: Phong shape factor; ½ is the consistent one (see `jaxgeo._phong`).
    - `normals`: a vertex-normal weighting (`"uniform"`: eq. 8–9) or a `(V, 3)`
      array of unit normals.
    - `n_quad`: Gauss–Legendre points per segment.
    - `gtol`: stop when max |dL/du| on the free crossings ≤ gtol·mean edge length.
    - `max_steps`: Newton iterations allowed.

    **Returns:** a `SmoothPath`. Its `length` and `points` are differentiable in
    `mesh.vertices` (normals included), `start.bary` and `end.bary`: by the envelope
    theorem the gradient of the length is its partial derivative at the optimal,
    `stop_gradient`-ed parameters u* (exact, since L is stationary in u* and the
    bounds 0 ≤ u ≤ 1 do not depend on the inputs). Polishing to `gtol` makes this
    gradient accurate to about gtol².
    """
    dtype = mesh.vertices.dtype
    elements = jnp.asarray(elements, jnp.int32).reshape(-1)
    params = jnp.asarray(params, dtype).reshape(-1)
    n = elements.shape[0]
    kinds = (
        jnp.full(n, EDGE, jnp.int32)
        if kinds is None
        else jnp.asarray(kinds, jnp.int32).reshape(-1)
    )
    count = jnp.asarray(n if count is None else count, jnp.int32)
    nrm = phong_normals(mesh, normals, boundary)
    zero_i = jnp.zeros(1, jnp.int32)
    node_kinds = jnp.concatenate([zero_i, kinds, zero_i])
    node_elems = jnp.concatenate([zero_i, elements, zero_i])
    u0 = jnp.concatenate([jnp.zeros(1, dtype), jnp.clip(params, 0, 1), jnp.zeros(1)])
    n_nodes = count + 2
    u0 = jnp.where(jnp.arange(n + 2) < n_nodes - 1, u0, 0.0)
    return _solve(
        mesh, nrm, start, end, node_kinds, node_elems, u0, n_nodes,
        alpha, n_quad, gtol, max_steps,
    )  # fmt: skip


@eqx.filter_jit
def _solve(
    mesh, nrm, start, end, kinds, elements, u0, count, alpha, n_quad, gtol, max_steps
):
    dtype = mesh.vertices.dtype
    start = SurfacePoint(jnp.asarray(start.face), jnp.asarray(start.bary, dtype))
    end = SurfacePoint(jnp.asarray(end.face), jnp.asarray(end.bary, dtype))
    snap_tol = _SNAP_TOL
    sg = jax.lax.stop_gradient
    strip0 = build_strip(sg(mesh), sg(start), sg(end), kinds, elements, count, snap_tol)
    tol = gtol * sg(mesh.mean_edge_length)
    u, gnorm, hit, it = minimise(
        mesh.faces, strip0, sg(mesh.vertices), sg(nrm), u0, alpha, n_quad, tol,
        max_steps,
    )  # fmt: skip
    u = sg(u)
    # Re-evaluate from the live inputs (envelope theorem).
    strip = build_strip(mesh, start, end, kinds, elements, count, snap_tol)
    lens = lengths(mesh.faces, strip, mesh.vertices, nrm, u, alpha, n_quad)
    b0 = strip.a + u[:-1, None] * strip.b
    b_last = strip.c[-1] + u[-1] * strip.d[-1]
    fv = mesh.faces[strip.face]
    lift = jax.vmap(phong_point, in_axes=(0, 0, 0, None))
    pts = lift(mesh.vertices[fv], nrm[fv], b0, alpha)
    last = phong_point(mesh.vertices[fv[-1]], nrm[fv[-1]], b_last, alpha)
    pts = jnp.concatenate([pts, last[None]])
    idx = jnp.arange(kinds.shape[0])
    pts = jnp.where((idx < count)[:, None], pts, pts[jnp.maximum(count - 1, 0)])
    is_end = (idx == 0) | (idx >= count - 1)
    out_kinds = jnp.where(is_end, FACE, kinds)
    out_elems = jnp.where(
        idx == 0, start.face, jnp.where(idx >= count - 1, end.face, elements)
    )
    return SmoothPath(
        points=pts,
        kinds=out_kinds.astype(jnp.int32),
        elements=out_elems.astype(jnp.int32),
        params=jnp.where(strip.free, u, 0.0),
        faces=strip.face,
        count=count,
        length=jnp.sum(lens),
        converged=gnorm <= tol,
        grad_norm=gnorm,
        hit_vertex=hit,
        valid_strip=strip.valid,
        iterations=jnp.asarray(it, jnp.int32),
    )


# ----------------------------------------------------------------------- strip repair


def _capacity(n: int) -> int:
    """Buffer size for n interior nodes: a power of two (≥ 32), so that paths of
    similar length share one compiled shape."""
    return max(32, 1 << (n - 1).bit_length()) if n > 0 else 32


def smooth_shortest_path(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    elements: Int[ArrayLike, " n"],
    params: Float[ArrayLike, " n"],
    kinds: Int[ArrayLike, " n"] | None = None,
    *,
    repair: bool = True,
    max_rounds: int = 8,
    capacity: int | None = None,
    **options,
) -> SmoothPath:
    """`smooth_geodesic` on a strip, with strip repair at vertex contacts
    (eager: not jit-able, the strip changes).

    After each solve, runs of crossings pulled onto the same vertex become one
    vertex node. For each vertex node the two ways around the vertex (the edges of
    its fan between the faces the path enters and leaves by) are solved as well,
    starting next to the vertex; the shortest of the three is kept (a side whose
    crossings are pulled back onto the vertex ties with it, and the vertex stays).
    Repeats until nothing changes or `max_rounds` is reached. `capacity`: buffer
    size (default: the next power of two ≥ 32; fix it to reuse one compiled
    shape). `options` go to `smooth_geodesic`.
    """
    mesh_np = {
        "faces": np.asarray(mesh.faces),
        "face_edges": np.asarray(mesh.face_edges),
        "fan_faces": np.asarray(mesh.fan_faces),
        "fan_size": np.asarray(mesh.fan_size),
        "fan_closed": np.asarray(mesh.fan_closed),
    }
    edges_np = np.asarray(mesh.edges, np.int64)
    elements = np.asarray(elements, np.int64).reshape(-1)
    params = np.asarray(params, np.float64).reshape(-1)
    kinds = (
        np.full(elements.shape, EDGE)
        if kinds is None
        else np.asarray(kinds, np.int64).reshape(-1)
    )
    nodes = list(zip(kinds.tolist(), elements.tolist(), params.tolist()))
    # one set of normals for every solve of the repair
    options["normals"] = phong_normals(
        mesh, options.get("normals", "uniform"), options.pop("boundary", "fit")
    )
    options["boundary"] = "keep"

    def solve(nodes):
        n = len(nodes)
        cap = _capacity(n) if capacity is None or capacity < n else capacity
        k = np.full(cap, EDGE, np.int32)
        el = np.zeros(cap, np.int32)
        u = np.zeros(cap)
        if n:
            k[:n], el[:n], u[:n] = (np.asarray(c) for c in zip(*nodes))
        return smooth_geodesic(mesh, start, end, el, u, k, count=n, **options)

    def collapse(path: SmoothPath):
        """Nodes of a solved path, runs of crossings at one vertex merged."""
        n = int(path.count) - 2
        out = []
        for j in range(1, n + 1):
            kind, elem = int(path.kinds[j]), int(path.elements[j])
            u = float(path.params[j])
            if kind == EDGE and (u <= 0.0 or u >= 1.0):
                kind, elem = VERTEX, int(edges_np[elem, 0 if u <= 0.0 else 1])
                u = 0.0
            if kind == VERTEX and out and out[-1][:2] == (VERTEX, elem):
                continue
            out.append((kind, elem, u))
        return out

    best = solve(nodes)
    if not repair:
        return best

    verts = np.asarray(mesh.vertices, np.float64)
    ends = (
        np.asarray(start.position(mesh), np.float64),
        np.asarray(end.position(mesh), np.float64),
    )

    def flat(nodes, j):
        """Flat 3-D position of node j (−1: start, len(nodes): end)."""
        if j < 0 or j >= len(nodes):
            return ends[0] if j < 0 else ends[1]
        kind, elem, u = nodes[j]
        if kind == VERTEX:
            return verts[elem]
        a, b = edges_np[elem]
        return (1 - u) * verts[a] + u * verts[b]

    def release(nodes, seg_faces, choice):
        """Replace vertex node j by the edges of arc choice[j] of its fan, started
        where the straight line between its neighbours crosses them in the
        unfolded fan (next to the vertex when it misses that side)."""
        out = []
        for j, node in enumerate(nodes):
            side = choice.get(j)
            f_in, f_out = int(seg_faces[j]), int(seg_faces[j + 1])
            arcs = (
                []
                if side is None
                else fan_arcs(vertex_fan(mesh_np, node[1]), f_in, f_out)
            )
            if side is None or side >= len(arcs) or not arcs[side]:
                out.append(node)
                continue
            v, arc = node[1], arcs[side]
            u0 = unfolded_crossings(
                verts, mesh_np["faces"], edges_np, v, arc, f_in, f_out,
                flat(nodes, j - 1), flat(nodes, j + 1),
            )  # fmt: skip
            out += [(EDGE, e, w) for e, w in zip(arc, u0)]
        return out

    for _ in range(max_rounds):
        nodes = collapse(best)
        kept = solve(nodes)
        seg_faces = np.asarray(kept.faces)
        at = [j for j, node in enumerate(nodes) if node[0] == VERTEX]
        if not at:
            return kept
        # every contact to the same side (a path hugging a row of vertices), then
        # each contact alone to either side; the shortest wins
        choices = [{j: side for j in at} for side in (0, 1)]
        if len(at) > 1:
            choices += [{j: side} for j in at for side in (0, 1)]
        improved, length = None, float(kept.length)
        for choice in choices:
            cand = solve(release(nodes, seg_faces, choice))
            ok = bool(cand.converged) and bool(cand.valid_strip)
            if ok and float(cand.length) < length * (1 - 1e-13):
                improved, length = cand, float(cand.length)
        if improved is None:
            return kept
        best = improved
    return best


# ----------------------------------------------------------------------- JAX-native


def _relax(mesh, nrm, start, end, kinds, elements, u0, count, alpha, n_quad, tol,
           max_steps):  # fmt: skip
    """`minimise` on a strip, nothing differentiated: `(u, length, ok, faces)`,
    ok = converged on a valid strip."""
    strip = build_strip(mesh, start, end, kinds, elements, count, _SNAP_TOL)
    u, gnorm, _, _ = minimise(
        mesh.faces, strip, mesh.vertices, nrm, u0, alpha, n_quad, tol, max_steps
    )
    lens = lengths(mesh.faces, strip, mesh.vertices, nrm, u, alpha, n_quad)
    length = jnp.sum(lens)
    ok = (gnorm <= tol) & strip.valid & jnp.isfinite(length)
    return jnp.where(strip.free, u, 0.0), length, ok, strip.face


class SmoothResult(eqx.Module):
    """`smooth_path`'s result: the `SmoothPath` on the repaired strip, the
    repair rounds that changed the strip, and the vertex contacts released."""

    path: SmoothPath
    rounds: Int[Array, "*B"]  # (leading axes B when batched, as under vmap)
    releases: Int[Array, "*B"]

    @property
    def ok(self) -> Bool[Array, "*B"]:
        """Converged on a valid strip (the pipeline's SUCCESS)."""
        return self.path.converged & self.path.valid_strip


def smooth_path(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    kinds: Int[Array, " M"],
    elements: Int[Array, " M"],
    params: Float[Array, " M"],
    count: Int[Array, ""],
    normals: Weighting | Float[Array, "V 3"] = "uniform",
    *,
    boundary: Literal["fit", "keep"] = "fit",
    alpha: float = 0.5,
    n_quad: int = 4,
    gtol: float = 1e-12,
    max_steps: int = 200,
    max_rounds: int = 8,
    max_single: int = 4,
) -> SmoothResult:
    """The geodesic of the Phong surface started from a polyhedral path's strip,
    with strip repair at vertex contacts; all in JAX (jit, vmap, grad).

    **Arguments:**

    - `mesh`, `start`, `end`: the mesh and the endpoints.
    - `kinds`, `elements`, `params`, `count`: the starting path in `Path`'s format
      (`(M,)` buffers, node 0 the start, node `count − 1` the end), e.g. the exact
      polyhedral geodesic. M is the capacity of every strip of the repair.
    - `normals`, `boundary`, `alpha`, `n_quad`, `gtol`, `max_steps`: as in
      `smooth_geodesic`.
    - `max_rounds`: repair rounds allowed (static).
    - `max_single`: the first this many vertex contacts are also released one at
      a time (static; each costs two candidate strips per round).

    **Repair** (the same rule as `smooth_shortest_path`). After the strip is
    solved, crossings held at an end of their edge become vertex nodes (runs at one
    vertex one node). If there are any, candidate strips are solved in parallel
    (`vmap`): the strip as it is, every contact released to side 0, every contact
    to side 1, and each of the first `max_single` contacts alone to either side (a
    side is the arc of the vertex's fan between the faces the path enters and
    leaves by, `jaxgeo._smooth_repair`). The shortest converged candidate wins if
    it is shorter than the strip as it is by more than rounding (≈ 1e-13
    relative in float64); otherwise, or after `max_rounds`, the repair stops.

    **Returns:** a `SmoothResult`: `path` (a `SmoothPath` of capacity M, its
    `length` and `points` differentiable as in `smooth_geodesic`), `rounds`,
    `releases`, `ok`.
    """
    dtype = mesh.vertices.dtype
    start = SurfacePoint(jnp.asarray(start.face), jnp.asarray(start.bary, dtype))
    end = SurfacePoint(jnp.asarray(end.face), jnp.asarray(end.bary, dtype))
    # arrays, not static Python numbers: a new path must not recompile
    kinds = jnp.asarray(kinds, jnp.int32).reshape(-1)
    elements = jnp.asarray(elements, jnp.int32).reshape(-1)
    params = jnp.asarray(params, dtype).reshape(-1)
    count = jnp.asarray(count, jnp.int32)
    nrm = phong_normals(mesh, normals, boundary)
    return _smooth_path(
        mesh, nrm, start, end, kinds, elements, params, count, alpha, n_quad, gtol,
        max_steps, max_rounds, max_single,
    )  # fmt: skip


@eqx.filter_jit
def _smooth_path(
    mesh, nrm, start, end, kinds, elements, params, count, alpha, n_quad, gtol,
    max_steps, max_rounds, max_single,
):  # fmt: skip
    from . import _smooth_repair as rep

    dtype = mesh.vertices.dtype
    sg = jax.lax.stop_gradient
    m0, s0, e0, n0 = sg(mesh), sg(start), sg(end), sg(nrm)
    m = kinds.shape[0]
    idx = jnp.arange(m)
    u0 = jnp.where(
        (kinds == EDGE) & (idx > 0) & (idx < count - 1),
        jnp.clip(jnp.asarray(params, dtype), 0.0, 1.0),
        0.0,
    )
    tol = gtol * m0.mean_edge_length
    eps = jnp.finfo(dtype).eps
    better = 1.0 - 450 * eps  # 1e-13 in float64, as smooth_shortest_path

    def relax(k, e, u, c):
        return _relax(m0, n0, s0, e0, k, e, u, c, alpha, n_quad, tol, max_steps)

    u, length, _, _ = relax(kinds, elements, u0, count)

    def contacts(state):
        k, e, u, c = rep.collapse(m0, *state[:4])
        return (k, e, u, c), (k == VERTEX) & (idx > 0) & (idx < c - 1)

    def cond(state):
        _, at = contacts(state)
        return ~state[5] & (state[6] < max_rounds) & jnp.any(at)

    def body(state):
        (k, e, u, c), at = contacts(state)
        strip = build_strip(m0, s0, e0, k, e, c, _SNAP_TOL)
        arcs = rep.node_arcs(m0, s0, e0, k, e, u, c, strip.face)
        # the choices: none, all to side 0, all to side 1, then single contacts
        order = jnp.cumsum(at) - 1  # rank of each contact
        rows = [jnp.full(m, -1), jnp.where(at, 0, -1), jnp.where(at, 1, -1)]
        for j in range(max_single):
            for side in (0, 1):
                rows.append(jnp.where(at & (order == j), side, -1))
        sides = jnp.stack(rows).astype(jnp.int32)

        def candidate(side):
            ck, ce, cu, cc, changed = rep.release(k, e, u, c, side, *arcs)
            cu2, clen, cok, _ = relax(ck, ce, cu, cc)
            return (
                ck,
                ce,
                cu2,
                cc,
                clen,
                cok & changed,
                jnp.sum(side >= 0, dtype=jnp.int32),
            )

        ck, ce, cu, cc, clen, cok, cfree = jax.vmap(candidate)(sides)
        cok = cok.at[0].set(True)
        shorter = cok & (clen < clen[0] * better)
        shorter = shorter.at[0].set(False)
        best = jnp.where(
            jnp.any(shorter), jnp.argmin(jnp.where(shorter, clen, jnp.inf)), 0
        )
        stop = best == 0
        new = (ck[best], ce[best], cu[best], cc[best], clen[best])
        return (*new, stop, state[6] + jnp.where(stop, 0, 1),
                state[7] + jnp.where(stop, 0, cfree[best]))  # fmt: skip

    state = (kinds, elements, u, count, length, jnp.bool_(False), jnp.int32(0),
             jnp.int32(0))  # fmt: skip
    k, e, u, c, _, _, rounds, releases = jax.lax.while_loop(cond, body, state)
    k, e, u, c = rep.collapse(m0, k, e, u, c)
    path = _solve(mesh, nrm, start, end, k, e, u, c, alpha, n_quad, gtol, max_steps)
    return SmoothResult(path=path, rounds=rounds, releases=releases)
