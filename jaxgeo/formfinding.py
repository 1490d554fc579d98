"""Form finding by the force density method (Schek 1974).

A net of nodes joined by edges, each edge with a force density `q = force /
length`; some nodes fixed. Equilibrium of every free node without load,
`Σ_j q_ij (x_j − x_i) = 0`, is linear in the coordinates (Schek 1974, eq. 2.6):

    D_f x_f = −D_x x_x,    D = Cᵀ Q C,

`C` the edge-node incidence matrix split into free (`f`) and fixed (`x`)
columns, `Q = diag(q)`. One sparse solve (scipy) per coordinate.

**Four-point sail**: an `(n + 1) × (n + 1)` quad net on the unit square, its
four corners fixed at alternately high and low points (a hyperbolic paraboloid
when the net is uniform), boundary edges are edge cables with density
`q_cable`, the rest membrane with `q_membrane`. A larger cable density pulls the
edges straighter; a smaller one lets them sag inwards, as sails are built. The
quads are split along alternating diagonals into the triangle mesh (the
diagonals carry no force).

H.-J. Schek, *The force density method for form finding and computation of
general networks*, Computer Methods in Applied Mechanics and Engineering 3
(1974) 115–134.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jaxtyping import Float, Int

from ._errors import JaxgeoError
from ._grids import grid_faces

__all__ = ["Sail", "force_density", "four_point_sail"]


def force_density(
    edges: Int[np.ndarray, "E 2"],
    q: Float[np.ndarray, " E"],
    fixed: Int[np.ndarray, " K"],
    fixed_xyz: Float[np.ndarray, "K 3"],
    n_nodes: int,
) -> Float[np.ndarray, "N 3"]:
    """Node positions in equilibrium (module docstring): `edges` node pairs,
    `q` their force densities (> 0), `fixed` node ids held at `fixed_xyz`."""
    edges = np.asarray(edges)
    q = np.asarray(q, float)
    if np.any(~np.isfinite(q)) or np.any(q <= 0):
        raise JaxgeoError("force densities must be positive and finite")
    m = len(edges)
    rows = np.repeat(np.arange(m), 2)
    c = sp.csr_matrix(
        (np.tile([1.0, -1.0], m), (rows, edges.ravel())), shape=(m, n_nodes)
    )
    d = (c.T @ sp.diags(q) @ c).tocsr()
    free = np.setdiff1d(np.arange(n_nodes), fixed)
    dff = d[free][:, free].tocsc()
    rhs = -(d[free][:, fixed] @ np.asarray(fixed_xyz, float))
    x = np.empty((n_nodes, 3))
    x[fixed] = fixed_xyz
    solve = spla.factorized(dff)
    for k in range(3):
        x[free, k] = solve(rhs[:, k])
    return x


@dataclasses.dataclass
class Sail:
    """A form-found four-point sail: triangle mesh `vertices`, `faces`, and the
    vertex ids of its four edge `cables` (corner to corner, named
    `"south"`, `"east"`, `"north"`, `"west"`)."""

    vertices: np.ndarray
    faces: np.ndarray
    cables: dict[str, np.ndarray]

    def cable_polyline(self, name: str) -> np.ndarray:
        return self.vertices[self.cables[name]]


def four_point_sail(
    n: int = 16,
    span: float = 6.0,
    high: float = 2.0,
    low: float = 0.0,
    q_cable: float = 6.0,
    q_membrane: float = 1.0,
) -> Sail:
    """A four-point sail over the square `[0, span]²` in plan, corners at
    `(0,0)` and `(span, span)` at height `low`, the other two at `high`; the
    net form-found with edge-cable density `q_cable` and membrane density
    `q_membrane` (module docstring). `2n²` faces."""
    if n < 2:
        raise JaxgeoError("four_point_sail needs n >= 2")
    if not span > 0 or not high > low:
        raise JaxgeoError("four_point_sail needs span > 0 and high > low")
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    horiz = np.stack([idx[:-1, :].ravel(), idx[1:, :].ravel()], 1)
    vert = np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1)
    edges = np.concatenate([horiz, vert])
    on_side = lambda e: (  # noqa: E731
        np.isin(e, np.r_[idx[0], idx[-1], idx[:, 0], idx[:, -1]]).all(axis=1)
    )
    a, b = edges[:, 0] // (n + 1), edges[:, 0] % (n + 1)
    a2, b2 = edges[:, 1] // (n + 1), edges[:, 1] % (n + 1)
    same_side = ((a == a2) & ((a == 0) | (a == n))) | (
        (b == b2) & ((b == 0) | (b == n))
    )
    cable = on_side(edges) & same_side
    q = np.where(cable, q_cable, q_membrane)
    corners = np.array([idx[0, 0], idx[n, 0], idx[n, n], idx[0, n]])
    xyz = np.array(
        [[0, 0, low], [span, 0, high], [span, span, low], [0, span, high]], float
    )
    v = force_density(edges, q, corners, xyz, (n + 1) ** 2)
    f = grid_faces(n, n)
    # orient up: the first face's normal should have a positive z component
    p = v[f[0]]
    if np.cross(p[1] - p[0], p[2] - p[0])[2] < 0:
        f = f[:, ::-1]
    cables = {
        "south": idx[:, 0],
        "east": idx[n, :],
        "north": idx[::-1, n],
        "west": idx[0, ::-1],
    }
    return Sail(v, f, cables)
