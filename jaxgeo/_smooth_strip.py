"""The smooth method's strip and its length (`jaxgeo.smooth`): the faces and
barycentric coordinates of a path's segments, affine in the crossing parameters
u, and the path's length on the Phong surface with its gradient and tridiagonal
Hessian in u. Pure JAX functions of arrays of static shape."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._numerics import safe_norm
from ._phong import phong_velocity, segment_length
from .locate import SurfacePoint, snap
from .mesh import Mesh
from .path import EDGE, FACE, VERTEX


class Strip(eqx.Module):
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


def build_strip(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    kinds: Int[Array, " M"],
    elements: Int[Array, " M"],
    count: Int[Array, ""],
    snap_tol: float,
) -> Strip:
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
    return Strip(face, a, b, c, d, free, jnp.all(ok))


# ----------------------------------------------------------------------- the length


def _face_data(faces, strip, vertices, normals):
    fv = faces[strip.face]
    return vertices[fv], normals[fv]


def lengths(faces, strip, vertices, normals, u, alpha, n_quad):
    """Length of every segment, (S,)."""
    corners, ns = _face_data(faces, strip, vertices, normals)
    b0 = strip.a + u[:-1, None] * strip.b
    b1 = strip.c + u[1:, None] * strip.d
    return jax.vmap(segment_length, in_axes=(0, 0, 0, 0, None, None))(
        corners, ns, b0, b1, alpha, n_quad
    )


def derivatives(faces, strip, vertices, normals, u, alpha, n_quad):
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
