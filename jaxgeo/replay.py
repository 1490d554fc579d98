"""Replay: the crossings of a traced path recomputed, differentiably, on its fixed
sequence of edges and vertices.

The trace makes discrete choices (which edge comes next) and is not differentiated.
The replay walks the same sequence with `lax.scan`: each edge crossing is solved
again from System (16), with the chord running from the previous (replayed) point
to point 2, by `optimistix.root_find` with implicit differentiation. Vertex points
are the vertices themselves, endpoints their barycentric combinations. So every
point, and the length, is a differentiable function of the vertices (through the
Phong normals too) and of the endpoints.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .locate import SurfacePoint
from .mesh import Mesh
from .path import EDGE, VERTEX, Path, Status, pad_tail, polyline_length
from .projection import initial_guess, solve_crossing


def replay(
    mesh: Mesh,
    normals: Float[Array, "V 3"],
    start: SurfacePoint,
    end: SurfacePoint,
    traced: Path,
) -> Path:
    """Recompute the points of `traced` as differentiable functions of
    `mesh.vertices`, `normals` and the endpoints. The discrete structure (kinds,
    elements, count, status) is taken from `traced` as it is.

    Where the length is not differentiable (the path touches a vertex, or a
    perturbation would change the edge sequence) the result is the one-sided
    derivative for the current sequence: finite, never NaN.
    """
    traced = jax.lax.stop_gradient(traced)
    verts, edges = mesh.vertices, mesh.edges
    p1, p2 = start.position(mesh), end.position(mesh)
    last = traced.count - 1
    # Only a complete path ends at point 2; an incomplete one (MAX_STEPS,
    # NO_CROSSING) ends at its last crossing, which is replayed like the others.
    complete = traced.status == Status.SUCCESS

    def body(prev, slot):
        i, kind, element, u0 = slot
        edge = jnp.where(kind == EDGE, element, 0)
        e0, e1 = edges[edge, 0], edges[edge, 1]
        x1, x2, n1, n2 = verts[e0], verts[e1], normals[e0], normals[e1]
        is_end = (i == last) & complete
        is_edge = (kind == EDGE) & (i <= last) & ~is_end
        y0 = jax.lax.stop_gradient(initial_guess(prev, p2, x1, x2, n1, n2, u0))
        y0 = jnp.where(jnp.isfinite(y0), y0, 0.0)
        y, _ = solve_crossing(prev, p2, x1, x2, n1, n2, y0, is_edge)
        crossing = x1 + y[0] * (x2 - x1)
        vertex = verts[jnp.where(kind == VERTEX, element, 0)]
        point = jnp.where(is_end, p2, jnp.where(kind == VERTEX, vertex, crossing))
        point = jnp.where(i <= last, point, prev)
        return point, (point, jnp.where(is_edge, y[0], traced.params[i]))

    m = traced.points.shape[0]
    slots = (
        jnp.arange(1, m),
        traced.kinds[1:],
        traced.elements[1:],
        traced.params[1:],
    )
    _, (points, params) = jax.lax.scan(body, p1, slots)
    points = pad_tail(jnp.concatenate([p1[None], points]), traced.count)
    params = jnp.concatenate([traced.params[:1], params])
    return Path(
        points=points,
        kinds=traced.kinds,
        elements=traced.elements,
        params=params,
        branch=traced.branch,
        count=traced.count,
        length=polyline_length(points, traced.count),
        status=traced.status,
    )
