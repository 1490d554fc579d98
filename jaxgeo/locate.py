"""Points on the surface: `SurfacePoint` (face, barycentric) and `locate`, the
nearest point of the mesh to a 3-D point."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .mesh import Mesh

#: Default largest distance from the surface, in mean edge lengths, at which a 3-D
#: point is still taken as a point of the surface. A point sampled from the smooth
#: surface a coarse mesh approximates is off by the sagitta, about h²/(8R), far
#: below this for any mesh that resolves its surface (h ≪ R).
DEFAULT_MAX_DISTANCE = 0.5


class SurfacePoint(eqx.Module):
    """A point of the mesh: a face and barycentric coordinates in it.

    `bary[i]` weighs corner `i` of the face. A point on an edge has one zero
    coordinate (`bary[i] = 0` ⇒ edge `mesh.face_edges[face, i]`), a vertex two.
    Differentiable in `bary` (e.g. to slide an endpoint along a boundary edge).
    """

    face: Int[Array, ""]
    bary: Float[Array, "3"]

    def position(self, mesh: Mesh) -> Float[Array, "3"]:
        return self.bary @ mesh.vertices[mesh.faces[self.face]]


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


def locate(
    mesh: Mesh, point: Float[Array, "3"]
) -> tuple[SurfacePoint, Float[Array, ""]]:
    """The nearest point of the mesh to `point` and its distance.

    Brute force over all faces (O(F), jit- and vmap-friendly). Returns
    `(SurfacePoint, distance)`; the caller decides whether the distance is too far
    (see `shortest_path`).
    """
    tri = mesh.vertices[mesh.faces]  # (F, 3, 3)
    bary = jax.vmap(_closest_on_triangle, in_axes=(None, 0, 0, 0))(
        point, tri[:, 0], tri[:, 1], tri[:, 2]
    )
    bary = bary / jnp.sum(bary, axis=1, keepdims=True)
    closest = jnp.einsum("fi,fij->fj", bary, tri)
    dist2 = jnp.sum((closest - point) ** 2, axis=1)
    # A NaN distance (a NaN vertex, e.g. from `Mesh.with_vertices`, or a NaN point)
    # must never win the argmin (jnp.argmin returns the first NaN): it counts as
    # infinitely far, so a NaN point is FAR_FROM_SURFACE, not a point of face 0.
    dist2 = jnp.where(jnp.isnan(dist2), jnp.inf, dist2)
    face = jnp.argmin(dist2)
    return SurfacePoint(face, bary[face]), jnp.sqrt(dist2[face])


def snap(
    mesh: Mesh, sp: SurfacePoint, tol: float
) -> tuple[Int[Array, ""], Int[Array, ""]]:
    """The mesh element a surface point lies on, as `(kind, index)`: kind 0 a face,
    1 an edge, 2 a vertex. Barycentric coordinates below `tol` count as zero."""
    small = sp.bary <= tol
    n_small = jnp.sum(small)
    corner = jnp.argmax(sp.bary)
    edge_corner = jnp.argmax(small)
    kind = jnp.where(n_small >= 2, 2, jnp.where(n_small == 1, 1, 0))
    index = jnp.where(
        kind == 2,
        mesh.faces[sp.face, corner],
        jnp.where(kind == 1, mesh.face_edges[sp.face, edge_corner], sp.face),
    )
    return kind.astype(jnp.int32), index.astype(jnp.int32)
