"""Phong vertex normals (eq. 8–9) and their linear interpolation along an edge
(eq. 10)."""

from __future__ import annotations

from typing import Literal

import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ._errors import JaxgeoError
from ._numerics import safe_norm, safe_normalize

Weighting = Literal["uniform", "area", "angle"]


def _check_mesh_arrays(vertices, faces) -> None:
    """Shape and dtype checks on static information only, so they run at trace
    time and cost nothing under `jax.jit`."""
    if jnp.ndim(vertices) != 2 or jnp.shape(vertices)[1] != 3:
        raise JaxgeoError(f"vertices must have shape (V, 3), got {jnp.shape(vertices)}")
    if not jnp.issubdtype(jnp.result_type(vertices), jnp.floating):
        raise JaxgeoError(
            f"vertices must be floating point, got dtype {jnp.result_type(vertices)}"
        )
    if jnp.ndim(faces) != 2 or jnp.shape(faces)[1] != 3:
        raise JaxgeoError(f"faces must have shape (F, 3), got {jnp.shape(faces)}")
    if not jnp.issubdtype(jnp.result_type(faces), jnp.integer):
        raise JaxgeoError(
            f"faces must be an integer array, got dtype {jnp.result_type(faces)}"
        )


def face_normals(
    vertices: Float[Array, "V 3"], faces: Int[Array, "F 3"], *, unit: bool = True
) -> Float[Array, "F 3"]:
    """Normals of the faces, `(b − a) × (c − a)`; unit length unless `unit=False`
    (then their length is twice the face area)."""
    _check_mesh_arrays(vertices, faces)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    n = jnp.cross(b - a, c - a)
    return safe_normalize(n) if unit else n


def _corner_angles(vertices: Float[Array, "V 3"], faces: Int[Array, "F 3"]):
    p = vertices[faces]  # (F, 3, 3)
    e1 = safe_normalize(jnp.roll(p, -1, axis=1) - p)
    e2 = safe_normalize(jnp.roll(p, 1, axis=1) - p)
    cos = jnp.clip(jnp.sum(e1 * e2, -1), -1.0, 1.0)
    sin = safe_norm(jnp.cross(e1, e2))  # finite gradient even at sin = 0
    return jnp.arctan2(sin, cos)  # (F, 3)


def vertex_normals(
    vertices: Float[Array, "V 3"],
    faces: Int[Array, "F 3"],
    weighting: Weighting = "uniform",
) -> Float[Array, "V 3"]:
    """Phong vertex normals.

    `"uniform"` is the paper's eq. (8)–(9): the sum of the unit normals of the faces
    at a vertex, normalised. `"area"` weights each face normal by the face area,
    `"angle"` by the face's corner angle at the vertex. Differentiable in
    `vertices` (a vertex in no face gets the zero vector, with a finite gradient).

    Accuracy: every weighting is O(h) accurate on a general mesh (the first-order
    errors of the face normals cancel only in point-symmetric fans, where it is
    O(h²)); see `tests/test_normals.py` for measured constants.

    **Raises** `JaxgeoError` for an unknown `weighting`, or arrays of the wrong
    shape or dtype (integer coordinates would make the normals integers).
    """
    _check_mesh_arrays(vertices, faces)
    if weighting == "uniform":
        w = jnp.broadcast_to(
            face_normals(vertices, faces)[:, None, :], (*faces.shape, 3)
        )
    elif weighting == "area":
        n = face_normals(vertices, faces, unit=False)
        w = jnp.broadcast_to(n[:, None, :], (*faces.shape, 3))
    elif weighting == "angle":
        n = face_normals(vertices, faces)
        w = n[:, None, :] * _corner_angles(vertices, faces)[..., None]
    else:
        raise JaxgeoError(
            f"unknown normal weighting {weighting!r}; expected 'uniform', 'area' or "
            "'angle'"
        )
    summed = jnp.zeros_like(vertices).at[faces.reshape(-1)].add(w.reshape(-1, 3))
    return safe_normalize(summed)


def edge_normal(
    n1: Float[Array, 3], n2: Float[Array, 3], u: Float[Array, ""]
) -> Float[Array, 3]:
    """Eq. (10): the normal at parameter `u` of an edge, `n1 + u (n2 − n1)`, linearly
    interpolated and, as in the paper, not renormalised."""
    return n1 + u * (n2 - n1)
