"""Merging vertices at equal positions (what makes an STL or a texture-split OBJ
one surface) without making a mesh that `Mesh` refuses: `merge_coincident`, for
`jaxgeo.loading.load_mesh` and `Mesh.from_trimesh`."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph  # noqa: F401
from scipy.sparse.csgraph import connected_components

from ._mesh_checks import (
    corner_fans,
    duplicate_mask,
    fan_counts,
    repeated_mask,
    unique_pairs,
)


def _problem_vertices(f: np.ndarray, n_vertices: int) -> np.ndarray:
    """Vertices of what validation would refuse in the connectivity alone: faces
    with a repeated vertex, duplicate faces, edges of three or more faces, and
    vertices with several fans. A boolean mask over the vertices."""
    bad = np.zeros(n_vertices, bool)
    bad[f[repeated_mask(f) | duplicate_mask(f)].ravel()] = True
    half = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    edges, counts = unique_pairs(half, return_counts=True)
    bad[edges[counts > 2].ravel()] = True
    bad[fan_counts(f, n_vertices) > 1] = True
    return bad


def merge_coincident(
    v: np.ndarray, f: np.ndarray, *, safe: bool = True
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Merge vertices with equal coordinates, but never into an invalid mesh.

    Merging is what makes an STL (one copy of each corner per triangle) or an OBJ
    split at texture seams one surface; but two sheets that touch at a point or
    along an edge, or two solids that share a face, also have coincident
    vertices, and merging them makes a pinch, an edge of four faces or a doubled
    face. So a position's vertices merge per fan: the copies around each fan of
    faces at the merged vertex become one vertex (the fans linked across
    two-face edges only, as validation does), and fans that share an original
    vertex stay together; positions where the result would still be refused (a
    non-manifold edge, a duplicate face, a pinch) are not merged at all. Each
    resulting vertex is a set of original vertices at one position, numbered by
    its first occurrence, so a file without duplicates keeps its numbering.

    With `safe=False` every position becomes one vertex (for `repair_mesh`, whose
    fan split does the same separation and also joins solids that share a face).

    Returns the vertices, the faces, and the groups of resulting vertices that
    share a position but were kept apart. Files with out-of-range indices are
    returned as they are, for `Mesh` to report.
    """
    n = v.shape[0]
    if f.size == 0 or f.min() < 0 or f.max() >= n:
        return v, f, []
    _, group, sizes = np.unique(
        v + 0.0, axis=0, return_inverse=True, return_counts=True
    )  # + 0.0: −0.0 → +0.0, so both merge
    group = group.ravel()
    if sizes.size == n:
        return v, f, []
    n_groups = sizes.size
    merge = sizes > 1  # positions still allowed to merge
    used = np.zeros(n, bool)
    used[f.ravel()] = True
    lowest = np.full(n_groups, n)
    np.minimum.at(lowest, group, np.arange(n))
    rep = lowest[group]
    while safe:
        # tentative: a merging position is one vertex, any other vertex itself
        ids = np.where(merge[group], group, n_groups + np.arange(n))
        labels = corner_fans(ids[f])
        # fans and original vertices as one graph: a fan links the originals at
        # its corners; each component becomes one vertex
        n_fans = int(labels.max()) + 1
        link = sp.coo_matrix(
            (np.ones(f.size), (labels, n_fans + f.ravel())),
            (n_fans + n, n_fans + n),
        )
        comp = connected_components(link, directed=False)[1][n_fans:]
        rep = np.full(comp.max() + 1, n)
        np.minimum.at(rep, comp, np.arange(n))
        rep = rep[comp]  # lowest original index of each vertex's component
        # unused vertices join the lowest used copy at their position (or each
        # other, when no copy is used), where the position merges
        lowest_used = np.full(n_groups, n)
        np.minimum.at(lowest_used, group[used], rep[used])
        spare = ~used & merge[group]
        rep[spare] = np.where(lowest_used < n, lowest_used, lowest)[group[spare]]
        bad = _problem_vertices(rep[f], n)
        stop = np.zeros(n_groups, bool)
        stop[group[bad]] = True
        stop &= merge & (sizes > 1)
        if not stop.any():
            break
        merge &= ~stop
    keep = np.unique(rep)  # the representatives, in order of first occurrence
    index = np.empty(n, dtype=np.int64)
    index[keep] = np.arange(keep.size)
    out_f = index[rep[f]]
    out_v = v[keep]
    # positions held by several resulting vertices: kept apart
    kept_group = group[keep]
    order = np.argsort(kept_group, kind="stable")
    runs = np.split(order, np.flatnonzero(np.diff(kept_group[order])) + 1)
    return out_v, out_f, [r for r in runs if r.size > 1]
