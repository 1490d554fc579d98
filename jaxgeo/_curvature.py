"""What the exact method's certificate reads of a mesh (`jaxgeo.exact`,
"Certificate"), computed once per mesh rather than per query: the angle sum
Θ(v) at every vertex, and per connected component whether it has no interior
cone vertex (Θ(v) < 2π), is a disc, or is an annulus with a cut.

Why it matters: a triangle mesh whose interior vertices all have Θ ≥ 2π is
locally CAT(0) (the link condition of a 2-dimensional piecewise Euclidean
complex; boundary points impose none), so its universal cover is CAT(0)
(Cartan–Hadamard; Bridson & Haefliger 1999, II.4.1), where a local geodesic is
the unique geodesic (II.1.4). Every locally shortest path is then the only one
in its homotopy class: the detours, which stay in the class (they flip interior
vertices, whose fans are discs), cannot find another, and two starts of one
class reach the same path. A disc has one class; an annulus one per winding,
which the cut counts (`jaxgeo._cuts`). Anticlastic membranes (saddles, sails,
hypars, tents with a ring) are such meshes.

`Mesh` stores these (`vertex_angle_sums`, `component_cone_free`,
`component_disc`, `component_annulus`): computed per query they were scatters
over the whole mesh, 0.7 ms on a 20k-face mesh (jitted alone) and 5–7 ms of an
adjacent pair's 14–16 ms on a 100k-face catenoid. The functions of the angle
sums take numpy arrays (a concrete mesh: no per-size compile of eager JAX) or
JAX arrays (the vertices traced by `Mesh.with_vertices` under `jax.grad`) alike.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np


def cone_tolerance(dtype) -> float:
    """How far below 2π an angle sum must be to make a cone vertex (the exact
    method's tolerance for angles: 10·√ε of the dtype)."""
    return 10 * float(np.finfo(dtype).eps) ** 0.5


def _segment_sum(x, labels, n: int):
    """The sums of `x` over each label < n (negative labels dropped)."""
    if isinstance(x, jax.Array) or isinstance(labels, jax.Array):
        idx = jnp.where(labels >= 0, labels, n)
        return jnp.zeros(n, jnp.asarray(x).dtype).at[idx].add(x, mode="drop")
    ok = labels >= 0
    return np.bincount(labels[ok], x[ok], minlength=n)[:n]


def angle_sums(faces, corner_angles, n_vertices: int):
    """Θ(v): the sum of the face angles at every vertex."""
    return _segment_sum(corner_angles.reshape(-1), faces.reshape(-1), n_vertices)


def vertex_component(face_component, fan_faces, fan_size):
    """The component label of every vertex (−1: in no face)."""
    xp = jnp if isinstance(face_component, jax.Array) else np
    first = face_component[xp.maximum(fan_faces[:, 0], 0)]
    return xp.where(fan_size > 0, first, -1)


def cone_free(face_component, fan_faces, fan_size, fan_closed, theta, tol: float):
    """Per component label (< F): whether no interior vertex is a cone point
    (Θ(v) < 2π − tol, the cones `exact._detours` and `exact._flips` act on)."""
    cone = fan_closed & (fan_size > 0) & (theta < 2 * math.pi - tol)
    labels = vertex_component(face_component, fan_faces, fan_size)
    n = face_component.shape[0]
    return _segment_sum(cone.astype(np.int32), labels, n) == 0


def discs_and_annuli(face_component, vertex_labels, edge_faces, edge_cut):
    """Per component label (< F): whether it is a disc (Euler characteristic
    V − E + F = 1; 2, a sphere, cannot be cone-free) and whether it is an
    annulus with a cut (characteristic 0, cut edges: `jaxgeo._cuts`);
    `vertex_labels`: `vertex_component`'s. Numpy only: the connectivity does
    not change with the vertices."""
    n = face_component.shape[0]
    e_face = edge_faces[:, 0]
    e_comp = np.where(e_face >= 0, face_component[np.maximum(e_face, 0)], -1)

    def count(labels, weight=None):
        w = np.ones(labels.shape[0], np.int32) if weight is None else weight
        return _segment_sum(w, labels, n).astype(np.int32)

    euler = count(vertex_labels) - count(e_comp) + count(face_component)
    cut = count(e_comp, (edge_cut != 0).astype(np.int32))
    return euler == 1, (euler == 0) & (cut > 0)
