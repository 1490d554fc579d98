"""The public entry points: `shortest_path` and `path_length`."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._checks import (
    as_endpoint,
    check_arguments,
    check_point,
    is_traced,
    is_vertex_index,
)
from ._errors import JaxgeoError
from ._padding import padded
from .locate import DEFAULT_MAX_DISTANCE, SurfacePoint, locate, vertex_valid
from .mesh import Mesh
from .methods import (
    METHODS,
    AnyMethod,
    Method,
    as_method,
    first_attempts,
    for_mesh,
    initial_status,
)
from .normals import Weighting
from .path import Path, Status

__all__ = ["METHODS", "Method", "path_length", "shortest_path", "solve"]

Endpoint = ArrayLike | Sequence[float] | SurfacePoint


def as_surface_point(mesh: Mesh, p: Endpoint):
    """A located endpoint and its distance from the surface: 0 for a
    `SurfacePoint` or a vertex index (an integer scalar), NaN for one that is not
    a point of the mesh (a face or vertex index out of range, a vertex in no
    face; `solve` gives such a pair `Status.INVALID_ENDPOINT`)."""
    dtype = mesh.vertices.dtype
    if isinstance(p, SurfacePoint):
        face = jnp.asarray(p.face)
        sp = SurfacePoint(face, jnp.asarray(p.bary, dtype))
        inside = (face >= 0) & (face < mesh.n_faces)
        # a padded mesh's filler faces belong to no component (`jaxgeo._padding`)
        ok = inside & (mesh.face_component[jnp.where(inside, face, 0)] >= 0)
        return sp, jnp.where(ok, 0.0, jnp.nan).astype(dtype)
    if is_vertex_index(p):
        i = jnp.asarray(p)  # (an integer scalar)
        ok = vertex_valid(mesh, i)
        return SurfacePoint.vertex(mesh, i), jnp.where(ok, 0.0, jnp.nan).astype(dtype)
    return locate(mesh, jnp.asarray(p, dtype))


def solve(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    d1: Float[Array, " B"],
    d2: Float[Array, " B"],
    max_distance: Float[Array, ""],
    method: AnyMethod,
    max_points: int,
    differentiable: bool,
) -> Path:
    """The one pipeline: located endpoint pairs (leading batch axis B) → the
    method → `Path` (batched), which carries `start` and `end` (the endpoints
    as given here). `shortest_path`, `shortest_paths` and the cutting code all
    come through here."""
    # a NaN distance marks an endpoint that is no point of the mesh (see
    # `as_surface_point`); the method still runs on a valid stand-in (face 0)
    invalid = jnp.isnan(d1) | jnp.isnan(d2)
    given = (start, end)
    start = _stand_in(start, jnp.isnan(d1))
    end = _stand_in(end, jnp.isnan(d2))
    d1, d2 = jnp.nan_to_num(d1), jnp.nan_to_num(d2)
    initial = jax.vmap(initial_status, in_axes=(None, 0, 0, 0, 0, None))(
        mesh, start, end, d1, d2, max_distance
    )
    initial = jnp.where(invalid, Status.INVALID_ENDPOINT, initial).astype(jnp.int32)
    path = method.solve(mesh, start, end, initial, max_points, differentiable)
    # A failed path has no length: NaN, never a number an optimiser could
    # minimise. `where` passes a zero cotangent to the failed length, so its
    # gradient is zero and `jnp.where(path.ok, path.length, 0.0)` masks it.
    failed = path.status != Status.SUCCESS
    # Every method's result carries its endpoints, set here once: as located,
    # not the stand-ins of invalid rows (the row's status says it failed).
    return dataclasses.replace(
        path,
        length=jnp.where(failed, jnp.nan, path.length),
        start=_as_arrays(given[0]),
        end=_as_arrays(given[1]),
    )


def _as_arrays(sp: SurfacePoint) -> SurfacePoint:
    """`sp` with its face and barycentric coordinates as arrays (a `Path`'s
    endpoints are pytree leaves of fixed type, whatever the caller passed)."""
    return SurfacePoint(jnp.asarray(sp.face, jnp.int32), jnp.asarray(sp.bary))


def _stand_in(sp: SurfacePoint, bad) -> SurfacePoint:
    """`sp`, with the centroid of face 0 in the rows where it is not a point of
    the mesh (so that no method indexes out of range or meets NaN)."""
    face, bary = jnp.asarray(sp.face), jnp.asarray(sp.bary)
    third = jnp.full((3,), 1 / 3, bary.dtype)
    return SurfacePoint(
        jnp.where(bad, 0, face).astype(face.dtype),
        jnp.where(bad[:, None], third, bary),
    )


def checked_method(
    mesh, method, candidates, max_points, normals, max_distance, throw
) -> tuple[AnyMethod, int]:
    """The options shared by `shortest_path` and `shortest_paths`, checked: the
    method object they select and `max_points` as a Python int (a static shape;
    numpy integers are accepted). `JaxgeoError` names a bad option."""
    if not isinstance(mesh, Mesh):
        raise JaxgeoError(f"mesh must be a jaxgeo.Mesh, got {type(mesh).__name__}")
    check_arguments(
        mesh,
        candidates or "local",
        max_points,
        normals or "uniform",
        max_distance,
        throw,
    )
    m = as_method(method, candidates=candidates, normals=normals)
    return for_mesh(m, mesh), int(max_points)


# (`jax.jit`, not `eqx.filter_jit`: every argument but the static ones is a pytree
# of arrays, and equinox's partition of the mesh's fields cost 0.3 ms a call)
@functools.partial(jax.jit, static_argnames=("method", "max_points", "differentiable"))
def _solve_one(mesh, p1, p2, max_distance, method, max_points, differentiable):
    start, d1 = as_surface_point(mesh, p1)
    end, d2 = as_surface_point(mesh, p2)
    batch = jax.tree.map(lambda x: x[None], (start, end, d1, d2))
    # (pyright misreads *args of unknown length followed by more arguments)
    path = solve(mesh, *batch, max_distance, method, max_points, differentiable)  # pyright: ignore[reportCallIssue]
    return jax.tree.map(lambda x: x[0], path), jnp.stack([d1, d2])


def shortest_path(
    mesh: Mesh,
    p1: Endpoint,
    p2: Endpoint,
    *,
    method: Method = "exact",
    candidates: Literal["local", "all"] | None = None,
    max_points: int | np.integer = 1024,
    normals: Weighting | None = None,
    max_distance: float = DEFAULT_MAX_DISTANCE,
    throw: bool = True,
) -> Path:
    """The geodesic from `p1` to `p2` on `mesh`.

    **Arguments:**

    - `mesh`: a `Mesh`.
    - `p1`, `p2`: endpoints, each a 3-D point near the surface (it is moved to the
      nearest point of the mesh), an integer (a vertex index: the same as
      `SurfacePoint.vertex(mesh, i)`) or a `SurfacePoint` (face, barycentric).
    - `method`: `"exact"` (the default; `jaxgeo.Exact`), the exact polyhedral
      geodesic, computed in JAX: graph paths through landmarks straightened and
      flipped round vertices until locally shortest, the shortest of several kept
      (`jaxgeo.exact`); `"laser"` (`jaxgeo.Laser`), the paper's sliding laser ray
      (sections 4–5), which is not a shortest path in general; or `"smooth"`
      (`jaxgeo.Smooth`), the geodesic of the Phong surface (α = ½) that the vertex
      normals define, started from the exact path (`jaxgeo.smooth`). A method
      object carries its options, e.g. `jaxgeo.Exact(max_starts=8)`.
    - `candidates`: `"local"` or `"all"` edges per step (laser only; shorthand for
      `Laser(candidates=...)`).
    - `max_points`: capacity of the path (endpoints included).
    - `normals`: vertex-normal weighting, `"uniform"` = the paper's eq. (8)–(9)
      (laser and smooth; shorthand for the method's `normals`).
    - `max_distance`: largest distance of a 3-D endpoint from the surface, in mean
      edge lengths.
    - `throw`: raise when the path is not complete: `JaxgeoError` on concrete
      inputs; under `jax.jit`/`jax.vmap` the compiled program raises when it runs
      (`equinox.error_if`, as optimistix does: a `RuntimeError` with the same
      message). With `throw=False` check `Path.status`; a failed path's `length`
      is NaN.

    **Returns:** a `Path`; its points and length are differentiable with respect to
    `mesh.vertices` and the endpoints. `path.start` and `path.end` are the
    endpoints as `SurfacePoint`s (a 3-D point as located on the mesh).
    """
    m, max_points = checked_method(
        mesh, method, candidates, max_points, normals, max_distance, throw
    )
    concrete = not is_traced((mesh, p1, p2))
    if concrete:
        check_point("p1", p1, mesh)
        check_point("p2", p2, mesh)
    p1, p2 = as_endpoint(p1, mesh), as_endpoint(p2, mesh)
    args = (
        # padded to its size class: compiled once per class (`padded(mesh)`, not
        # `mesh.padded()`: an equinox bound method costs ~25 µs to create)
        padded(mesh),
        p1,
        p2,
        # an array, not a static float: a new value must not recompile (numpy
        # where concrete: the call transfers it, without a dispatch of its own)
        jnp.asarray(max_distance, mesh.vertices.dtype)
        if is_traced(max_distance)
        else np.asarray(max_distance, mesh.vertices.dtype),
    )
    # one cheaper attempt (256 faces): each further size would be one more
    # program to compile per size class and method for the few single paths
    # that outgrow 256 (batches, which amortise it, climb 256 -> 512 -> ...)
    for cheaper in first_attempts(m, max_points)[:1] if concrete else []:
        path, dist = _solve_one(*args, cheaper, max_points, False)
        if not int(path.stats.get("outgrew", 0)):
            return _checked(path, dist, throw, mesh, max_distance)
    path, dist = _solve_one(*args, m, max_points, not concrete)
    return _checked(path, dist, throw, mesh, max_distance)


def _checked(path: Path, dist, throw: bool, mesh: Mesh, max_distance) -> Path:
    """`path`, or the error its status calls for when `throw`."""
    if throw:
        known = _known(path.status)
        if known is None:  # traced: the check runs with the program
            return _error_if_failed(path)
        status = Status(int(known))
        if status != Status.SUCCESS:
            detail = ""
            if status == Status.FAR_FROM_SURFACE and _known(dist) is not None:
                limit = max_distance * float(mesh.mean_edge_length)
                detail = (
                    f": distances {float(dist[0]):.3g} (p1) and {float(dist[1]):.3g} "
                    f"(p2), limit {limit:.3g} ({max_distance} mean edge lengths)"
                )
            raise JaxgeoError(f"{_MESSAGES[status]}{detail}")
    return path


#: The error of a failed path, by `Status` value.
_MESSAGES = tuple(f"no path from p1 to p2: {s.message}" for s in Status)


def _known(x) -> np.ndarray | None:
    """`x` as numpy if its value is known now (concrete input, or an integer
    under an eager `jax.grad`), None when it is traced (under `jax.jit`,
    `jax.vmap`; a float under `jax.grad`)."""
    try:
        return np.asarray(x)
    except jax.errors.JAXTypeError:
        return None


def _error_if_failed(path: Path) -> Path:
    """`path`, checked when the compiled program runs: an error with the status's
    message if it failed (as optimistix's `throw=True`: `eqx.branched_error_if`;
    under `jax.vmap`, if any row failed, with the message of the highest status
    code among them). Transparent to `jax.grad` and `jax.jvp`. The
    `EQX_ON_ERROR` environment variable chooses what an error does (`raise`, the
    default; `nan`; `breakpoint`)."""
    return eqx.branched_error_if(
        path, path.status != Status.SUCCESS, path.status, _MESSAGES
    )


def path_length(mesh: Mesh, p1: Endpoint, p2: Endpoint, **kwargs) -> Float[Array, ""]:
    """The length of `shortest_path(mesh, p1, p2, **kwargs)`; differentiable with
    respect to `mesh.vertices`, `p1` and `p2` (`jax.grad`, `jax.jvp`)."""
    return shortest_path(mesh, p1, p2, **kwargs).length
