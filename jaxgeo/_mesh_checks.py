"""The numpy checks a `Mesh` validates its input by, shared with `repair_mesh`
(which removes what they refuse, by the same criteria) and with the vertex merge
of `jaxgeo.loading` (which never merges into a mesh they refuse).

Each `check_*` raises `JaxgeoError` naming the problem and the offending indices
(`fail`); each `*_mask` finds what a check refuses.
"""

from __future__ import annotations

from typing import Any, NoReturn

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph  # noqa: F401
from scipy.sparse.csgraph import connected_components

from ._errors import JaxgeoError

#: A face whose area is below this fraction of the square of its longest edge is a
#: needle. For a triangle, area / longest² = h / (2 L), with h its height over the
#: longest edge L, so this rejects faces with h / L < 2e-8 (aspect ratio worse than
#: about 5e7). The unit normal of such a face, computed from a cross product in
#: float64, has a relative error of about eps / (2 · ratio) ≈ 1e-8 = sqrt(eps): below
#: that, Phong normals and crossing parameters lose more than half their digits.
DEGENERATE_AREA_RATIO = 1e-8

#: Below this ratio (a few float64 ulps) the area is zero to rounding: the three
#: vertices are collinear.
_ZERO_AREA_RATIO = 64 * float(np.finfo(np.float64).eps)


def unique_pairs(pairs: np.ndarray, **kwargs) -> Any:  # as np.unique's
    """`np.unique(pairs, axis=0, ...)` for `(N, 2)` non-negative integers, through
    one int64 key per row (a 1-D sort: ~20x faster than sorting rows)."""
    pairs = np.asarray(pairs, dtype=np.int64)
    base = int(pairs.max()) + 1 if pairs.size else 1
    if base > 3_000_000_000:  # base² would overflow int64
        return np.unique(pairs, axis=0, **kwargs)
    out = np.unique(pairs[:, 0] * base + pairs[:, 1], **kwargs)
    first, *rest = out if isinstance(out, tuple) else (out,)
    first = np.stack(np.divmod(first, base), axis=1)
    return (first, *rest) if rest else first


def fail(problem: str, indices: Any = None, *, limit: int = 10) -> NoReturn:
    """Raise `JaxgeoError(problem)`, listing up to `limit` indices (or index pairs
    when `indices` is 2-D)."""
    if indices is not None:
        idx = np.asarray(indices)
        rows = idx.reshape(len(idx), -1) if idx.ndim > 1 else idx.reshape(-1, 1)

        def show(row: np.ndarray) -> str:
            items = ", ".join(str(int(i)) for i in row)
            return items if row.size == 1 else f"({items})"

        shown = ", ".join(show(r) for r in rows[:limit])
        more = f", … ({len(rows)} in all)" if len(rows) > limit else ""
        problem = f"{problem}: {shown}{more}"
    raise JaxgeoError(problem)


def _as_array(x: Any, name: str) -> np.ndarray:
    try:
        return np.asarray(x)
    except Exception as e:  # ragged lists, tracers, objects numpy cannot convert
        raise JaxgeoError(
            f"{name} could not be converted to an array ({type(e).__name__}: {e}); "
            "a Mesh must be built from concrete (V, 3) and (F, 3) arrays, outside "
            "jax.jit (use Mesh.with_vertices to swap in traced vertices)"
        ) from e


def check_arrays(vertices: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    v = _as_array(vertices, "vertices")
    f = _as_array(faces, "faces")
    if v.size == 0 or f.size == 0:
        fail(
            f"empty mesh: vertices of shape {v.shape} and faces of shape {f.shape}; "
            "a mesh needs at least one triangle"
        )
    if v.dtype.kind not in "fiu":
        fail(f"vertices must be a real array of numbers, got dtype {v.dtype}")
    if f.dtype.kind not in "iu":
        fail(f"faces must be an integer array of vertex indices, got dtype {f.dtype}")
    if v.ndim != 2 or v.shape[1] != 3:
        fail(f"vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        fail(f"faces must have shape (F, 3) (triangles only), got {f.shape}")
    if v.dtype == np.float16:
        v = v.astype(np.float32)
    elif v.dtype not in (np.float32, np.float64):  # integers, long double
        v = v.astype(np.float64)
    nan = np.isnan(v).any(axis=1)
    if nan.any():
        fail("vertex coordinates are NaN at vertices", np.flatnonzero(nan))
    inf = np.isinf(v).any(axis=1)
    if inf.any():
        fail("vertex coordinates are infinite at vertices", np.flatnonzero(inf))
    # Squared lengths and cross products must not overflow in the vertex dtype.
    limit = np.sqrt(np.finfo(v.dtype).max) / 64
    huge = np.abs(v).max(axis=1) > limit
    if huge.any():
        fail(
            f"vertex coordinates too large for {v.dtype} (|x| > {limit:.3g}: squared "
            "lengths would overflow) at vertices",
            np.flatnonzero(huge),
        )
    out = (f < 0) | (f >= v.shape[0])
    if out.any():
        fail(
            f"face indices out of range [0, {v.shape[0]}) in faces",
            np.flatnonzero(out.any(axis=1)),
        )
    return v, f.astype(np.int64)


#: How the error messages of problems that `jaxgeo.repair_mesh` fixes point to it.
REPAIR_HINT = "jaxgeo.repair_mesh or load_mesh(path, repair=True) {}"


def repeated_mask(f: np.ndarray) -> np.ndarray:
    """Faces with a vertex repeated within the face."""
    return (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])


def _area_ratio(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Twice each face's area over its longest edge squared (float64)."""
    a, b, c = (v[f[:, i]].astype(np.float64) for i in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest2 = np.max(
        [np.sum((b - a) ** 2, 1), np.sum((c - b) ** 2, 1), np.sum((a - c) ** 2, 1)],
        axis=0,
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(longest2 > 0, area2 / np.where(longest2 > 0, longest2, 1), 0.0)


def degenerate_mask(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Faces that validation refuses as degenerate: a repeated vertex, zero area or
    a needle (area below `DEGENERATE_AREA_RATIO` x longest edge squared)."""
    return repeated_mask(f) | (_area_ratio(v, f) <= 2 * DEGENERATE_AREA_RATIO)


def duplicate_mask(f: np.ndarray) -> np.ndarray:
    """Faces whose three vertices (in any order) another face also has."""
    key = np.sort(f, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return counts[inverse.ravel()] > 1


def check_faces(v: np.ndarray, f: np.ndarray) -> None:
    repeated = repeated_mask(f)
    if repeated.any():
        fail(
            "degenerate faces (a vertex repeated within the face; "
            + REPAIR_HINT.format("removes them")
            + ")",
            np.flatnonzero(repeated),
        )
    ratio = _area_ratio(v, f)
    zero = ratio <= 2 * _ZERO_AREA_RATIO
    if zero.any():
        fail(
            "degenerate faces with zero area (collinear or coincident vertices; "
            + REPAIR_HINT.format("removes them")
            + ")",
            np.flatnonzero(zero),
        )
    needle = ratio <= 2 * DEGENERATE_AREA_RATIO
    if needle.any():
        fail(
            "near-degenerate needle faces (area below "
            f"{DEGENERATE_AREA_RATIO:g} x longest edge squared; "
            + REPAIR_HINT.format("removes them")
            + ")",
            np.flatnonzero(needle),
        )
    dup = duplicate_mask(f)
    if dup.any():
        fail(
            "duplicate faces (the same three vertices; "
            + REPAIR_HINT.format("keeps one of each")
            + ")",
            np.flatnonzero(dup),
        )


def corner_fans(f: np.ndarray) -> np.ndarray:
    """The fan of each corner, `(3F,)` labels: the corners of a vertex are linked
    across each edge through it that has exactly two faces (edges of one face or
    of three and more do not link). Corner `3 * face + i` is corner `i` of `face`.
    """
    n = f.shape[0]
    # half-edge 3 * face + i is the edge opposite corner i: its ends are corners
    # (i + 1) % 3 and (i + 2) % 3 of the face
    face, i = np.divmod(np.arange(3 * n), 3)
    end_a, end_b = 3 * face + (i + 1) % 3, 3 * face + (i + 2) % 3
    va, vb = f.ravel()[end_a], f.ravel()[end_b]
    key = np.sort(np.stack([va, vb], axis=1), axis=1)
    _, inverse, counts = unique_pairs(key, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    # the two half-edges of each two-face edge are consecutive in `order`
    h0, h1 = order[counts[inverse[order]] == 2].reshape(-1, 2).T
    same = va[h0] == va[h1]  # both faces list the edge's ends in the same order
    rows = np.concatenate([end_a[h0], end_b[h0]])
    cols = np.concatenate(
        [np.where(same, end_a[h1], end_b[h1]), np.where(same, end_b[h1], end_a[h1])]
    )
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)), (3 * n, 3 * n))
    return connected_components(graph, directed=False)[1]


def fan_counts(f: np.ndarray, n_vertices: int) -> np.ndarray:
    """How many fans of faces each vertex has (0 for an unused vertex)."""
    fans = unique_pairs(np.stack([f.ravel(), corner_fans(f)], axis=1))[:, 0]
    return np.bincount(fans, minlength=n_vertices)


def check_vertex_fans(f: np.ndarray, n_vertices: int) -> None:
    """Every vertex's faces must form one fan (no bow-tie / non-manifold vertex)."""
    bad = np.flatnonzero(fan_counts(f, n_vertices) > 1)
    if bad.size:
        fail(
            "non-manifold vertices (faces around them form several fans; "
            + REPAIR_HINT.format("splits them into one vertex per fan")
            + ")",
            bad,
        )
