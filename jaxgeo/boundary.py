"""Boundary loops of an open mesh and points on them by arc length.

A loop is an ordered cycle of boundary vertices, running the way the faces are
oriented (the mesh interior on the left when the normals point at the viewer).
`loop_point(mesh, loop, s)` is the point at normalised arc length `s` (period 1)
as a `SurfacePoint` in the boundary face of the edge it falls on; it is
differentiable in `s` (and in `mesh.vertices`), so a seam end can slide along
the boundary under `jax.grad`.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._errors import JaxgeoError
from .locate import SurfacePoint
from .mesh import Mesh

__all__ = [
    "BoundaryLoop",
    "PackedLoops",
    "boundary_loops",
    "loop_parameter",
    "loop_point",
    "pack_loops",
    "packed_point",
]


class BoundaryLoop(eqx.Module):
    """One boundary loop: `n` vertices and the `n` edges between them.

    - `vertices`: `(n,)` vertex indices in loop order; edge `i` joins
      `vertices[i]` to `vertices[(i + 1) % n]`.
    - `faces`: `(n,)` the boundary face of edge `i`.
    - `corners`: `(n, 2)` the corners (0, 1, 2) of `faces[i]` holding the edge's
      start and end vertex.
    """

    vertices: Int[Array, " n"]
    faces: Int[Array, " n"]
    corners: Int[Array, "n 2"]

    @property
    def size(self) -> int:
        return int(self.vertices.shape[0])

    def cumulative(self, mesh: Mesh) -> Float[Array, " n_plus_1"]:
        """Arc length at each loop vertex, from 0 to the perimeter (closing vertex
        included)."""
        p = mesh.vertices[self.vertices]
        seg = jnp.linalg.norm(jnp.roll(p, -1, axis=0) - p, axis=1)
        return jnp.concatenate([jnp.zeros((1,), p.dtype), jnp.cumsum(seg)])

    def length(self, mesh: Mesh) -> Float[Array, ""]:
        return self.cumulative(mesh)[-1]

    def polyline(self, mesh: Mesh) -> np.ndarray:
        """The loop's points `(n + 1, 3)`, closed (first point repeated)."""
        v = np.asarray(mesh.vertices)[np.asarray(self.vertices)]
        return np.concatenate([v, v[:1]])


def boundary_loops(mesh: Mesh) -> list[BoundaryLoop]:
    """The boundary loops of `mesh`, longest (by perimeter) first.

    Each loop runs along the face orientation: for a boundary face (a, b, c) with
    boundary edge a→b, the loop goes from a to b. It starts at its lowest
    vertex index. Read from the mesh's own record of its boundary
    (`Mesh.boundary_next`, the first face of each boundary vertex's fan). Raises
    `JaxgeoError` for a closed mesh.
    """
    nxt = np.asarray(mesh.boundary_next)
    on = np.flatnonzero(nxt >= 0)
    if on.size == 0:
        raise JaxgeoError("the mesh is closed: it has no boundary loops")
    faces = np.asarray(mesh.faces)
    # the edge v → nxt[v] is the first face of v's (open) fan: corners ca → cb
    face = np.asarray(mesh.fan_faces)[:, 0]
    corner_a = np.argmax(faces[face[on]] == on[:, None], axis=1)
    corner_b = np.argmax(faces[face[on]] == nxt[on][:, None], axis=1)
    corners = np.zeros((nxt.size, 2), np.int64)
    corners[on] = np.stack([corner_a, corner_b], axis=1)
    step = nxt.tolist()
    seen = np.zeros(nxt.size, bool)
    loops: list[BoundaryLoop] = []
    for start in on.tolist():  # ascending: each loop from its lowest vertex
        if seen[start]:
            continue
        vs = [start]
        v = step[start]
        while v != start:
            if v < 0 or seen[v] or len(vs) > on.size:
                raise JaxgeoError("boundary is not a set of simple loops")
            vs.append(v)
            v = step[v]
        seen[vs] = True
        loops.append(
            BoundaryLoop(
                jnp.asarray(vs, jnp.int32),
                jnp.asarray(face[vs], jnp.int32),
                jnp.asarray(corners[vs], jnp.int32),
            )
        )
    loops.sort(key=lambda lp: -float(lp.length(mesh)))
    return loops


class PackedLoops(eqx.Module):
    """Several loops padded into one array each (`L` loops, at most `n` edges),
    so that points on different loops can be taken in one `jax.vmap`.
    Padding repeats each loop's last edge; `sizes` holds the real counts."""

    vertices: Int[Array, "L n"]
    faces: Int[Array, "L n"]
    corners: Int[Array, "L n 2"]
    sizes: Int[Array, " L"]


def pack_loops(loops: list[BoundaryLoop]) -> PackedLoops:
    """Pad `loops` into a `PackedLoops`."""
    n = max(lp.size for lp in loops)

    def pad(x):
        x = np.asarray(x)
        return np.concatenate([x, np.repeat(x[-1:], n - len(x), axis=0)])

    return PackedLoops(
        jnp.asarray(np.stack([pad(lp.vertices) for lp in loops]), jnp.int32),
        jnp.asarray(np.stack([pad(lp.faces) for lp in loops]), jnp.int32),
        jnp.asarray(np.stack([pad(lp.corners) for lp in loops]), jnp.int32),
        jnp.asarray([lp.size for lp in loops], jnp.int32),
    )


def packed_point(
    mesh: Mesh, packed: PackedLoops, which: ArrayLike, s: ArrayLike, inset: float = 0.0
) -> SurfacePoint:
    """`loop_point` on loop number `which` of `packed` (`which` may be traced, so
    this vmaps over seams whose ends lie on different loops)."""
    n = jnp.asarray(packed.sizes)[which]
    verts = packed.vertices[which]
    p = mesh.vertices[verts]
    idx = jnp.arange(verts.shape[0])
    nxt = mesh.vertices[verts[jnp.where(idx + 1 < n, idx + 1, 0)]]
    seg = jnp.where(idx < n, jnp.linalg.norm(nxt - p, axis=1), 0.0)
    cum = jnp.concatenate([jnp.zeros((1,), p.dtype), jnp.cumsum(seg)])
    t = jnp.mod(jnp.asarray(s, cum.dtype), 1.0) * cum[-1]
    i = jnp.clip(
        jnp.searchsorted(jax.lax.stop_gradient(cum), jax.lax.stop_gradient(t)) - 1,
        0,
        n - 1,
    )
    u = (t - cum[i]) / jnp.where(seg[i] > 0, seg[i], 1.0)
    ca, cb = packed.corners[which, i, 0], packed.corners[which, i, 1]
    eye = jnp.eye(3, dtype=cum.dtype)
    bary = (1.0 - u) * eye[ca] + u * eye[cb]
    bary = (1.0 - inset) * bary + inset * eye[3 - ca - cb]
    return SurfacePoint(packed.faces[which, i], bary)


def loop_point(
    mesh: Mesh, loop: BoundaryLoop, s: ArrayLike, inset: float = 0.0
) -> SurfacePoint:
    """The point of `loop` at normalised arc length `s` (period 1, measured from
    `loop.vertices[0]` along the loop) as a `SurfacePoint`.

    **Arguments:**

    - `s`: scalar; differentiable (the barycentric coordinates are linear in `s`
      on each edge; the edge index is piecewise constant).
    - `inset`: move the point this fraction of the way towards the face's third
      corner (0 = on the boundary edge). A tiny inset (1e-6) keeps the laser ray
      from starting exactly on the boundary, where its chord projection can leave
      the mesh (status NO_CROSSING).

    **Returns:** `SurfacePoint(face, bary)`.
    """
    cum = loop.cumulative(mesh)
    total = cum[-1]
    t = jnp.mod(jnp.asarray(s, cum.dtype), 1.0) * total
    i = jnp.clip(
        jnp.searchsorted(jax.lax.stop_gradient(cum), jax.lax.stop_gradient(t)) - 1,
        0,
        loop.size - 1,
    )
    u = (t - cum[i]) / (cum[i + 1] - cum[i])
    ca, cb = loop.corners[i, 0], loop.corners[i, 1]
    cc = 3 - ca - cb
    eye = jnp.eye(3, dtype=cum.dtype)
    bary = (1.0 - u) * eye[ca] + u * eye[cb]
    bary = (1.0 - inset) * bary + inset * eye[cc]
    return SurfacePoint(loop.faces[i], bary)


def loop_parameter(
    mesh: Mesh, loop: BoundaryLoop, point: ArrayLike | Sequence[float]
) -> float:
    """The normalised arc length `s` of the loop point nearest to a 3-D `point`
    (numpy; for building layouts from coordinates)."""
    p = np.asarray(point, float)
    poly = loop.polyline(mesh)
    a, b = poly[:-1], poly[1:]
    d = b - a
    u = np.clip(np.einsum("ij,ij->i", p - a, d) / np.einsum("ij,ij->i", d, d), 0, 1)
    q = a + u[:, None] * d
    i = int(np.argmin(np.linalg.norm(q - p, axis=1)))
    cum = np.asarray(loop.cumulative(mesh))
    return float((cum[i] + u[i] * (cum[i + 1] - cum[i])) / cum[-1])
