"""The methods, as `eqx.Module`s holding their options (as `optimistix.Newton`
holds its tolerances). `shortest_path(..., method=Exact(max_starts=8))`; the
strings "exact", "laser" and "smooth" are shorthands for the defaults.

Each method solves a batch of located endpoint pairs (`solve`): the single-path
API calls it with a batch of one, `shortest_paths` with a chunk.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Int

from ._checks import is_traced
from ._errors import JaxgeoError
from .exact import POOL_MIN_CONE_FREE, exact_solve
from .locate import SurfacePoint
from .mesh import Mesh
from .normals import Weighting, vertex_normals
from .path import Path, Status
from .replay import replay
from .trace import TraceOptions, trace_batch


class Exact(eqx.Module):
    """The exact polyhedral geodesic, computed in JAX (`jaxgeo.exact`): landmark
    graph paths refined by wedge flips until locally shortest, then `detours`
    corridors round the other side of the best path's nearest cone vertices and,
    with `walls`, 8 corridors moved across a stretch of one of its walls
    (`detour_rounds` times); the shortest kept. Where the mesh has no cone vertex
    (anticlastic membranes) the detours are skipped and a start stops once
    another of its class has converged, exactly (`jaxgeo.exact`, "Certificate").
    Length and points differentiable.
    `max_starts=4` is ~1.4x faster per single path on a scan (`bone.ply`, README),
    and `walls=False, detour_rounds=1` ~1.8x more; both miss the shortest path
    more often on scanned meshes (`docs/accuracy.md`).
    The default method. `corridor_capacity`: faces a corridor may hold (None:
    `max_points`; `shortest_path` then tries 256 first, `shortest_paths` 256
    and 512, see `first_attempts`). `min_lanes`: the flip loop's lanes at least
    (None: 1 on a concrete mesh with no cone vertex, else 4; see `for_mesh`); with
    1, every pair's first start is built and refined alone, and its others only
    if that did not settle it (`jaxgeo.exact`, "Certificate")."""

    max_starts: int = 8
    max_iterations: int | None = None  # None: the corridor capacity, >= 256
    detours: int = 16
    detour_rounds: int = 2
    walls: bool = True
    corridor_capacity: int | None = None
    min_lanes: int | None = None

    def solve(self, mesh, start, end, initial, max_points, differentiable) -> Path:
        res = exact_solve(
            mesh,
            start,
            end,
            max_points=max_points,
            max_starts=self.max_starts,
            max_iterations=self.max_iterations,
            detours=self.detours,
            detour_rounds=self.detour_rounds,
            walls=self.walls,
            corridor_capacity=self.corridor_capacity,
            min_lanes=self.min_lanes,
        )
        status = jnp.where(initial >= 0, initial, res.status).astype(jnp.int32)
        stats = {
            f.name: getattr(res.stats, f.name) for f in dataclasses.fields(res.stats)
        }
        return Path(
            points=res.points,
            kinds=res.kinds,
            elements=res.elements,
            params=res.params,
            branch=jnp.zeros(res.kinds.shape, bool),
            count=res.count,
            length=res.length,
            status=status,
            stats=stats,
        )


class Laser(eqx.Module):
    """The paper's sliding laser ray (sections 4–5; `jaxgeo.trace`): System (16) as
    a batched `optimistix.Newton` root find per step. Not a shortest path in
    general (see the README's validation table). `candidates`: `"local"` or
    `"all"` edges per step; `normals`: vertex-normal weighting (eq. 8–9:
    `"uniform"`)."""

    candidates: Literal["local", "all"] = "local"
    normals: Weighting = "uniform"

    def solve(self, mesh, start, end, initial, max_points, differentiable) -> Path:
        normals = vertex_normals(mesh.vertices, mesh.faces, self.normals)
        options = TraceOptions(candidates=self.candidates, max_points=max_points)
        sg = jax.lax.stop_gradient
        traced = trace_batch(
            sg(mesh), sg(normals), sg(start), sg(end), options, initial
        )
        if differentiable:
            traced = jax.vmap(lambda s, e, t: replay(mesh, normals, s, e, t))(
                start, end, traced
            )
        stats = {"branch_points": jnp.sum(traced.branch, axis=-1, dtype=jnp.int32)}
        return dataclasses.replace(traced, stats=stats)


class Smooth(eqx.Module):
    """The geodesic of the smooth surface the Phong normals define (Phong
    tessellation, α = ½; `jaxgeo.smooth`), started from the exact path's strip and
    repaired at vertex contacts, all in JAX. `normals`: vertex-normal weighting;
    `max_rounds`: strip repair rounds. The result's `stats` hold the exact
    method's and the smooth solve's (`Path.stats`)."""

    normals: Weighting = "uniform"
    max_rounds: int = 8
    exact: Exact = Exact()

    def solve(self, mesh, start, end, initial, max_points, differentiable) -> Path:
        from .smooth import smooth_path

        ex = self.exact.solve(mesh, start, end, initial, max_points, differentiable)
        normals = vertex_normals(mesh.vertices, mesh.faces, self.normals)

        def one(s, e, k, el, u, c):
            return smooth_path(
                mesh, s, e, k, el, u, c, normals, max_rounds=self.max_rounds
            )

        r = jax.vmap(one)(start, end, ex.kinds, ex.elements, ex.params, ex.count)
        ok = ex.status == Status.SUCCESS
        good = ok & r.ok
        sp = r.path

        def pick(a, b):
            g = good.reshape(good.shape + (1,) * (a.ndim - 1))
            return jnp.where(g, a, b)

        # the smooth solve's own diagnostics beside the exact method's (whose
        # `iterations` are flip rounds: the Newton iterations get their own key)
        stats = dict(
            ex.stats or {},
            repair_rounds=r.rounds,
            releases=r.releases,
            converged=sp.converged,
            grad_norm=sp.grad_norm,
            newton_iterations=sp.iterations,
        )
        return Path(
            points=pick(sp.points, ex.points),
            kinds=pick(sp.kinds, ex.kinds),
            elements=pick(sp.elements, ex.elements),
            params=pick(sp.params, ex.params),
            branch=ex.branch,
            count=pick(sp.count, ex.count),
            length=pick(sp.length, ex.length),
            status=jnp.where(ok & ~r.ok, Status.REFINE_FAILED, ex.status).astype(
                jnp.int32
            ),
            stats=stats,
        )


AnyMethod = Exact | Laser | Smooth

#: Faces a corridor of the exact engine holds in the cheaper attempts made
#: before `max_points` (`first_attempts`), smallest first.
FIRST_CAPACITIES = (256, 512)


def first_attempts(method: AnyMethod, max_points: int) -> list[AnyMethod]:
    """Cheaper `method`s to try first on concrete inputs, in order: the exact
    engine (also under `Smooth`) with corridors of each of `FIRST_CAPACITIES`
    faces below `max_points`. Every flip round costs in proportion to the
    capacity, and most paths cross far fewer faces: on random pairs of a
    20k-face catenoid (CPU time, `benchmarks/`) single paths took 163 instead
    of 252 ms and batches ran 2.7× faster with 256 alone. A pair whose
    corridor outgrew an attempt (`stats["outgrew"]`) is solved again by the
    next, and last by `method` itself; 512 before 1024 caught every pair of 30
    that outgrew 256 there (a whole-wall detour corridor of a long path, most
    often). Compiling a larger size happens only when a path needs it.
    `shortest_paths` climbs the whole ladder (for the pairs that outgrew only);
    `shortest_path` makes the first attempt only, as each size is one more
    compile per size class."""
    if isinstance(method, Exact) and method.corridor_capacity is None:
        return [
            _replace(method, corridor_capacity=c)
            for c in FIRST_CAPACITIES
            if c < max_points
        ]
    if isinstance(method, Smooth):
        return [
            _replace(method, exact=e) for e in first_attempts(method.exact, max_points)
        ]
    return []


def for_mesh(method: AnyMethod, mesh: Mesh) -> AnyMethod:
    """`method` with the options it leaves to the mesh set, where the mesh is
    concrete: the exact engine's `min_lanes` is 1 on a mesh with no cone vertex
    (`exact.POOL_MIN_CONE_FREE`; a static choice, so one program per mesh, not
    one per branch). A traced mesh keeps the defaults."""
    if isinstance(method, Smooth):
        return _replace(method, exact=for_mesh(method.exact, mesh))
    if not isinstance(method, Exact) or method.min_lanes is not None:
        return method
    if is_traced(mesh.component_cone_free):  # (`Mesh.with_vertices` under jit)
        return method
    cone_free = bool(np.all(np.asarray(mesh.component_cone_free)))
    return _replace(method, min_lanes=POOL_MIN_CONE_FREE if cone_free else None)


def _replace(method: AnyMethod, **changes) -> AnyMethod:
    """`dataclasses.replace(method, **changes)`, remembered: building a module
    costs ~50 µs, and `shortest_path` derives its method on every call."""
    try:
        return _replaced(method, tuple(sorted(changes.items())))
    except TypeError:  # (an unhashable option)
        return dataclasses.replace(method, **changes)


@functools.lru_cache(maxsize=256)
def _replaced(method: AnyMethod, changes: tuple) -> AnyMethod:
    return dataclasses.replace(method, **dict(changes))


Method = Literal["exact", "laser", "smooth"] | AnyMethod
#: The method names `shortest_path` accepts.
METHODS: tuple[str, ...] = ("exact", "laser", "smooth")
_BY_NAME = {"exact": Exact, "laser": Laser, "smooth": Smooth}


def as_method(method: Method, **legacy) -> AnyMethod:
    """The method object for a name or an object; `legacy` keywords (the
    `candidates=`/`normals=` arguments of `shortest_path`) fill options a name
    leaves at their defaults."""
    if isinstance(method, Exact | Laser | Smooth):
        from ._checks import check_arguments

        check_arguments(
            None,
            getattr(method, "candidates", "local"),
            normals=getattr(method, "normals", "uniform"),
        )
        return method
    if not isinstance(method, str) or method not in _BY_NAME:
        raise JaxgeoError(
            f"unknown method {method!r}; expected one of {METHODS} or a "
            "jaxgeo.Exact/Laser/Smooth object"
        )
    try:  # (remembered, as `_replace`)
        return _named_cached(method, tuple(sorted(legacy.items())))
    except TypeError:  # (an unhashable option: the checks name it)
        return _named(method, tuple(legacy.items()))


@functools.lru_cache(maxsize=64)
def _named_cached(name: str, legacy: tuple) -> AnyMethod:
    return _named(name, legacy)


def _named(name: str, legacy: tuple) -> AnyMethod:
    cls = _BY_NAME[name]
    fields = {f for f in cls.__dataclass_fields__}
    return cls(**{k: v for k, v in legacy if k in fields and v is not None})


def initial_status(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    d1,
    d2,
    max_distance,
) -> Int[Array, ""]:
    """−1 (solve), or the status for endpoints too far from the surface (`d1`,
    `d2`: the 3-D endpoints' distances) or on different components."""
    far = jnp.maximum(d1, d2) > max_distance * mesh.mean_edge_length
    apart = mesh.face_component[start.face] != mesh.face_component[end.face]
    return jnp.where(
        far, Status.FAR_FROM_SURFACE, jnp.where(apart, Status.DIFFERENT_COMPONENTS, -1)
    ).astype(jnp.int32)
