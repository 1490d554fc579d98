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
"""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._errors import JaxgeoError
from ._numerics import safe_norm
from ._phong import phong_point, phong_velocity, segment_length
from .locate import SurfacePoint, snap
from .mesh import Mesh
from .normals import Weighting, fit_boundary_normals, vertex_normals
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


# ----------------------------------------------------------------------- the strip


class _Strip(eqx.Module):
    """Per segment s (between nodes s and s+1): its face and the barycentric
    coordinates of its ends in that face, affine in the node parameters,
    b_start = a + u_s·b, b_end = c + u_{s+1}·d."""

    face: Int[Array, " S"]
    a: Float[Array, "S 3"]
    b: Float[Array, "S 3"]
    c: Float[Array, "S 3"]
    d: Float[Array, "S 3"]
    free: Bool[Array, " M"]
    valid: Bool[Array, ""]


def _star(mesh: Mesh, kind, index, width: int):
    """Faces around an edge or vertex, padded with −1 to `width`."""

    def pad(x):
        return jnp.concatenate([x, jnp.full(width - x.shape[0], -1, x.dtype)])

    edge = pad(mesh.edge_faces[index].astype(jnp.int32))
    vertex = pad(mesh.vertex_faces[index].astype(jnp.int32))
    return jnp.where(kind == EDGE, edge, vertex)


def _build_strip(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    kinds: Int[Array, " M"],
    elements: Int[Array, " M"],
    count: Int[Array, ""],
    snap_tol: float,
) -> _Strip:
    m = kinds.shape[0]
    dtype = mesh.vertices.dtype
    idx = jnp.arange(m)
    is_end = idx >= count - 1
    kinds = jnp.where(idx == 0, FACE, jnp.where(is_end, FACE, kinds))
    elements = jnp.where(
        idx == 0, start.face, jnp.where(is_end, end.face, elements)
    ).astype(jnp.int32)
    bary = jnp.where(
        (idx == 0)[:, None], jnp.asarray(start.bary), jnp.asarray(end.bary)
    )
    bary = bary.astype(dtype)

    width = max(mesh.vertex_faces.shape[1], 2)

    def node(kind, elem, bary):
        e = mesh.edges[jnp.clip(elem, 0, mesh.n_edges - 1)]
        fv = mesh.faces[jnp.clip(elem, 0, mesh.n_faces - 1)]
        v = jnp.clip(elem, 0, mesh.n_vertices - 1)
        minus = jnp.asarray(-1, jnp.int32)
        vids = jnp.where(
            kind == EDGE,
            jnp.stack([e[0], e[1], minus]),
            jnp.where(kind == VERTEX, jnp.stack([v, minus, minus]), fv),
        ).astype(jnp.int32)
        one = jnp.asarray([1.0, 0.0, 0.0], dtype)
        base = jnp.where(kind == FACE, bary, one)
        direction = jnp.where(
            kind == EDGE, jnp.asarray([-1.0, 1.0, 0.0], dtype), jnp.zeros(3, dtype)
        )
        # vertices the node's face must contain
        support = jnp.where(kind == FACE, bary > snap_tol, vids >= 0)
        sp = SurfacePoint(jnp.clip(elem, 0, mesh.n_faces - 1), bary)
        s_kind, s_idx = snap(mesh, sp, snap_tol)
        own = jnp.where(kind == FACE, elem, -1).reshape(1).astype(jnp.int32)
        star = jnp.where(
            kind == FACE,
            jnp.where(s_kind == FACE, -1, _star(mesh, s_kind, s_idx, width)),
            _star(mesh, kind, elem, width),
        )
        return vids, base, direction, support, jnp.concatenate([own, star])

    vids, base, direction, support, stars = jax.vmap(node)(kinds, elements, bary)

    def segment(s):
        cand = jnp.concatenate([stars[s], stars[s + 1]])
        fv = mesh.faces[jnp.maximum(cand, 0)]  # (C, 3)

        def contains(n):  # (C,) does the candidate hold node n's support
            hit = jnp.any(vids[n][None, :, None] == fv[:, None, :], axis=2)
            return jnp.all(hit | ~support[n][None, :], axis=1)

        ok = (cand >= 0) & contains(s) & contains(s + 1)
        face = cand[jnp.argmax(ok)]
        corners = mesh.faces[jnp.maximum(face, 0)]

        def match(n):  # (3 corners, 3 slots)
            return (corners[:, None] == vids[n][None, :]).astype(dtype)

        ms, me = match(s), match(s + 1)
        return (
            face,
            ms @ base[s],
            ms @ direction[s],
            me @ base[s + 1],
            me @ direction[s + 1],
            jnp.any(ok),
        )

    face, a, b, c, d, ok = jax.vmap(segment)(jnp.arange(m - 1))
    free = (kinds == EDGE) & (idx < count - 1)
    return _Strip(face, a, b, c, d, free, jnp.all(ok))


# ----------------------------------------------------------------------- the length


def _face_data(faces, strip, vertices, normals):
    fv = faces[strip.face]
    return vertices[fv], normals[fv]


def _lengths(faces, strip, vertices, normals, u, alpha, n_quad):
    """Length of every segment, (S,)."""
    corners, ns = _face_data(faces, strip, vertices, normals)
    b0 = strip.a + u[:-1, None] * strip.b
    b1 = strip.c + u[1:, None] * strip.d
    return jax.vmap(segment_length, in_axes=(0, 0, 0, 0, None, None))(
        corners, ns, b0, b1, alpha, n_quad
    )


def _derivatives(faces, strip, vertices, normals, u, alpha, n_quad):
    """L, its gradient in u, the tridiagonal Hessian (diag, off), and per node the
    one-sided growth rate of its adjacent zero-length segments (their kink)."""
    corners, ns = _face_data(faces, strip, vertices, normals)

    def seg(x, cs, nn, a, b, c, d):
        return segment_length(cs, nn, a + x[0] * b, c + x[1] * d, alpha, n_quad)

    def kink(x, cs, nn, a, b, c, d):
        # a segment whose ends coincide grows like |∂X/∂u| when either end moves
        b0, b1 = a + x[0] * b, c + x[1] * d
        zero = jnp.max(jnp.abs(b1 - b0)) <= 1e-14

        def rate(bb, dd):
            return safe_norm(phong_velocity(cs, nn, bb, dd, alpha))

        return jnp.where(zero, jnp.stack([rate(b0, b), rate(b1, d)]), 0.0)

    x = jnp.stack([u[:-1], u[1:]], axis=1)
    args = (corners, ns, strip.a, strip.b, strip.c, strip.d)

    def all3(x, *args):
        grad = jax.jacfwd(seg)
        return seg(x, *args), grad(x, *args), jax.jacfwd(grad)(x, *args)

    lens, grads, hess = jax.vmap(all3)(x, *args)
    kinks = jax.vmap(kink)(x, *args)

    def nodes(pair):  # (S, 2) per-segment ends → (M,) per node
        zero = jnp.zeros(1, u.dtype)
        return jnp.concatenate([pair[:, 0], zero]) + jnp.concatenate([zero, pair[:, 1]])

    g = nodes(grads)
    diag = nodes(jnp.stack([hess[:, 0, 0], hess[:, 1, 1]], axis=1))
    return jnp.sum(lens), g, diag, hess[:, 0, 1], nodes(kinks)


# ----------------------------------------------------------------------- the solver

#: Parameters this close to 0 or 1 are put on the bound: a crossing pulled onto a
#: vertex converges there quadratically, and the segments between crossings at the
#: same vertex have zero length, where the length has a kink (|x| at 0) that a
#: Newton step cannot resolve. On the bound, the projection holds it.
_SNAP = 1e-10


def _snap(u):
    return jnp.where(u < _SNAP, 0.0, jnp.where(u > 1.0 - _SNAP, 1.0, u))


def _tridiagonal_solve(diag, off, rhs):
    """Thomas algorithm for the symmetric tridiagonal system (diag, off)·x = rhs
    (no pivoting: used on damped, held-row-regularised Newton matrices; a
    breakdown gives non-finite entries, which the caller rejects)."""

    def forward(carry, xs):
        c_prev, d_prev = carry
        a, b, c, r = xs  # sub-diagonal, diagonal, super-diagonal, rhs
        m = b - a * c_prev
        c_new = c / m
        d_new = (r - a * d_prev) / m
        return (c_new, d_new), (c_new, d_new)

    zero = jnp.zeros(1, diag.dtype)
    sub = jnp.concatenate([zero, off])
    sup = jnp.concatenate([off, zero])
    init = (jnp.zeros((), diag.dtype), jnp.zeros((), diag.dtype))
    _, (cp, dp) = jax.lax.scan(forward, init, (sub, diag, sup, rhs))

    def backward(x_next, xs):
        c, d = xs
        x = d - c * x_next
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros((), diag.dtype), (cp, dp), reverse=True)
    return x


def _minimise(faces, strip, vertices, normals, u0, alpha, n_quad, gtol, max_steps):
    """Projected Levenberg–Marquardt Newton on the tridiagonal Hessian.

    Each iteration evaluates L, g, H at a trial point; the trial is accepted when
    it is shorter (or level within rounding and flatter); then the next trial is
    u + δ with (H + λ·|diag H|)·δ = −g on the free rows, clipped to [0, 1]."""
    dtype = u0.dtype
    eps = jnp.finfo(dtype).eps
    free = strip.free

    def projected(u, g, kink):
        # at a bound, held when the one-sided derivative inwards is ≥ 0
        held = ~free | ((u <= 0) & (g + kink >= 0)) | ((u >= 1) & (kink - g >= 0))
        return held, jnp.where(held, 0.0, g)

    def pg_norm(cur):
        u, _, g, diag, _, kink = cur
        pg = projected(u, g, kink)[1]
        # A crossing whose Newton step |g|/H is below the rounding of u cannot
        # move: the rest of its gradient is rounding (a path 1e-8 from a vertex has
        # H ≈ 3e6, and stalled at |g| = 1e-10 on an 82k-face sphere).
        pg = jnp.where(jnp.abs(pg) <= 4 * eps * jnp.abs(diag), 0.0, pg)
        return jnp.max(jnp.abs(pg), initial=0.0)

    def cond(state):
        cur, _, _, it, n_fail = state
        going = (pg_norm(cur) > gtol) & (it < max_steps) & (n_fail < 40)
        return (it == 0) | going

    def body(state):
        cur, trial, lam, it, n_fail = state
        new = (trial, *_derivatives(faces, strip, vertices, normals, trial, alpha,
                                    n_quad))  # fmt: skip
        first = it == 0
        shorter = new[1] < cur[1]
        level = new[1] <= cur[1] + 8 * eps * jnp.abs(cur[1])
        flatter = pg_norm(new) < pg_norm(cur)
        accept = first | (jnp.isfinite(new[1]) & (shorter | (level & flatter)))
        cur = jax.tree.map(lambda a, b: jnp.where(accept, a, b), new, cur)
        lam = jnp.where(
            first, lam, jnp.where(accept, jnp.maximum(lam * 0.25, 1e-12), lam * 8.0)
        )
        u, _, g, diag, off, kink = cur
        held, pg = projected(u, g, kink)
        scale = jnp.maximum(jnp.abs(diag), jnp.finfo(dtype).tiny)
        dd = jnp.where(held, 1.0, diag + lam * scale)
        lo = jnp.where(held[1:] | held[:-1], 0.0, off)
        step = _tridiagonal_solve(dd, lo, -pg)
        step = jnp.where(held | ~jnp.isfinite(step), 0.0, step)
        trial = jnp.where(free, _snap(jnp.clip(u + step, 0.0, 1.0)), u)
        return cur, trial, lam, it + 1, jnp.where(accept, 0, n_fail + 1)

    u0 = jnp.where(free, _snap(u0), u0)
    m = u0.shape[0]
    z = jnp.zeros(m, dtype)
    cur = (u0, jnp.asarray(jnp.inf, dtype), z, z + 1, z[1:], z)
    state = (cur, u0, jnp.asarray(1e-3, dtype), 0, 0)
    cur, _, _, it, _ = jax.lax.while_loop(cond, body, state)
    u = cur[0]
    at_end = free & ((u <= 0) | (u >= 1))
    return u, pg_norm(cur), jnp.any(at_end), it


# ----------------------------------------------------------------------- entry point

#: An endpoint this close (in barycentric coordinates) to an edge or vertex lies
#: in every face round it when the strip's faces are chosen.
_SNAP_TOL = 1e-12


@eqx.filter_jit
def phong_normals(
    mesh: Mesh,
    normals: Weighting | Float[Array, "V 3"] = "uniform",
    boundary: Literal["fit", "keep"] = "fit",
) -> Float[Array, "V 3"]:
    """The unit vertex normals that define the Phong surface (see
    `smooth_geodesic`'s `normals` and `boundary`): a weighting's normals (eq.
    8–9 for `"uniform"`) or the given array, with the boundary vertices' normals
    refitted to second order when `boundary="fit"`."""
    if isinstance(normals, str):
        nrm = vertex_normals(mesh.vertices, mesh.faces, normals)
    else:
        nrm = jnp.asarray(normals, mesh.vertices.dtype)
    if boundary == "fit":
        return fit_boundary_normals(mesh, nrm)
    if boundary != "keep":
        raise JaxgeoError(f"boundary must be 'fit' or 'keep', got {boundary!r}")
    return nrm


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
    strip0 = _build_strip(
        sg(mesh), sg(start), sg(end), kinds, elements, count, snap_tol
    )
    tol = gtol * sg(mesh.mean_edge_length)
    u, gnorm, hit, it = _minimise(
        mesh.faces, strip0, sg(mesh.vertices), sg(nrm), u0, alpha, n_quad, tol,
        max_steps,
    )  # fmt: skip
    u = sg(u)
    # Re-evaluate from the live inputs (envelope theorem).
    strip = _build_strip(mesh, start, end, kinds, elements, count, snap_tol)
    lens = _lengths(mesh.faces, strip, mesh.vertices, nrm, u, alpha, n_quad)
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


def _fan(mesh_np: dict, v: int) -> tuple[list[int], list[int], bool]:
    """Faces around vertex v in order, the edge between consecutive faces
    (`edges[j]` joins `faces[j]` and `faces[j + 1]`, cyclically when closed), and
    whether the fan is closed."""
    faces, edge_faces, key = mesh_np["faces"], mesh_np["edge_faces"], mesh_np["key"]
    n_v = mesh_np["n_vertices"]

    def edge_id(a: int, b: int) -> int:
        a, b = min(a, b), max(a, b)
        return int(np.searchsorted(key, a * n_v + b))

    def step(f: int, forward: bool) -> tuple[int, int]:
        i = int(np.flatnonzero(faces[f] == v)[0])
        w = faces[f, (i + 2) % 3] if forward else faces[f, (i + 1) % 3]
        e = edge_id(v, int(w))
        other = edge_faces[e, 0] if edge_faces[e, 0] != f else edge_faces[e, 1]
        return int(other), e

    start = int(mesh_np["vertex_faces"][v, 0])
    order, between = [start], []
    f = start
    while True:
        nxt, e = step(f, True)
        if nxt == start:
            between.append(e)
            return order, between, True
        if nxt < 0:
            break
        between.append(e)
        order.append(nxt)
        f = nxt
    # open fan: walk backwards from the start to the other boundary edge
    f = start
    while True:
        prv, e = step(f, False)
        if prv < 0:
            return order, between, False
        order.insert(0, prv)
        between.insert(0, e)
        f = prv


def _arcs(fan, f_in: int, f_out: int) -> list[list[int]]:
    """The edge sequences leading around the vertex from face f_in to f_out, one per
    side (one when the fan is open)."""
    order, between, closed = fan
    if f_in not in order or f_out not in order:
        return []
    i, o, m = order.index(f_in), order.index(f_out), len(order)
    if not closed:
        return [between[i:o] if i <= o else between[o:i][::-1]]
    forward = [between[(i + j) % m] for j in range((o - i) % m)]
    backward = [between[(i - 1 - j) % m] for j in range((i - o) % m)]
    return [forward, backward]


#: Rounding tolerance on the unfolded segment's parameter λ ∈ [0, 1].
_UNFOLD_TOL = 1e-9


def _unfolded_crossings(verts, faces, edges, v, arc, f_in, f_out, a, b):
    """Parameters where the segment a → b, unfolded into the plane with the faces
    of the fan of v from f_in across the edges `arc` to f_out, crosses those edges
    (0.02 from v where it misses)."""

    def other(e):
        return int(edges[e, 1] if edges[e, 0] == v else edges[e, 0])

    def corner(f, e1, e2):  # flat angle at v between edges e1, e2 of face f
        d1, d2 = verts[other(e1)] - verts[v], verts[other(e2)] - verts[v]
        return np.arctan2(np.linalg.norm(np.cross(d1, d2)), d1 @ d2)

    def face_edge(f, not_e):  # the edge at v of face f other than not_e
        w = [int(x) for x in faces[f] if x != v and x != other(not_e)][0]
        lo, hi = min(v, w), max(v, w)
        return int(np.flatnonzero((edges[:, 0] == lo) & (edges[:, 1] == hi))[0])

    def place(p, f, e_known, angle_known, sign):
        """2-D image of point p of face f, given edge e_known at angle_known; the
        face's other edge at v lies at angle_known + sign·corner."""
        e_other = face_edge(f, e_known)
        alpha = corner(f, e_known, e_other)
        d1 = verts[other(e_known)] - verts[v]
        d2 = verts[other(e_other)] - verts[v]
        st = np.linalg.lstsq(np.stack([d1, d2], 1), p - verts[v], rcond=None)[0]
        t1, t2 = angle_known, angle_known + sign * alpha
        return st[0] * np.linalg.norm(d1) * np.array([np.cos(t1), np.sin(t1)]) + st[
            1
        ] * np.linalg.norm(d2) * np.array([np.cos(t2), np.sin(t2)])

    angles = [0.0]
    faces_seq = [f_in]
    for k in range(1, len(arc)):
        shared = [
            f
            for f in set(np.flatnonzero((faces == v).any(1)).tolist())
            if set(faces[f].tolist()) >= {v, other(arc[k - 1]), other(arc[k])}
        ]
        faces_seq.append(shared[0])
        angles.append(angles[-1] + corner(shared[0], arc[k - 1], arc[k]))
    a2 = place(a, f_in, arc[0], 0.0, -1.0)
    b2 = place(b, f_out, arc[-1], angles[-1], 1.0)
    out = []
    for e, phi in zip(arc, angles):
        ray = np.array([np.cos(phi), np.sin(phi)])
        m = np.stack([b2 - a2, -ray], 1)
        try:
            lam, mu = np.linalg.solve(m, -a2)
        except np.linalg.LinAlgError:
            lam, mu = -1.0, -1.0
        length = np.linalg.norm(verts[other(e)] - verts[v])
        # closed segment, with rounding: when the next node is the far end of an
        # arc edge (two vertex contacts in a row) the line ends exactly on that
        # edge, at λ = 1 to rounding, and must count as crossing it there
        hit = -_UNFOLD_TOL < lam < 1 + _UNFOLD_TOL and mu > 0
        t = mu / length if hit else 0.02
        t = float(np.clip(t, 1e-3, 1 - 1e-3))
        out.append(t if edges[e, 0] == v else 1 - t)
    return out


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
        "edges": np.asarray(mesh.edges),
        "edge_faces": np.asarray(mesh.edge_faces),
        "vertex_faces": np.asarray(mesh.vertex_faces),
        "n_vertices": mesh.n_vertices,
    }
    edges_np = mesh_np["edges"].astype(np.int64)
    mesh_np["key"] = edges_np[:, 0] * mesh.n_vertices + edges_np[:, 1]
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
            arcs = [] if side is None else _arcs(_fan(mesh_np, node[1]), f_in, f_out)
            if side is None or side >= len(arcs) or not arcs[side]:
                out.append(node)
                continue
            v, arc = node[1], arcs[side]
            u0 = _unfolded_crossings(
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
    """`_minimise` on a strip, nothing differentiated: `(u, length, ok, faces)`,
    ok = converged on a valid strip."""
    strip = _build_strip(mesh, start, end, kinds, elements, count, _SNAP_TOL)
    u, gnorm, _, _ = _minimise(
        mesh.faces, strip, mesh.vertices, nrm, u0, alpha, n_quad, tol, max_steps
    )
    lens = _lengths(mesh.faces, strip, mesh.vertices, nrm, u, alpha, n_quad)
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
        strip = _build_strip(m0, s0, e0, k, e, c, _SNAP_TOL)
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
