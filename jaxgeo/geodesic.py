"""The public entry points: `shortest_path` and `path_length`."""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

from ._checks import as_endpoint, check_arguments, check_point, is_traced
from ._errors import JaxgeoError
from ._exact_method import exact_path
from .locate import DEFAULT_MAX_DISTANCE, SurfacePoint, locate
from .mesh import Mesh
from .normals import Weighting, vertex_normals
from .path import Path, Status
from .replay import replay
from .trace import TraceOptions, trace

Method = Literal["exact", "laser", "smooth"]
#: The methods `shortest_path` accepts.
METHODS: tuple[str, ...] = ("laser", "exact", "smooth")
Endpoint = ArrayLike | SurfacePoint


def _validate_options(method: str) -> None:
    if method not in METHODS:
        raise JaxgeoError(f"unknown method {method!r}; expected one of {METHODS}")


def _as_surface_point(mesh: Mesh, p: Endpoint):
    if isinstance(p, SurfacePoint):
        sp = SurfacePoint(jnp.asarray(p.face), jnp.asarray(p.bary, mesh.vertices.dtype))
        return sp, jnp.zeros((), mesh.vertices.dtype)
    return locate(mesh, jnp.asarray(p, mesh.vertices.dtype))


@eqx.filter_jit
def _solve(
    mesh: Mesh,
    p1: Endpoint,
    p2: Endpoint,
    max_distance: float | Float[Array, ""],
    weighting: str,
    options: TraceOptions,
    differentiable: bool = True,
    method: str = "laser",
) -> tuple[Path, SurfacePoint, SurfacePoint, Float[Array, "2"]]:
    start, d1 = _as_surface_point(mesh, p1)
    end, d2 = _as_surface_point(mesh, p2)
    initial = _initial_status(mesh, start, end, d1, d2, max_distance)
    normals = vertex_normals(mesh.vertices, mesh.faces, weighting)
    traced = trace(
        jax.lax.stop_gradient(mesh),
        jax.lax.stop_gradient(normals),
        jax.lax.stop_gradient(start),
        jax.lax.stop_gradient(end),
        options,
        initial,
    )
    path = _finish_method(
        mesh, normals, start, end, traced, initial, differentiable, method
    )
    return path, start, end, jnp.stack([d1, d2])


def _initial_status(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    d1: Float[Array, ""],
    d2: Float[Array, ""],
    max_distance: float | Float[Array, ""],
) -> Int[Array, ""]:
    """−1 (trace), or the status for endpoints too far from the surface (`d1`, `d2`:
    the 3-D endpoints' distances) or on different components."""
    far = jnp.maximum(d1, d2) > max_distance * mesh.mean_edge_length
    apart = mesh.face_component[start.face] != mesh.face_component[end.face]
    return jnp.where(
        far, Status.FAR_FROM_SURFACE, jnp.where(apart, Status.DIFFERENT_COMPONENTS, -1)
    ).astype(jnp.int32)


def _finish_method(
    mesh: Mesh,
    normals: Float[Array, "V 3"],
    start: SurfacePoint,
    end: SurfacePoint,
    traced: Path,
    initial: Int[Array, ""],
    differentiable: bool,
    method: str,
) -> Path:
    """The path of `method` from the laser trace `traced`."""
    if method == "exact":
        return exact_path(mesh, start, end, traced, initial)
    if method == "smooth":
        return exact_path(mesh, start, end, traced, initial, smooth_normals=normals)
    # The replay only attaches derivatives: its points equal the traced ones to
    # rounding. Concrete calls outside any transformation cannot be differentiated
    # afterwards, so they skip it.
    if differentiable:
        return replay(mesh, normals, start, end, traced)
    return traced


def shortest_path(
    mesh: Mesh,
    p1: Endpoint,
    p2: Endpoint,
    *,
    method: Method = "laser",
    candidates: Literal["local", "all"] = "local",
    max_points: int = 1024,
    normals: Weighting = "uniform",
    max_distance: float = DEFAULT_MAX_DISTANCE,
    throw: bool = True,
) -> Path:
    """The geodesic from `p1` to `p2` on `mesh`.

    **Arguments:**

    - `mesh`: a `Mesh`.
    - `p1`, `p2`: endpoints, each a 3-D point near the surface (it is moved to the
      nearest point of the mesh) or a `SurfacePoint` (face, barycentric).
    - `method`: `"laser"`, the sliding laser ray of the paper (sections 4–5), or
      `"exact"`, the exact polyhedral geodesic: the laser ray's corridor (and a
      Dijkstra corridor) straightened and released around vertices until it is
      locally shortest (`jaxgeo.refine`); its length is differentiable, its points
      are not; or `"smooth"`, the geodesic of the Phong surface (α = ½) that the
      vertex normals define, started from the exact path's strip
      (`jaxgeo.smooth`); points and length differentiable.
    - `candidates`: `"local"` or `"all"` edges per step (see `jaxgeo.trace`).
    - `max_points`: capacity of the path (endpoints included).
    - `normals`: vertex-normal weighting, `"uniform"` = the paper's eq. (8)–(9).
    - `max_distance`: largest distance of a 3-D endpoint from the surface, in mean
      edge lengths.
    - `throw`: raise `JaxgeoError` when the path is not complete. Only acts on
      concrete inputs; under `jax.jit`/`jax.vmap` check `Path.status` instead.

    **Returns:** a `Path`; its points and length are differentiable with respect to
    `mesh.vertices` and the endpoints (see `jaxgeo.replay`).
    """
    if not isinstance(mesh, Mesh):
        raise JaxgeoError(f"mesh must be a jaxgeo.Mesh, got {type(mesh).__name__}")
    _validate_options(method)
    check_arguments(mesh, candidates, max_points, normals, max_distance, throw)
    concrete = not is_traced((mesh, p1, p2))
    if concrete:
        check_point("p1", p1, mesh)
        check_point("p2", p2, mesh)
    p1, p2 = as_endpoint(p1, mesh), as_endpoint(p2, mesh)
    options = TraceOptions(candidates=candidates, max_points=max_points)
    path, _, _, dist = _solve(
        mesh,
        p1,
        p2,
        # an array, not a static float: a new value must not recompile
        jnp.asarray(max_distance, mesh.vertices.dtype),
        normals,
        options,
        differentiable=not concrete,
        method=method,
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
