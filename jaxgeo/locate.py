"""Points on the surface: `SurfacePoint` (face, barycentric) and `locate`, the
nearest point of the mesh to a 3-D point."""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .mesh import Mesh

#: Default largest distance from the surface, in mean edge lengths, at which a 3-D
#: point is still taken as a point of the surface. A point sampled from the smooth
#: surface a coarse mesh approximates is off by the sagitta, about h²/(8R), far
#: below this for any mesh that resolves its surface (h ≪ R).
DEFAULT_MAX_DISTANCE = 0.5

#: Kinds of mesh element, as `snap` and `SurfacePoint.element` answer (and as
#: `Path.kinds` holds them, kind 0 there being an endpoint).
FACE, EDGE, VERTEX = 0, 1, 2


class SurfacePoint(eqx.Module):
    """A point of the mesh: a face and barycentric coordinates in it.

    `bary[i]` weighs corner `i` of the face. A point on an edge has one zero
    coordinate (`bary[i] = 0` ⇒ edge `mesh.face_edges[face, i]`), a vertex two:
    `SurfacePoint.vertex(mesh, i)` and `SurfacePoint.on_edge(mesh, e, t)` make
    them, and `element` reads a point back as the element it lies on (vertex,
    edge + parameter or face, as geometry-central's tagged `SurfacePoint`).
    Differentiable in
    `bary` (e.g. to slide an endpoint along a boundary edge). A `Path` keeps its
    endpoints as these (`Path.start`, `Path.end`).
    """

    # (any array-like, as given; batched alike, with leading axes B: in a batch of
    # paths and inside `shortest_path`'s solver)
    face: Int[ArrayLike, "*B"]
    bary: Float[ArrayLike, "*B 3"] | Sequence[float]

    def position(self, mesh: Mesh) -> Float[Array, "*B 3"]:
        """The 3-D point (one per point of a batch)."""
        corners = mesh.vertices[mesh.faces[jnp.asarray(self.face)]]
        return jnp.einsum("...i,...ij->...j", jnp.asarray(self.bary), corners)

    @classmethod
    def vertex(cls, mesh: Mesh, i: Int[ArrayLike, ""]) -> SurfacePoint:
        """Mesh vertex `i` as a point of the first face around it, barycentric
        coordinates one at its corner and zero at the other two (how
        `shortest_path` reads an integer endpoint). Works on a traced `i`; an
        index that is out of range or of a vertex in no face gives face 0 with
        NaN coordinates (`vertex_valid` tells; `shortest_path` checks concrete
        indices and raises `JaxgeoError`)."""
        return cls(*_vertex_point(mesh, jnp.asarray(i)))

    @classmethod
    def on_edge(
        cls, mesh: Mesh, e: Int[ArrayLike, ""], t: Float[ArrayLike, ""]
    ) -> SurfacePoint:
        """The point `(1 − t)·V[edges[e, 0]] + t·V[edges[e, 1]]` of edge `e`
        (`t` as `Path.params` of an edge crossing), as a point of the first face
        beside the edge: barycentric coordinates `1 − t` and `t` at the edge's
        corners, zero at the third. Works on a traced `e`; differentiable in
        `t`. An edge index out of range (or of a padded edge, which no face
        holds) gives face 0 with NaN coordinates, as `vertex` does."""
        return cls(*_edge_point(mesh, jnp.asarray(e), jnp.asarray(t)))

    def element(
        self, mesh: Mesh, tol: float = 0.0
    ) -> tuple[Int[Array, "*B"], Int[Array, "*B"], Float[Array, "*B"]]:
        """The element the point lies on, `(kind, index, t)`: kind `VERTEX` (index
        a vertex), `EDGE` (index an edge, `t` the parameter along it in
        `mesh.edges` orientation, as `on_edge` takes it) or `FACE` (index the
        face); `t` is 0 but on an edge. Barycentric coordinates `<= tol` count as
        zero (`snap`); an edge point's `t` is then its coordinates' share
        `b_1 / (b_0 + b_1)` at the edge's two ends. The inverse of `vertex` and
        `on_edge` (`t` exactly, for `t` in [0, 1]; at 0 or 1 the point is the
        vertex). Batched alike (leading axes B); works under `jax.jit` and
        `jax.vmap`; differentiable in `t` through `bary`."""
        kind, index = snap(mesh, self, tol)
        face, bary = jnp.asarray(self.face), jnp.asarray(self.bary)
        on_edge = kind == EDGE
        ends = mesh.edges[jnp.where(on_edge, index, 0)]
        corners = mesh.faces[face]
        b0 = jnp.sum(jnp.where(corners == ends[..., :1], bary, 0), axis=-1)
        b1 = jnp.sum(jnp.where(corners == ends[..., 1:], bary, 0), axis=-1)
        t = jnp.where(on_edge, b1 / jnp.where(on_edge, b0 + b1, 1), 0)
        return kind, index, t


# `SurfacePoint.vertex` and `.on_edge`, compiled: run eagerly (a concrete vertex
# index given to `shortest_path`, a notebook), their dozen small operations cost
# ~4 ms on the CPU, compiled 0.1 ms (inside a traced caller they are inlined).
@eqx.filter_jit
def _vertex_point(mesh: Mesh, i):
    ok = vertex_valid(mesh, i)
    face = jnp.where(ok, mesh.vertex_faces[jnp.where(ok, i, 0), 0], 0)
    corner = jnp.argmax(mesh.faces[face] == i)
    bary = jax.nn.one_hot(corner, 3, dtype=mesh.vertices.dtype)
    return face.astype(jnp.int32), jnp.where(ok, bary, jnp.nan)


@eqx.filter_jit
def _edge_point(mesh: Mesh, e, t):
    inside = (e >= 0) & (e < mesh.edges.shape[0])
    face = mesh.edge_faces[jnp.where(inside, e, 0), 0]
    ok = inside & (face >= 0)
    face = jnp.where(ok, face, 0)
    a, b = mesh.edges[jnp.where(ok, e, 0), 0], mesh.edges[jnp.where(ok, e, 0), 1]
    corners = mesh.faces[face]
    t = t.astype(mesh.vertices.dtype)
    bary = (1 - t) * (corners == a) + t * (corners == b)
    return face.astype(jnp.int32), jnp.where(ok, bary, jnp.nan)


def vertex_valid(mesh: Mesh, i: Int[ArrayLike, "*B"]) -> Bool[Array, "*B"]:
    """Whether `i` indexes a vertex of `mesh` that belongs to a face (a vertex no
    face references has no point of the surface)."""
    i = jnp.asarray(i)
    inside = (i >= 0) & (i < mesh.n_vertices)
    return inside & (mesh.vertex_faces[jnp.where(inside, i, 0), 0] >= 0)


def _closest_on_triangle(p, a, b, c):
    """Closest point of triangle abc to p, as barycentric coordinates (Ericson,
    Real-Time Collision Detection, 5.1.5), branch-free for vmap."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = jnp.dot(ab, ap), jnp.dot(ac, ap)
    bp = p - b
    d3, d4 = jnp.dot(ab, bp), jnp.dot(ac, bp)
    cp = p - c
    d5, d6 = jnp.dot(ab, cp), jnp.dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2

    def div(x, y):
        return x / jnp.where(y == 0, 1.0, y)

    one = jnp.ones_like(d1)
    zero = jnp.zeros_like(d1)
    # Interior.
    denom = va + vb + vc
    v_in, w_in = div(vb, denom), div(vc, denom)
    bary = jnp.stack([1 - v_in - w_in, v_in, w_in])
    # Edge bc.
    w_bc = div(d4 - d3, (d4 - d3) + (d5 - d6))
    bary = jnp.where(
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
        jnp.stack([zero, 1 - w_bc, w_bc]),
        bary,
    )
    # Edge ac.
    w_ac = div(d2, d2 - d6)
    bary = jnp.where(
        (vb <= 0) & (d2 >= 0) & (d6 <= 0), jnp.stack([1 - w_ac, zero, w_ac]), bary
    )
    # Edge ab.
    v_ab = div(d1, d1 - d3)
    bary = jnp.where(
        (vc <= 0) & (d1 >= 0) & (d3 <= 0), jnp.stack([1 - v_ab, v_ab, zero]), bary
    )
    # Vertices.
    bary = jnp.where((d6 >= 0) & (d5 <= d6), jnp.stack([zero, zero, one]), bary)
    bary = jnp.where((d3 >= 0) & (d4 <= d3), jnp.stack([zero, one, zero]), bary)
    bary = jnp.where((d1 <= 0) & (d2 <= 0), jnp.stack([one, zero, zero]), bary)
    return jnp.clip(bary, 0.0, 1.0)


#: Only faces whose bounding sphere reaches within the distance of a first guess
#: can be nearest; on a mesh that resolves its surface those are a vertex ring or
#: two (≤ 10 faces on the benchmark catenoid). The exact nearest point is computed
#: on the blocks of `_BLOCK_FACES` consecutive faces that hold them, at most
#: `_BLOCKS` blocks (blocks, not single faces: selecting a few of F faces costs a
#: scan of F, of F/32 blocks a scan of F/32).
_BLOCK_FACES = 32
_BLOCKS = 16


def _nearest_of(point, tri, faces, real=None):
    """The nearest of the triangles `tri[faces]`: `(face, bary, squared distance)`,
    ties to the lowest face id (as a brute-force argmin over all faces). Faces
    not `real` (a size class's padding; `(F,)` mask, default all) are infinitely
    far."""
    t = tri[faces]
    bary = jax.vmap(_closest_on_triangle, in_axes=(None, 0, 0, 0))(
        point, t[:, 0], t[:, 1], t[:, 2]
    )
    bary = bary / jnp.sum(bary, axis=1, keepdims=True)
    closest = jnp.einsum("fi,fij->fj", bary, t)
    dist2 = jnp.sum((closest - point) ** 2, axis=1)
    # A NaN distance (a NaN vertex, e.g. from `Mesh.with_vertices`, or a NaN point)
    # must never win the argmin (jnp.argmin returns the first NaN): it counts as
    # infinitely far, so a NaN point is FAR_FROM_SURFACE, not a point of face 0.
    padding = jnp.zeros(faces.shape, bool) if real is None else ~real[faces]
    dist2 = jnp.where(jnp.isnan(dist2) | padding, jnp.inf, dist2)
    tied = dist2 == jnp.min(dist2)
    k = jnp.argmin(jnp.where(tied, faces, jnp.iinfo(faces.dtype).max))
    return faces[k], bary[k], dist2[k]


def locate(
    mesh: Mesh, point: Float[Array, "3"]
) -> tuple[SurfacePoint, Float[Array, ""]]:
    """The nearest point of the mesh to `point` and its distance.

    Exact (the nearest distance a brute force over all faces finds; among faces
    tied to rounding, the lowest id) and jit- and vmap-friendly. Each face has a
    bounding sphere (centroid, radius r). The face of the nearest centroid gives a
    first distance d; a face whose centroid is farther than d + r cannot be
    nearer, so the exact nearest point is computed only on the faces within reach
    (when they span more than `_BLOCKS` blocks, e.g. for a point far from the surface,
    on all faces). Padded faces (`face_component` −1, see `Mesh.padded`) are
    never chosen: the mask is data, so meshes of one size class share the
    compiled search. Returns `(SurfacePoint, distance)`; the caller decides
    whether the distance is too far (see `shortest_path`).
    """
    tri = mesh.vertices[mesh.faces]  # (F, 3, 3)
    real = mesh.face_component >= 0
    face = _nearest_face(jax.lax.stop_gradient(point), jax.lax.stop_gradient(tri), real)
    # The search is a discrete choice; the answer is differentiable in the point
    # and the vertices through the nearest point of the chosen face.
    _, bary, dist2 = _nearest_of(point, tri, face[None], real)
    return SurfacePoint(face, bary), jnp.sqrt(dist2)


def _nearest_face(point, tri, real) -> Int[Array, ""]:
    n = tri.shape[0]
    all_faces = jnp.arange(n, dtype=jnp.int32)
    if n <= _BLOCK_FACES * _BLOCKS:
        return _nearest_of(point, tri, all_faces, real)[0]
    centre = jnp.mean(tri, axis=1)
    radius = jnp.max(jnp.linalg.norm(tri - centre[:, None], axis=-1), axis=1)
    # |p − c|² expanded: under vmap the p·c term is one matrix product. Its
    # rounding, ≤ a few eps·(|p|² + |c|²), is covered by `slack`.
    cc = jnp.sum(centre * centre, axis=1)
    pp = jnp.dot(point, point)
    d2c = jnp.maximum(pp - 2 * (centre @ point) + cc, 0.0)
    d2c = jnp.where(jnp.isnan(d2c) | ~real, jnp.inf, d2c)
    first = jnp.argmin(d2c).astype(jnp.int32)
    _, _, d2_first = _nearest_of(point, tri, first[None], real)
    reach = jnp.sqrt(d2_first) + radius
    slack = 64 * jnp.finfo(tri.dtype).eps * (pp + cc + reach * reach)
    near = d2c <= reach * reach + slack
    n_blocks = -(-n // _BLOCK_FACES)
    near = jnp.pad(near, (0, n_blocks * _BLOCK_FACES - n))
    near_blocks = jnp.any(near.reshape(n_blocks, _BLOCK_FACES), axis=1)
    (blocks,) = jnp.nonzero(near_blocks, size=_BLOCKS, fill_value=0)
    cand = blocks[:, None] * _BLOCK_FACES + jnp.arange(_BLOCK_FACES)
    cand = jnp.minimum(cand.reshape(-1), n - 1).astype(jnp.int32)
    face, _, dist2 = _nearest_of(point, tri, cand, real)
    pruned = jnp.sum(near_blocks) <= _BLOCKS
    return _search_blocks(point, tri, real, pruned, face, dist2)


#: Faces per step of the full search (bounds its temporaries on large meshes).
_SEARCH_BLOCK = 4096


def _search_blocks(point, tri, real, done, face, dist2):
    """Where not `done`, the nearest face over all faces, a block at a time.

    A while loop over blocks, not `lax.cond`: under vmap a cond runs both branches
    for every lane, and a loop-invariant full search inside a loop is hoisted out
    of it by XLA (and run unconditionally). Indexing by the loop counter keeps the
    work inside, so it costs nothing when every lane is `done`."""
    n = tri.shape[0]
    n_blocks = -(-n // _SEARCH_BLOCK)
    block = jnp.arange(min(_SEARCH_BLOCK, n), dtype=face.dtype)

    def body(state):
        i, face, dist2 = state
        ids = jnp.minimum(i * block.shape[0] + block, n - 1)
        f, _, d2 = _nearest_of(point, tri, ids, real)
        better = (d2 < dist2) | ((d2 == dist2) & (f < face))
        return i + 1, jnp.where(better, f, face), jnp.where(better, d2, dist2)

    start = jnp.where(done, n_blocks, 0)
    dist2 = jnp.where(done, dist2, jnp.inf)
    _, face, _ = jax.lax.while_loop(
        lambda state: state[0] < n_blocks, body, (start, face, dist2)
    )
    return face


def snap(
    mesh: Mesh, sp: SurfacePoint, tol: float
) -> tuple[Int[Array, "*B"], Int[Array, "*B"]]:
    """The mesh element a surface point lies on, as `(kind, index)`: kind `FACE`
    (0), `EDGE` (1) or `VERTEX` (2). Barycentric coordinates below `tol` count as
    zero. Batched alike (leading axes B); `SurfacePoint.element` adds the edge
    parameter."""
    bary, face = jnp.asarray(sp.bary), jnp.asarray(sp.face)
    small = bary <= tol
    n_small = jnp.sum(small, axis=-1)
    corner = jnp.argmax(bary, axis=-1)
    edge_corner = jnp.argmax(small, axis=-1)
    kind = jnp.where(n_small >= 2, VERTEX, jnp.where(n_small == 1, EDGE, FACE))
    index = jnp.where(
        kind == VERTEX,
        mesh.faces[face, corner],
        jnp.where(kind == EDGE, mesh.face_edges[face, edge_corner], face),
    )
    return kind.astype(jnp.int32), index.astype(jnp.int32)
