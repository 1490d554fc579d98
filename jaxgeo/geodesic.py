"""The public entry points: `shortest_path` and `path_length`."""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._checks import as_endpoint, check_arguments, check_point, is_traced
from ._errors import JaxgeoError
from .locate import DEFAULT_MAX_DISTANCE, SurfacePoint, locate
from .mesh import Mesh
from .methods import METHODS, AnyMethod, Method, as_method, initial_status
from .normals import Weighting
from .path import Path, Status

__all__ = ["METHODS", "Method", "path_length", "shortest_path", "solve"]

Endpoint = ArrayLike | SurfacePoint


def as_surface_point(mesh: Mesh, p: Endpoint):
    """A located endpoint and its distance from the surface (0 for a
    `SurfacePoint`)."""
    if isinstance(p, SurfacePoint):
        sp = SurfacePoint(jnp.asarray(p.face), jnp.asarray(p.bary, mesh.vertices.dtype))
        return sp, jnp.zeros((), mesh.vertices.dtype)
    return locate(mesh, jnp.asarray(p, mesh.vertices.dtype))


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
    method → `Path` (batched). `shortest_path`, `shortest_paths` and the cutting
    code all come through here."""
    initial = jax.vmap(initial_status, in_axes=(None, 0, 0, 0, 0, None))(
        mesh, start, end, d1, d2, max_distance
    )
    return method.solve(mesh, start, end, initial, max_points, differentiable)


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
    return as_method(method, candidates=candidates, normals=normals), int(max_points)


@eqx.filter_jit
def _solve_one(mesh, p1, p2, max_distance, method, max_points, differentiable):
    start, d1 = as_surface_point(mesh, p1)
    end, d2 = as_surface_point(mesh, p2)
    batch = jax.tree.map(lambda x: x[None], (start, end, d1, d2))
    path = solve(mesh, *batch, max_distance, method, max_points, differentiable)
    return jax.tree.map(lambda x: x[0], path), jnp.stack([d1, d2])


def shortest_path(
    mesh: Mesh,
    p1: Endpoint,
    p2: Endpoint,
    *,
    method: Method = "exact",
    candidates: Literal["local", "all"] | None = None,
    max_points: int = 1024,
    normals: Weighting | None = None,
    max_distance: float = DEFAULT_MAX_DISTANCE,
    throw: bool = True,
) -> Path:
    """The geodesic from `p1` to `p2` on `mesh`.

    **Arguments:**

    - `mesh`: a `Mesh`.
    - `p1`, `p2`: endpoints, each a 3-D point near the surface (it is moved to the
      nearest point of the mesh) or a `SurfacePoint` (face, barycentric).
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
    - `throw`: raise `JaxgeoError` when the path is not complete. Only acts on
      concrete inputs; under `jax.jit`/`jax.vmap` check `Path.status` instead.

    **Returns:** a `Path`; its points and length are differentiable with respect to
    `mesh.vertices` and the endpoints.
    """
    m, max_points = checked_method(
        mesh, method, candidates, max_points, normals, max_distance, throw
    )
    concrete = not is_traced((mesh, p1, p2))
    if concrete:
        check_point("p1", p1, mesh)
        check_point("p2", p2, mesh)
    p1, p2 = as_endpoint(p1, mesh), as_endpoint(p2, mesh)
    path, dist = _solve_one(
        mesh.padded(),  # padded to its size class: compiled once per class
        p1,
        p2,
        # an array, not a static float: a new value must not recompile
        jnp.asarray(max_distance, mesh.vertices.dtype),
        m,
        max_points,
        not concrete,
    )
    if throw and concrete:
        status = Status(int(path.status))
        if status != Status.SUCCESS:
            detail = ""
            if status == Status.FAR_FROM_SURFACE:
                limit = max_distance * float(mesh.mean_edge_length)
                detail = (
                    f": distances {float(dist[0]):.3g} (p1) and {float(dist[1]):.3g} "
                    f"(p2), limit {limit:.3g} ({max_distance} mean edge lengths)"
                )
            raise JaxgeoError(f"no path from p1 to p2: {status.message}{detail}")
    return path


def path_length(mesh: Mesh, p1: Endpoint, p2: Endpoint, **kwargs) -> Float[Array, ""]:
    """The length of `shortest_path(mesh, p1, p2, **kwargs)`; differentiable with
    respect to `mesh.vertices`, `p1` and `p2` (`jax.grad`, `jax.jvp`)."""
    return shortest_path(mesh, p1, p2, **kwargs).length
