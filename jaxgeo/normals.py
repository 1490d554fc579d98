"""Phong vertex normals (eq. 8–9), a second-order fit for the normals at boundary
vertices, the normals' linear interpolation along an edge (eq. 10), and the
smooth method's choice of them (`phong_normals`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._errors import JaxgeoError
from ._numerics import corner_angles, safe_normalize

if TYPE_CHECKING:
    from .mesh import Mesh

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
    vertices: Float[Array | np.ndarray, "V 3"],
    faces: Int[Array | np.ndarray, "F 3"],
    *,
    unit: bool = True,
) -> Float[Array, "F 3"]:
    """Normals of the faces, `(b − a) × (c − a)`; unit length unless `unit=False`
    (then their length is twice the face area)."""
    _check_mesh_arrays(vertices, faces)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    n = jnp.cross(b - a, c - a)
    return safe_normalize(n) if unit else n


def vertex_normals(
    vertices: Float[Array | np.ndarray, "V 3"],
    faces: Int[Array | np.ndarray, "F 3"],
    weighting: Weighting = "uniform",
) -> Float[Array, "V 3"]:
    """Phong vertex normals.

    `"uniform"` is the paper's eq. (8)–(9): the sum of the unit normals of the faces
    at a vertex, normalised. `"area"` weights each face normal by the face area,
    `"angle"` by the face's corner angle at the vertex. Differentiable in
    `vertices` (a vertex in no face gets the zero vector, with a finite gradient).

    Accuracy: every weighting is O(h) accurate on a general mesh (the first-order
    errors of the face normals cancel only in point-symmetric fans, where it is
    O(h²)); see `tests/test_normals.py` for measured constants. At a boundary
    vertex the fan is one-sided, nothing cancels, and the normal is O(h) off on
    any mesh (0.4·h rad on the catenoid's rings); `fit_boundary_normals` replaces
    those by a second-order fit.

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
        w = n[:, None, :] * corner_angles(vertices, faces)[..., None]
    else:
        raise JaxgeoError(
            f"unknown normal weighting {weighting!r}; expected 'uniform', 'area' or "
            "'angle'"
        )
    summed = jnp.zeros_like(vertices).at[faces.reshape(-1)].add(w.reshape(-1, 3))
    return safe_normalize(summed)


#: Smallest eigenvalue ratio λ_min/λ_max of the (scaled) normal equations for
#: which the boundary fit is trusted (estimated within a factor 25 by
#: 1/(tr(M)·tr(M⁻¹))). Regular boundary stencils measure 1e-3 to 1e-2; a stencil
#: whose points lie near one line or conic in the tangent plane falls far below,
#: and the vertex keeps its given normal.
_FIT_CONDITION = 1e-6


def _fit_stencil(mesh: Mesh, verts: Int[Array, " B"]) -> Int[Array, "B S"]:  # S = 9K²
    """Per vertex v of `verts`, its two-ring: the vertices of the faces that touch
    v's neighbours (v excluded; 11 points at a regular boundary vertex of a
    triangulated grid: three rows, so the quadratic across the boundary is
    determined). Padded with −1, no repeats."""
    n_b = verts.shape[0]
    vf = mesh.vertex_faces
    f1 = vf[verts]  # (B, K) v's faces
    ring1 = jnp.where((f1 >= 0)[..., None], mesh.faces[jnp.maximum(f1, 0)], -1)
    ring1 = ring1.reshape(n_b, -1)  # (B, 3K) v and its neighbours, repeated
    f2 = jnp.where((ring1 >= 0)[..., None], vf[jnp.maximum(ring1, 0)], -1)
    f2 = f2.reshape(n_b, -1)  # (B, 3K²) faces touching them
    ids = jnp.where((f2 >= 0)[..., None], mesh.faces[jnp.maximum(f2, 0)], -1)
    ids = ids.reshape(n_b, -1)  # (B, 9K²)
    ids = jnp.where(ids == verts[:, None], -1, ids)
    ids = jnp.sort(ids, axis=1)
    repeat = jnp.concatenate(
        [jnp.zeros((n_b, 1), bool), ids[:, 1:] == ids[:, :-1]], axis=1
    )
    return jnp.where(repeat, -1, ids)


def _cholesky_solve(m, rhs):
    """Solve m·x = rhs for a small symmetric positive definite m, unrolled (under
    `vmap`, fused elementwise operations); also returns the smallest pivot, ≤ 0
    where m is not positive definite to rounding.

    Not `jnp.linalg`: batched LAPACK calls (eigvalsh, solve) deadlocked on 2 cores
    from 384 boundary vertices (catenoid level 5) when the smooth method still ran
    JAX inside a host callback; unrolled, the fit is also fused elementwise work
    under `vmap`, with no per-lane LAPACK call."""
    n = m.shape[0]
    low = [[None] * n for _ in range(n)]
    pivot = []
    for j in range(n):
        d = m[j, j] - sum(low[j][k] ** 2 for k in range(j))
        pivot.append(d)
        ljj = jnp.sqrt(jnp.where(d > 0, d, 1.0))
        low[j][j] = ljj
        for i in range(j + 1, n):
            low[i][j] = (m[i, j] - sum(low[i][k] * low[j][k] for k in range(j))) / ljj
    y = []
    for i in range(n):
        y.append((rhs[i] - sum(low[i][k] * y[k] for k in range(i))) / low[i][i])
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum(low[k][i] * x[k] for k in range(i + 1, n))) / low[i][i]
    return jnp.stack(x), jnp.min(jnp.stack(pivot))


def _jet_normal(p0, pts, live, n0):
    """Normal at p0 of the least-squares quadratic height function
    z = a·x + b·y + c·x² + d·xy + e·y² through p0, in the frame of n0; and
    whether the fit is well posed."""
    dtype = p0.dtype
    axis = jnp.eye(3, dtype=dtype)[jnp.argmin(jnp.abs(n0))]
    t1 = safe_normalize(jnp.cross(n0, axis))
    t2 = jnp.cross(n0, t1)
    d = pts - p0
    x, y, z = d @ t1, d @ t2, d @ n0
    rho = jnp.max(jnp.where(live, jnp.hypot(x, y), 0.0))
    rho = jnp.where(rho > 0, rho, 1.0)
    xs, ys = x / rho, y / rho  # scaled: the matrix's condition is h-free
    a = jnp.stack([xs, ys, xs * xs, xs * ys, ys * ys], axis=1)
    a = jnp.where(live[:, None], a, 0.0)
    m = a.T @ a
    rhs = jnp.concatenate(
        [(a.T @ jnp.where(live, z / rho, 0.0))[:, None], jnp.eye(5, dtype=dtype)], 1
    )
    sol, pivot = _cholesky_solve(m, rhs)
    # λ_min ≥ 1/tr(m⁻¹) ≥ λ_min/5 and λ_max ≤ tr(m) ≤ 5·λ_max
    inv_trace = jnp.trace(sol[:, 1:])
    ok = (pivot > 0) & (inv_trace * jnp.trace(m) < 1.0 / _FIT_CONDITION)
    ok = jax.lax.stop_gradient(ok & jnp.isfinite(inv_trace))
    coef = jnp.where(ok, sol[:, 0], 0.0)
    # z/ρ = a·xs + b·ys + …  ⇒  ∂z/∂x = a, ∂z/∂y = b
    n = safe_normalize(n0 - coef[0] * t1 - coef[1] * t2)
    return n, ok


@jax.jit
def fit_boundary_normals(
    mesh: Mesh, normals: Float[Array, "V 3"]
) -> Float[Array, "V 3"]:
    """`normals` with those of the boundary vertices replaced by the normal of a
    local quadratic fit (a degree-2 osculating jet, Cazals & Pouget 2005).

    Eq. (8)–(9) averages the faces around a vertex; at a boundary vertex they lie
    on one side only, so their first-order errors do not cancel and the normal is
    O(h) off (interior vertices of regular meshes: O(h²)). At a boundary vertex v
    this fits z = a·x + b·y + c·x² + d·xy + e·y² (least squares, through v) to the
    positions of v's two-ring in the tangent frame of the given normal n_v, and
    returns the fitted surface's normal at v, ∝ n_v − a·t₁ − b·t₂. A degree-2
    fit recovers the tangent plane to O(h²), the order of the interior normals.

    A vertex keeps its given normal when its fit is ill-posed (fewer than five
    independent stencil points, as at a corner with a single face; see
    `_FIT_CONDITION`) or when the fitted normal would fold an incident face
    (n · n_face ≤ 0). Interior vertices are unchanged.

    **Arguments:** `mesh` (for its connectivity), `normals` `(V, 3)` unit vertex
    normals, e.g. `vertex_normals(mesh.vertices, mesh.faces)`.

    **Returns:** `(V, 3)` unit normals, differentiable in `mesh.vertices` and
    `normals`. Compiled (`jax.jit`): eagerly, its many small operations would
    dispatch one at a time.
    """
    # A manifold vertex has one fan, so a boundary vertex lies on exactly two
    # boundary edges: there are as many boundary vertices as boundary edges,
    # 2E − 3F (3F edge slots, two per interior edge, one per boundary edge). A
    # static count, so only those vertices are fitted, under `jit` too.
    n_open = 2 * mesh.n_edges - 3 * mesh.n_faces
    if n_open <= 0:
        return normals
    n_v = mesh.n_vertices
    verts = jnp.nonzero(mesh.is_boundary_vertex, size=n_open, fill_value=n_v)[0]
    real = verts < n_v
    verts = jnp.minimum(verts, n_v - 1)
    ids = _fit_stencil(mesh, verts)
    v = mesh.vertices
    fitted, ok = jax.vmap(_jet_normal)(
        v[verts], v[jnp.maximum(ids, 0)], ids >= 0, normals[verts]
    )
    vf = mesh.vertex_faces[verts]
    fn = face_normals(v, mesh.faces)[jnp.maximum(vf, 0)]  # (B, K, 3)
    folds = jnp.any((vf >= 0) & (jnp.sum(fn * fitted[:, None, :], -1) <= 0), -1)
    use = real & ok & ~jax.lax.stop_gradient(folds)
    new = jnp.where(use[:, None], fitted, normals[verts])
    return normals.at[jnp.where(real, verts, n_v)].set(new, mode="drop")


def edge_normal(
    n1: Float[Array | np.ndarray, "3"],
    n2: Float[Array | np.ndarray, "3"],
    u: Float[ArrayLike, ""],
) -> Float[Array | np.ndarray, "3"]:
    """Eq. (10): the normal at parameter `u` of an edge, `n1 + u (n2 − n1)`, linearly
    interpolated and, as in the paper, not renormalised."""
    return n1 + u * (n2 - n1)


@eqx.filter_jit
def phong_normals(
    mesh: Mesh,
    normals: Weighting | Float[Array, "V 3"] = "uniform",
    boundary: Literal["fit", "keep"] = "fit",
) -> Float[Array, "V 3"]:
    """The unit vertex normals that define the Phong surface (see
    `jaxgeo.smooth.smooth_geodesic`'s `normals` and `boundary`): a weighting's
    normals (eq. 8–9 for `"uniform"`) or the given array, with the boundary
    vertices' normals refitted to second order when `boundary="fit"`."""
    if isinstance(normals, str):
        nrm = vertex_normals(mesh.vertices, mesh.faces, normals)
    else:
        nrm = jnp.asarray(normals, mesh.vertices.dtype)
    if boundary == "fit":
        return fit_boundary_normals(mesh, nrm)
    if boundary != "keep":
        raise JaxgeoError(f"boundary must be 'fit' or 'keep', got {boundary!r}")
    return nrm
