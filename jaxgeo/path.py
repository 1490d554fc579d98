"""The `Path` pytree and its status codes."""

from __future__ import annotations

import enum
from collections.abc import Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, Shaped

from ._errors import JaxgeoError
from ._numerics import safe_norm
from .locate import EDGE, FACE, VERTEX, SurfacePoint
from .mesh import Mesh

__all__ = ["EDGE", "FACE", "VERTEX", "Path", "Status", "pad_tail", "polyline_length"]


class Status(enum.IntEnum):
    """How a trace ended. `Path.status` holds one of these as an integer array."""

    #: Point 2 was reached; the polyline is complete.
    SUCCESS = 0
    #: The buffer of `max_points` filled before point 2 was reached.
    MAX_STEPS = 1
    #: No valid crossing of System (16) ahead of the current point (e.g. the chord's
    #: projection leaves the mesh through its boundary).
    NO_CROSSING = 2
    #: An endpoint is farther from the surface than the allowed distance.
    FAR_FROM_SURFACE = 3
    #: The endpoints lie on different connected components of the mesh.
    DIFFERENT_COMPONENTS = 4
    #: The exact refinement could not complete (see `jaxgeo.exact`).
    REFINE_FAILED = 5
    #: An endpoint is no point of the mesh: a vertex or face index out of range,
    #: or a vertex that no face references (checked eagerly on concrete input;
    #: this code is what a traced index gets).
    INVALID_ENDPOINT = 6

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    Status.SUCCESS: "point 2 reached",
    Status.MAX_STEPS: "out of steps: the path needs more than max_points points, "
    "or the laser ray's step budget (8 per point) ran out (raise max_points)",
    Status.NO_CROSSING: "the laser ray found no crossing ahead of the current "
    "point on its faces (the chord's projection leaves the surface there: a "
    "concave region, a gap, or a boundary it cannot slide along without turning "
    "back); method='exact' does not depend on it",
    Status.FAR_FROM_SURFACE: "an endpoint is too far from the surface",
    Status.DIFFERENT_COMPONENTS: "the endpoints lie on different connected "
    "components of the mesh",
    Status.REFINE_FAILED: "the exact method did not converge (no start reached a "
    "locally shortest path within max_iterations flip rounds)",
    Status.INVALID_ENDPOINT: "an endpoint is not a point of the mesh (a vertex or "
    "face index out of range, or a vertex in no face)",
}


class Path(eqx.Module):
    """A polyline on the mesh from point 1 to point 2.

    Buffers have a fixed capacity `M` (static, so that `jax.jit` and `jax.vmap`
    see fixed shapes); the first `count` entries are the path.

    - `points`: `(M, 3)` 3-D points; entries past `count` repeat the last point,
      so `points` can be plotted or summed over without masking.
    - `kinds`: `(M,)` 0 = an endpoint (its face in `elements`, its barycentric
      coordinates in `start` / `end`, wherever it lies in the face's closure),
      1 = a crossing of an edge, 2 = a mesh vertex.
    - `elements`: `(M,)` the face, edge or vertex index of each point.
    - `params`: `(M,)` for edge crossings, the parameter `u` on the edge
      (point = (1 − u)·V[edges[e, 0]] + u·V[edges[e, 1]]); 0 otherwise.
    - `branch`: `(M,)` True where the step to this point had several valid
      crossings ahead: a branch point in the sense of the paper's section 6.
    - `count`; `length`, NaN when the path failed (never a number an optimiser
      could minimise; its gradient there is zero); `status`, a `Status` code as
      an integer array (`Status(int(path.status))`, or `outcome` /
      `outcomes`, reads it).
    - `stats`: the method's diagnostics, a dict of arrays (as optimistix's
      `Solution.stats`): for `"exact"` the flip rounds (`iterations`) and `flips`
      of the winning start, `starts` refined and `starts_converged`, the final
      `corridor_length` in faces, `outgrew` (a corridor outgrew its capacity)
      and `certified` (1: globally shortest, on a disc with no cone vertex or
      an annulus with none at most half its systole, see `jaxgeo.exact`); for
      `"laser"` the `branch_points`; for `"smooth"` the exact method's, and of
      the smooth solve the strip `repair_rounds` and `releases`, whether the
      Newton solve `converged`, its final projected `grad_norm` and its
      `newton_iterations` (meaningless in a row whose exact path failed: its
      status says so).
    - `start`, `end`: the two endpoints as `SurfacePoint`s (face and barycentric
      coordinates; leading axes B in a batch), as located from what was given:
      `start.position(mesh)` is `points[0]` and `end.position(mesh)` is
      `points[count - 1]` (the smooth method's end nodes are these points
      lifted onto the Phong surface, which meets the mesh at its vertices
      only). Differentiable as the endpoints were (a 3-D
      endpoint through `locate`). A row that failed `INVALID_ENDPOINT` keeps
      what was given (it may name no face of the mesh). `None` only on a `Path`
      built by hand or by a method's internals; every result of
      `shortest_path`, `shortest_paths` and `solve` has them.
    """

    # (leading axes B in a batch of paths, `shortest_paths`' and the solver's)
    points: Float[Array, "*B M 3"]
    kinds: Int[Array, "*B M"]
    elements: Int[Array, "*B M"]
    params: Float[Array, "*B M"]
    branch: Bool[Array, "*B M"]
    count: Int[Array, "*B"]
    length: Float[Array, "*B"]
    status: Int[Array, "*B"]
    stats: dict[str, Shaped[Array, "*B"]] | None = None
    start: SurfacePoint | None = None
    end: SurfacePoint | None = None

    @property
    def ok(self) -> Bool[Array, "*B"]:
        return self.status == Status.SUCCESS

    @property
    def n_branch_points(self) -> Int[Array, ""]:
        return jnp.sum(self.branch)

    def surface_points(self, mesh: Mesh) -> SurfacePoint:
        """The path's nodes as one `SurfacePoint` with leading axes `(*B, M)`: a
        vertex node as `SurfacePoint.vertex`, an edge crossing as
        `SurfacePoint.on_edge(mesh, element, param)`, the endpoints as `start`
        and `end`; entries past `count` repeat the last node, as `points` does.
        So `surface_points(mesh).position(mesh)` is `points` (to rounding; for
        the smooth method, whose points lie on the Phong surface, it is where on
        the mesh each node is), and `.element(mesh)` reads back
        `(kinds, elements, params)` with the endpoints' own elements. Works
        under `jax.jit` and `jax.vmap`; differentiable in `params` and the
        endpoints' coordinates."""
        if self.start is None or self.end is None:
            raise JaxgeoError(
                "surface_points needs the path's endpoints (start, end): trace it "
                "with shortest_path, shortest_paths or solve"
            )
        m = self.kinds.shape[-1]
        node = jnp.minimum(jnp.arange(m), jnp.maximum(self.count[..., None] - 1, 0))
        kinds, elements, params = (
            jnp.take_along_axis(x, node, axis=-1)
            for x in (self.kinds, self.elements, self.params)
        )

        def on_mesh(kind, element, param):
            v = SurfacePoint.vertex(mesh, element)
            e = SurfacePoint.on_edge(mesh, element, param)
            vertex = kind == VERTEX
            bary = jnp.where(vertex, jnp.asarray(v.bary), jnp.asarray(e.bary))
            return jnp.where(vertex, v.face, e.face), bary

        flat = jax.vmap(on_mesh)(*(x.reshape(-1) for x in (kinds, elements, params)))
        face, bary = flat[0].reshape(kinds.shape), flat[1].reshape(*kinds.shape, 3)
        # the endpoints' faces and coordinates along the nodes: node 0 is the
        # start, any other endpoint node the end
        first = jnp.arange(m) == 0
        ends = [jnp.asarray(p.face)[..., None] for p in (self.start, self.end)]
        end_face = jnp.where(first, *jnp.broadcast_arrays(*ends))
        ends = [
            jnp.asarray(p.bary, bary.dtype)[..., None, :]
            for p in (self.start, self.end)
        ]
        end_bary = jnp.where(first[:, None], *jnp.broadcast_arrays(*ends))
        endpoint = kinds == FACE
        return SurfacePoint(
            jnp.where(endpoint, end_face, face).astype(jnp.int32),
            jnp.where(endpoint[..., None], end_bary, bary),
        )

    def polyline(self) -> np.ndarray:
        """The path's points as a numpy array `(count, 3)` (not jit-able). On a
        batch, `polylines()` gives one per row."""
        if _batch_size(self) is not None:
            raise JaxgeoError(
                f"polyline() is for a single path; this is a batch of "
                f"{_batch_size(self)} paths: use paths.polylines() (a list of "
                "(count_i, 3) arrays) or paths[i].polyline()"
            )
        return np.asarray(self.points)[: _concrete_int(self.count, "polyline()")]

    def polylines(self) -> list[np.ndarray]:
        """The points of every row of a batch, a list of `(count_i, 3)` numpy
        arrays (rows that failed included: check `status`); a single path gives a
        list of one."""
        if _batch_size(self) is None:
            return [self.polyline()]
        return [row.polyline() for row in self]

    @property
    def outcome(self) -> Status:
        """How the trace ended, as a `Status` (`.name`, `.message`); `status` holds
        the same as an integer array. A single, concrete path only: under
        `jax.jit` compare `path.status == Status.SUCCESS`."""
        if _batch_size(self) is not None:
            raise JaxgeoError(
                "outcome is for a single path; for a batch use paths.outcomes "
                "(a list of Status) or paths.status"
            )
        return Status(_concrete_int(self.status, "outcome"))

    @property
    def outcomes(self) -> list[Status]:
        """How every row of a batch ended, a list of `Status` (a single path gives
        a list of one)."""
        if _batch_size(self) is None:
            return [self.outcome]
        return [Status(_concrete_int(s, "outcomes")) for s in self.status]

    def __bool__(self) -> bool:
        # without this, `if path:` would call __len__ and fail on a single path
        return True

    def __len__(self) -> int:
        """The batch size (rows of a `shortest_paths` result)."""
        n = _batch_size(self)
        if n is None:
            raise TypeError("len() of a single Path: only batches have rows")
        return n

    def __getitem__(self, i) -> Path:
        """Row `i` of a batch as a single `Path` (an index array or slice gives a
        smaller batch)."""
        n = _batch_size(self)
        if n is None:
            raise JaxgeoError(
                "a single Path has no rows; indexing is for shortest_paths results"
            )
        if isinstance(i, (int, np.integer)) and not -n <= i < n:
            raise IndexError(f"row {i} out of range for a batch of {n} paths")
        return jax.tree.map(lambda x: x[i], self)

    def __iter__(self) -> Iterator[Path]:
        """The rows of a batch, each a single `Path`."""
        for i in range(len(self)):
            yield self[i]


def polyline_length(
    points: Float[Array, "M 3"], count: Int[Array, ""]
) -> Float[Array, ""]:
    """Length of the first `count` points of a padded polyline (safe at repeated
    points: no NaN gradient)."""
    seg = safe_norm(points[1:] - points[:-1])
    live = jnp.arange(1, points.shape[0]) < count
    return jnp.sum(jnp.where(live, seg, 0.0))


def pad_tail(points: Float[Array, "M 3"], count: Int[Array, ""]) -> Float[Array, "M 3"]:
    """Repeat the last live point into the unused part of the buffer."""
    idx = jnp.minimum(jnp.arange(points.shape[0]), jnp.maximum(count - 1, 0))
    return points[idx]


def _batch_size(path: Path) -> int | None:
    """Rows of a batched path (leading axis of `count`), None for a single path."""
    shape = np.shape(path.count)
    return shape[0] if len(shape) == 1 else None


def _concrete_int(x, what: str) -> int:
    try:
        return int(x)
    except (
        jax.errors.ConcretizationTypeError,
        jax.errors.TracerIntegerConversionError,
    ):
        raise JaxgeoError(
            f"{what} needs a concrete path, not one traced under jax.jit/vmap; "
            "inside a transformation use the arrays (status, count, points)"
        ) from None
