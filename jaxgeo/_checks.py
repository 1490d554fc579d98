"""Eager checks of the arguments of `shortest_path` and `shortest_paths`.

Everything here runs in Python/numpy before anything is traced, and raises
`JaxgeoError` naming the argument and the problem. Traced values (under `jax.jit`,
`jax.vmap`, `jax.grad`) cannot be inspected and are skipped; there the result's
`Path.status` is the check.
"""

from __future__ import annotations

import numbers
import warnings
import weakref
from collections.abc import Callable
from typing import Any

import jax
import jax.core
import numpy as np
from scipy.spatial import cKDTree

from ._errors import JaxgeoError
from ._stacklevel import caller_stacklevel
from .locate import SurfacePoint

#: The vertex-normal weightings of `jaxgeo.normals.vertex_normals`.
WEIGHTINGS = ("uniform", "area", "angle")
#: The candidate-edge sets of `jaxgeo.trace`.
CANDIDATES = ("local", "all")
#: A 3-D endpoint within this many mean edge lengths of a position that several
#: vertices share is taken to be at it: nearer, which of the copies' faces is the
#: nearest is decided by rounding (text files keep 6-9 significant digits, float32
#: 7), not by the caller.
COINCIDENT_TOLERANCE = 1e-6


def is_traced(x: Any) -> bool:
    """Whether any leaf of `x` is a tracer (inside `jit`, `vmap`, `grad`, ...)."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(x))


def _check_bool(name: str, value: Any) -> None:
    if not isinstance(value, bool | np.bool_):
        raise JaxgeoError(f"{name} must be True or False, got {value!r}")


def _check_int(name: str, value: Any, low: int) -> None:
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise JaxgeoError(
            f"{name} must be an integer, got {type(value).__name__} {value!r}"
        )
    if value < low:
        raise JaxgeoError(f"{name} must be at least {low}, got {value}")


#: The vertex array `check_mesh_vertices` last found good (a weak reference):
#: `shortest_path` in a loop over one mesh checks it once, not per call.
_checked_vertices: weakref.ref | None = None


def check_mesh_vertices(mesh) -> None:
    """The vertex array of a concrete mesh is float32/float64 and finite.

    `Mesh(...)` validates its input, but `Mesh.with_vertices` does not (it must
    accept tracers), so a NaN or a wrong dtype can reach the solver that way; a NaN
    vertex would otherwise give NaN crossings or a wrong nearest face."""
    global _checked_vertices
    v = mesh.vertices
    if is_traced(v):
        return
    if _checked_vertices is not None and _checked_vertices() is v:
        return  # (the last array checked: a loop over paths)
    a = np.asarray(v)
    if a.dtype not in (np.float32, np.float64):
        raise JaxgeoError(
            f"mesh.vertices must be float32 or float64, got dtype {a.dtype} (set "
            "with Mesh.with_vertices?)"
        )
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise JaxgeoError(
            "mesh.vertices has NaN or infinite coordinates at vertices "
            f"{np.flatnonzero(bad)[:10].tolist()} (Mesh.with_vertices does not "
            "re-validate)"
        )
    if isinstance(v, jax.Array):  # (immutable: its check stays true)
        _checked_vertices = weakref.ref(v)


def check_arguments(
    mesh,
    candidates: Any = "local",
    max_points: Any = 1024,
    normals: Any = "uniform",
    max_distance: Any = 0.5,
    throw: Any = True,
) -> None:
    """Check the options shared by `shortest_path` and `shortest_paths` and the
    mesh's vertex array.

    **Raises** `JaxgeoError` naming the argument: an unknown `candidates` or
    `normals`; a `max_points` that is not an integer ≥ 2; a `max_distance` that is
    not a positive real number (NaN would silently accept any endpoint; +inf is
    allowed and means no limit); a non-bool `throw`; a mesh whose vertices are not
    finite floats.
    """
    if not isinstance(candidates, str) or candidates not in CANDIDATES:
        raise JaxgeoError(f"candidates must be one of {CANDIDATES}, not {candidates!r}")
    if not isinstance(normals, str) or normals not in WEIGHTINGS:
        raise JaxgeoError(f"normals must be one of {WEIGHTINGS}, not {normals!r}")
    _check_int("max_points", max_points, 2)
    if not is_traced(max_distance):
        d = np.asarray(max_distance)
        if d.shape != () or d.dtype.kind not in "fiu" or d.dtype == bool:
            raise JaxgeoError(
                f"max_distance must be a real number (mean edge lengths), got "
                f"{max_distance!r}"
            )
        if not float(d) > 0:  # also catches NaN
            raise JaxgeoError(f"max_distance must be positive, got {float(d)}")
    _check_bool("throw", throw)
    if mesh is not None:
        check_mesh_vertices(mesh)


def check_batch_options(
    chunk_size: Any, shard: Any, progress: Callable[[int, int], None] | None
) -> None:
    """`shortest_paths`' own options: `chunk_size` an integer ≥ 1, `shard` a bool,
    `progress` callable or None."""
    _check_int("chunk_size", chunk_size, 1)
    _check_bool("shard", shard)
    if progress is not None and not callable(progress):
        raise JaxgeoError(f"progress must be callable or None, got {progress!r}")


def is_vertex_index(p: Any) -> bool:
    """Whether an endpoint is an integer scalar (a Python, numpy or JAX integer,
    traced or not; not a bool): a vertex index."""
    if isinstance(p, bool | np.bool_):
        return False
    if isinstance(p, numbers.Integral):
        return True
    dtype, shape = getattr(p, "dtype", None), getattr(p, "shape", None)
    return dtype is not None and np.dtype(dtype).kind in "iu" and shape == ()


def as_endpoint(p: Any, mesh) -> Any:
    """An endpoint as the compiled solver takes it: a 3-D point as a JAX array of
    the mesh's dtype; a concrete vertex index as `SurfacePoint.vertex` (so it
    shares the compiled code of surface points), a traced one as an int32
    array; a `SurfacePoint` with an int32 face and bary of the mesh's dtype.
    Lists, tuples, Python and integer scalars would otherwise reach the
    jit-compiled solver as static values or new dtypes, and compile it again for
    every call."""
    jnp = jax.numpy
    if isinstance(p, SurfacePoint):
        return SurfacePoint(
            jnp.asarray(p.face, jnp.int32), jnp.asarray(p.bary, mesh.vertices.dtype)
        )
    if is_vertex_index(p):
        if is_traced(p):
            return jnp.asarray(p, jnp.int32)
        if is_traced((mesh.faces, mesh.vertex_faces)):
            return SurfacePoint.vertex(mesh, jnp.asarray(p, jnp.int32))
        return _vertex_point(mesh, int(p))
    return jnp.asarray(p, mesh.vertices.dtype)


def _vertex_point(mesh, i: int) -> SurfacePoint:
    """`SurfacePoint.vertex(mesh, i)` for a concrete mesh and index, in numpy (the
    host copies of the tables are cached by JAX): a fifth of a single path's
    fixed cost was its two endpoints' dispatches."""
    vertex_faces, faces = np.asarray(mesh.vertex_faces), np.asarray(mesh.faces)
    dtype = np.dtype(mesh.vertices.dtype)
    ok = 0 <= i < vertex_faces.shape[0] and vertex_faces[i, 0] >= 0
    if not ok:  # (as `SurfacePoint.vertex`: face 0, NaN; `check_point` refuses it)
        return SurfacePoint(np.int32(0), np.full(3, np.nan, dtype))
    face = vertex_faces[i, 0]
    bary = np.zeros(3, dtype)
    bary[np.argmax(faces[face] == i)] = 1
    return SurfacePoint(np.int32(face), bary)


def check_vertex_indices(name: str, idx: np.ndarray, mesh) -> None:
    """Concrete vertex indices (a scalar or `(N,)`) are in range and of vertices
    that belong to a face."""
    idx = np.asarray(idx)
    rows = np.atleast_1d(idx)
    out = np.flatnonzero((rows < 0) | (rows >= mesh.n_vertices))
    which = (lambda k: name) if idx.ndim == 0 else (lambda k: f"{name}[{k}]")
    if out.size:
        k = int(out[0])
        more = f" ({out.size} of {rows.size} rows of {name} are)" if idx.ndim else ""
        raise JaxgeoError(
            f"{which(k)}: vertex {int(rows[k])} is out of range "
            f"[0, {mesh.n_vertices}){more}"
        )
    unused = np.flatnonzero(np.asarray(mesh.vertex_faces)[rows, 0] < 0)
    if unused.size:
        k = int(unused[0])
        raise JaxgeoError(
            f"{which(k)}: vertex {int(rows[k])} belongs to no face of the mesh"
        )


def check_point(name: str, p: Any, mesh) -> None:
    """Eager checks of an endpoint given as a 3-D point, a vertex index or a
    SurfacePoint."""
    if is_vertex_index(p):
        check_vertex_indices(name, np.asarray(p), mesh)
        return
    if isinstance(p, SurfacePoint):
        face, bary = np.asarray(p.face), np.asarray(p.bary)
        if face.shape != () or face.dtype.kind not in "iu":
            raise JaxgeoError(f"{name}.face must be an integer scalar, got {face!r}")
        if not 0 <= int(face) < mesh.n_faces:
            raise JaxgeoError(
                f"{name}.face {int(face)} is out of range [0, {mesh.n_faces})"
            )
        if bary.shape != (3,) or not np.isfinite(bary).all():
            raise JaxgeoError(f"{name}.bary must be 3 finite numbers, got {bary!r}")
        if (bary < -1e-9).any() or abs(bary.sum() - 1) > 1e-6:
            raise JaxgeoError(
                f"{name}.bary must be non-negative and sum to 1, got {bary!r}"
            )
        return
    a = np.asarray(p)
    if a.dtype.kind not in "fiu":
        raise JaxgeoError(f"{name} must be a real 3-D point, got dtype {a.dtype}")
    if a.shape != (3,):
        raise JaxgeoError(
            f"{name} must be a 3-D point, shape (3,), or an integer vertex index, "
            f"got shape {a.shape} ({a.dtype})"
        )
    if not np.isfinite(a).all():
        raise JaxgeoError(f"{name} has NaN or infinite coordinates: {a}")
    warn_if_coincident(name, a, mesh)


class _Coincident:
    """The vertices of a mesh that share their position with another vertex: a
    KD-tree over them, and one (face, corner) of each for the warning's hint."""

    def __init__(self, mesh):
        v = np.asarray(mesh.vertices)
        _, group, counts = np.unique(v, axis=0, return_inverse=True, return_counts=True)
        self.vertices = np.flatnonzero(counts[group.ravel()] > 1)
        self.tree = cKDTree(v[self.vertices]) if self.vertices.size else None
        if self.vertices.size:
            faces = np.asarray(mesh.faces)
            self.face = np.asarray(mesh.vertex_faces)[self.vertices, 0]
            self.corner = np.argmax(faces[self.face] == self.vertices[:, None], 1)
        self.radius = COINCIDENT_TOLERANCE * float(mesh.mean_edge_length)


#: `_Coincident` per vertex array (by identity; dropped with the array).
_COINCIDENT: dict[int, tuple[weakref.ref, _Coincident]] = {}


def _coincident(mesh) -> _Coincident:
    key = id(mesh.vertices)
    hit = _COINCIDENT.get(key)
    if hit is not None and hit[0]() is mesh.vertices:
        return hit[1]

    def drop(ref, key=key):
        if _COINCIDENT.get(key, (None,))[0] is ref:
            del _COINCIDENT[key]

    entry = _Coincident(mesh)
    _COINCIDENT[key] = (weakref.ref(mesh.vertices, drop), entry)
    return entry


def warn_if_coincident(name: str, points: np.ndarray, mesh) -> None:
    """Warn when a 3-D endpoint (`(3,)`, or rows of `(N, 3)`) sits where several
    vertices of the mesh share a position (kept apart: a pinch, a crack,
    `merge_vertices=False`): the nearest point of the mesh is then any of them,
    and the path silently starts from one. One KD-tree query per point; the tree
    (over the shared vertices only) is built once per mesh."""
    c = _coincident(mesh)
    if c.tree is None:
        return
    rows = np.atleast_2d(points)
    hits = c.tree.query_ball_point(rows, c.radius)
    ambiguous = [i for i, h in enumerate(hits) if len(h) > 1]
    if not ambiguous:
        return
    row = ambiguous[0]
    near = np.sort(hits[row])
    hints = " or ".join(
        f"jaxgeo.SurfacePoint({int(c.face[i])}, "
        f"{[1.0 if k == c.corner[i] else 0.0 for k in range(3)]}) for vertex "
        f"{int(c.vertices[i])}"
        for i in near[:4]
    )
    which = name if np.ndim(points) == 1 else f"{name}[{row}]"
    more = f" ({len(ambiguous)} such rows of {name})" if np.ndim(points) > 1 else ""
    warnings.warn(
        f"{which} = {rows[row].tolist()} is at a position shared by vertices "
        f"{', '.join(str(int(c.vertices[i])) for i in near)}{more}, which the mesh "
        "keeps apart: which of them the path starts from is arbitrary. Pass a "
        f"jaxgeo.SurfacePoint on the intended side instead, e.g. {hints}",
        stacklevel=caller_stacklevel(),
    )


def check_point_batch(name: str, p: Any, mesh=None) -> np.ndarray:
    """Eager checks of a batch of endpoints: 3-D points `(N, 3)` or vertex indices,
    an integer array `(N,)` (checked against `mesh` if given); returns it as
    numpy."""
    a = np.asarray(p)
    if a.dtype.kind not in "fiu":
        raise JaxgeoError(f"{name} must be real 3-D points, got dtype {a.dtype}")
    if a.ndim == 1 and a.dtype.kind in "iu":
        if mesh is not None:
            check_vertex_indices(name, a, mesh)
        return a
    if a.ndim != 2 or a.shape[1] != 3:
        raise JaxgeoError(
            f"{name} must be 3-D points, shape (N, 3), or vertex indices, an "
            f"integer array of shape (N,); got shape {a.shape} ({a.dtype})"
        )
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise JaxgeoError(
            f"{name} has NaN or infinite coordinates in rows {np.flatnonzero(bad)[:10]}"
        )
    return a
