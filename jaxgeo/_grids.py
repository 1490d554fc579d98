"""The triangulation of a rectangular vertex grid, shared by the built-in surfaces
(`surfaces.saddle`) and the form-found sail (`formfinding.four_point_sail`), so
that neither imports the other for it."""

from __future__ import annotations

import numpy as np

__all__ = ["grid_faces"]


def grid_faces(nx: int, ny: int) -> np.ndarray:
    """Faces of a `(nx + 1) × (ny + 1)` vertex grid (index `a*(ny + 1) + b`), each
    cell split along alternating diagonals, counter-clockwise in (a, b)."""
    a, b = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a, b = a.ravel(), b.ravel()
    v00 = a * (ny + 1) + b
    v10 = v00 + (ny + 1)
    v01 = v00 + 1
    v11 = v10 + 1
    even = (a + b) % 2 == 0
    t1 = np.where(
        even[:, None], np.stack([v00, v10, v11], 1), np.stack([v00, v10, v01], 1)
    )
    t2 = np.where(
        even[:, None], np.stack([v00, v11, v01], 1), np.stack([v10, v11, v01], 1)
    )
    return np.concatenate([t1, t2]).astype(np.int64)
