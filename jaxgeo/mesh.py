"""The `Mesh` pytree: vertices, faces and the connectivity every algorithm needs.

Construction validates its input (in numpy, once, outside any JAX transformation)
and raises `JaxgeoError` naming the problem. The connectivity arrays are integer
leaves, so a `Mesh` passes through `jax.jit`, `jax.vmap` and `jax.grad` as it is;
`Mesh.with_vertices` swaps the vertex array (for instance for a tracer) without
re-validating.
"""

from __future__ import annotations

import io
import logging
import os
import re
import sys
import warnings
from typing import Any, Literal, NoReturn

import equinox as eqx
import jax.numpy as jnp
import jaxtyping
import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph  # noqa: F401
import trimesh
from jaxtyping import Array, ArrayLike, Bool, Float, Int
from scipy.sparse.csgraph import connected_components

from ._errors import JaxgeoError
from ._fans import vertex_fans
from ._landmarks import DEFAULT_LANDMARKS, landmark_forests
from ._padding import SizeClass, class_of, padded
from ._precision import warn_if_x64_disabled

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


def _unique_pairs(pairs: np.ndarray, **kwargs) -> Any:  # as np.unique's
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


def _fail(problem: str, indices: Any = None, *, limit: int = 10) -> NoReturn:
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


def _check_arrays(vertices: Any, faces: Any) -> tuple[np.ndarray, np.ndarray]:
    v = _as_array(vertices, "vertices")
    f = _as_array(faces, "faces")
    if v.size == 0 or f.size == 0:
        _fail(
            f"empty mesh: vertices of shape {v.shape} and faces of shape {f.shape}; "
            "a mesh needs at least one triangle"
        )
    if v.dtype.kind not in "fiu":
        _fail(f"vertices must be a real array of numbers, got dtype {v.dtype}")
    if f.dtype.kind not in "iu":
        _fail(f"faces must be an integer array of vertex indices, got dtype {f.dtype}")
    if v.ndim != 2 or v.shape[1] != 3:
        _fail(f"vertices must have shape (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3:
        _fail(f"faces must have shape (F, 3) (triangles only), got {f.shape}")
    if v.dtype == np.float16:
        v = v.astype(np.float32)
    elif v.dtype not in (np.float32, np.float64):  # integers, long double
        v = v.astype(np.float64)
    nan = np.isnan(v).any(axis=1)
    if nan.any():
        _fail("vertex coordinates are NaN at vertices", np.flatnonzero(nan))
    inf = np.isinf(v).any(axis=1)
    if inf.any():
        _fail("vertex coordinates are infinite at vertices", np.flatnonzero(inf))
    # Squared lengths and cross products must not overflow in the vertex dtype.
    limit = np.sqrt(np.finfo(v.dtype).max) / 64
    huge = np.abs(v).max(axis=1) > limit
    if huge.any():
        _fail(
            f"vertex coordinates too large for {v.dtype} (|x| > {limit:.3g}: squared "
            "lengths would overflow) at vertices",
            np.flatnonzero(huge),
        )
    out = (f < 0) | (f >= v.shape[0])
    if out.any():
        _fail(
            f"face indices out of range [0, {v.shape[0]}) in faces",
            np.flatnonzero(out.any(axis=1)),
        )
    return v, f.astype(np.int64)


#: How the error messages of problems that `jaxgeo.repair_mesh` fixes point to it.
REPAIR_HINT = "jaxgeo.repair_mesh or load_mesh(path, repair=True) {}"


def _repeated_mask(f: np.ndarray) -> np.ndarray:
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


def _degenerate_mask(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Faces that validation refuses as degenerate: a repeated vertex, zero area or
    a needle (area below `DEGENERATE_AREA_RATIO` x longest edge squared)."""
    return _repeated_mask(f) | (_area_ratio(v, f) <= 2 * DEGENERATE_AREA_RATIO)


def _duplicate_mask(f: np.ndarray) -> np.ndarray:
    """Faces whose three vertices (in any order) another face also has."""
    key = np.sort(f, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return counts[inverse.ravel()] > 1


def _check_faces(v: np.ndarray, f: np.ndarray) -> None:
    repeated = _repeated_mask(f)
    if repeated.any():
        _fail(
            "degenerate faces (a vertex repeated within the face; "
            + REPAIR_HINT.format("removes them")
            + ")",
            np.flatnonzero(repeated),
        )
    ratio = _area_ratio(v, f)
    zero = ratio <= 2 * _ZERO_AREA_RATIO
    if zero.any():
        _fail(
            "degenerate faces with zero area (collinear or coincident vertices; "
            + REPAIR_HINT.format("removes them")
            + ")",
            np.flatnonzero(zero),
        )
    needle = ratio <= 2 * DEGENERATE_AREA_RATIO
    if needle.any():
        _fail(
            "near-degenerate needle faces (area below "
            f"{DEGENERATE_AREA_RATIO:g} x longest edge squared; "
            + REPAIR_HINT.format("removes them")
            + ")",
            np.flatnonzero(needle),
        )
    dup = _duplicate_mask(f)
    if dup.any():
        _fail(
            "duplicate faces (the same three vertices; "
            + REPAIR_HINT.format("keeps one of each")
            + ")",
            np.flatnonzero(dup),
        )


def _edges(f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Unique edges, edge→faces (−1 on the boundary), face→edges, and whether the
    faces are consistently oriented.

    `face_edges[f, i]` is the edge opposite corner `i` of face `f`, i.e. the edge
    `(faces[f, i+1], faces[f, i+2])`: a barycentric coordinate `b[i] = 0` puts a
    point on edge `face_edges[f, i]`.
    """
    n_faces = f.shape[0]
    half = np.stack([f[:, [1, 2, 0]], f[:, [2, 0, 1]]], axis=-1).reshape(-1, 2)
    key = np.sort(half, axis=1)
    edges, inverse, counts = _unique_pairs(key, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    if (counts > 2).any():
        _fail(
            "non-manifold edges (shared by more than two faces; "
            + REPAIR_HINT.format("removes the smallest of them")
            + ") between vertices",
            edges[counts > 2],
        )
    face_of_half = np.repeat(np.arange(n_faces), 3)
    edge_faces = np.full((edges.shape[0], 2), -1, dtype=np.int64)
    order = np.argsort(inverse, kind="stable")
    sorted_edges = inverse[order]
    first = np.searchsorted(sorted_edges, sorted_edges, side="left")
    slot = np.arange(order.size) - first
    edge_faces[sorted_edges, slot] = face_of_half[order]
    # Orientation: the two faces of an interior edge must run through it in
    # opposite directions.
    directed = _unique_pairs(half, return_counts=True)[1]
    consistent = not (directed > 1).any()
    face_edges = inverse.reshape(n_faces, 3)
    return edges, edge_faces, face_edges, consistent


def _corner_fans(f: np.ndarray) -> np.ndarray:
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
    _, inverse, counts = _unique_pairs(key, return_inverse=True, return_counts=True)
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


def _fan_counts(f: np.ndarray, n_vertices: int) -> np.ndarray:
    """How many fans of faces each vertex has (0 for an unused vertex)."""
    fans = _unique_pairs(np.stack([f.ravel(), _corner_fans(f)], axis=1))[:, 0]
    return np.bincount(fans, minlength=n_vertices)


def _check_vertex_fans(f: np.ndarray, n_vertices: int) -> None:
    """Every vertex's faces must form one fan (no bow-tie / non-manifold vertex)."""
    bad = np.flatnonzero(_fan_counts(f, n_vertices) > 1)
    if bad.size:
        _fail(
            "non-manifold vertices (faces around them form several fans; "
            + REPAIR_HINT.format("splits them into one vertex per fan")
            + ")",
            bad,
        )


def _caller_stacklevel() -> int:
    """The `stacklevel` that points a warning at the first frame outside jaxgeo and
    equinox (whose module machinery wraps `Mesh.__init__`), and outside the type
    checks that jaxtyping's import hook wraps round jaxgeo's functions in tests
    (jaxtyping's frames and beartype's generated `<@beartype(...)>` ones)."""
    here = os.path.dirname(os.path.abspath(__file__))
    internal = tuple(
        os.path.dirname(os.path.abspath(f))
        for f in (__file__, eqx.__file__, jaxtyping.__file__)
    )
    frame, level = sys._getframe(1), 1
    # the frame that calls warnings.warn: our caller, past the checks round us
    while frame is not None and not frame.f_code.co_filename.startswith(here):
        frame = frame.f_back
    while frame is not None and (
        os.path.abspath(frame.f_code.co_filename).startswith(internal)
        or frame.f_code.co_filename.startswith("<@beartype")
    ):
        frame, level = frame.f_back, level + 1
    return level


def _runs_forward(f: np.ndarray, face: np.ndarray, u: np.ndarray, w: np.ndarray):
    """Whether each `face` runs through its edge as u → w (else w → u)."""
    nxt = np.roll(f[face], -1, axis=1)
    return ((f[face] == u[:, None]) & (nxt == w[:, None])).any(axis=1)


def _orient(f: np.ndarray, edges: np.ndarray, edge_faces: np.ndarray) -> np.ndarray:
    """Reorient faces consistently, keeping each component's majority orientation.

    Vectorised on the orientation double cover: node `(face, k)` is the face kept
    (k = 0) or reversed (k = 1). Across an interior edge whose two faces run the
    same way, one of them must be reversed, so `(a, k)` links to `(b, 1 − k)`;
    otherwise `(a, k)` links to `(b, k)`. A component is orientable iff `(f, 0)`
    and `(f, 1)` fall into different connected components of the cover, which
    then come in mirror pairs: keep the one holding more `k = 0` nodes.
    """
    n = f.shape[0]
    inner = edge_faces[:, 1] >= 0
    a, b = edge_faces[inner, 0], edge_faces[inner, 1]
    u, w = edges[inner, 0], edges[inner, 1]
    same = _runs_forward(f, a, u, w) == _runs_forward(f, b, u, w)
    rows = np.concatenate([a, a + n])
    cols = np.concatenate([b + n * same, b + n * (~same)])
    cover = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(2 * n, 2 * n))
    _, label = connected_components(cover, directed=False)
    kept, reversed_ = label[:n], label[n:]
    twisted = kept == reversed_
    if twisted.any():
        _fail(
            "the surface is not orientable (like a Möbius strip): no choice of face "
            "orientations is consistent, on the component(s) of faces",
            np.flatnonzero(twisted),
        )
    # votes[L]: faces whose as-given orientation lies in cover component L; ties go
    # to the mirror holding the lowest-numbered face as given.
    votes = np.bincount(kept, minlength=label.max() + 1)
    lowest = np.full(label.max() + 1, 2 * n)
    np.minimum.at(lowest, label, np.arange(2 * n))
    flip = (votes[reversed_] > votes[kept]) | (
        (votes[reversed_] == votes[kept]) & (lowest[reversed_] < lowest[kept])
    )
    warnings.warn(
        f"{int(flip.sum())} faces were inconsistently oriented and have been "
        "reoriented",
        stacklevel=_caller_stacklevel(),
    )
    return np.where(flip[:, None], f[:, ::-1], f)


def _vertex_faces(f: np.ndarray, n_vertices: int) -> np.ndarray:
    corner_vertex = f.ravel()
    order = np.argsort(corner_vertex, kind="stable")
    valence = np.bincount(corner_vertex, minlength=n_vertices)
    width = max(int(valence.max()), 1)
    start = np.concatenate([[0], np.cumsum(valence)[:-1]])
    slot = np.arange(order.size) - start[corner_vertex[order]]
    out = np.full((n_vertices, width), -1, dtype=np.int64)
    out[corner_vertex[order], slot] = order // 3
    return out


class Mesh(eqx.Module):
    """A validated, consistently oriented, manifold triangle mesh.

    **Arguments:**

    - `vertices`: `(V, 3)` float coordinates (float32 or float64).
    - `faces`: `(F, 3)` integer vertex indices.

    **Attributes** (all arrays, so the mesh is a pytree):

    - `edges`: `(E, 2)` unique edges, vertex indices sorted.
    - `edge_faces`: `(E, 2)` the faces on either side; `-1` on the boundary.
    - `face_edges`: `(F, 3)` the edge opposite each corner of each face.
    - `vertex_faces`: `(V, K)` faces around each vertex, padded with `-1`.
    - `face_component`: `(F,)` connected-component label of each face.
    - `mean_edge_length`: a scalar length scale (tolerances are relative to it).
    - `fan_faces`, `fan_spokes`, `fan_size`, `fan_closed`, `corner_fan_pos`: the
      faces and edges round every vertex in rotational order (`jaxgeo._fans`).
      Read from them, `boundary_next` `(V,)` gives for a boundary vertex the next
      vertex of its boundary loop (the loop runs the way the faces are
      oriented), −1 for any other vertex, and `is_boundary_vertex` is
      `boundary_next >= 0`: the one record of the boundary, which `normals`,
      `trace` and `boundary` read.
    - `landmark_pred_vertex`, `landmark_pred_edge`, `landmark_dist`:
      shortest-path forests of `landmarks` landmark slots on the graph of vertices
      and edge midpoints, from which the exact method reads its starting paths
      (`jaxgeo._landmarks`).

    **Size classes.** The arrays above have the mesh's real sizes. The solvers
    are handed `mesh.padded()`, the same arrays padded to the mesh's
    `size_class`: vertex, face and boundary-edge counts and the fan width rounded
    up to 2^j or 3·2^(j−1) (steps of about √2; edges follow, E = (3F + B)/2),
    with inert padding (never located, crossed, or in a fan). A new mesh of a
    class that was already compiled therefore runs its first path without
    compiling, from memory or from the persistent cache
    (`jaxgeo.enable_compilation_cache`). Results name real faces, edges and
    vertices; gradients are with respect to the real `vertices` (`jaxgeo._padding`).

    **Raises** `JaxgeoError` for wrong shapes or dtypes, an empty mesh, NaN or
    infinite coordinates, out-of-range indices, degenerate or duplicate faces,
    non-manifold edges or vertices, and non-orientable surfaces. Inconsistently
    oriented faces are reoriented with a warning.
    """

    vertices: Float[Array, "V 3"]
    faces: Int[Array, "F 3"]
    edges: Int[Array, "E 2"]
    edge_faces: Int[Array, "E 2"]
    face_edges: Int[Array, "F 3"]
    vertex_faces: Int[Array, "V K"]
    face_component: Int[Array, " F"]
    mean_edge_length: Float[Array, ""]
    fan_faces: Int[Array, "V K"]
    fan_spokes: Int[Array, "V K1"]
    fan_size: Int[Array, " V"]
    fan_closed: Bool[Array, " V"]
    corner_fan_pos: Int[Array, "F 3"]
    landmark_pred_vertex: Int[Array, "M V"]
    landmark_pred_edge: Int[Array, "M E"]
    landmark_dist: Float[Array, "M V"]

    def __init__(
        self, vertices: Any, faces: Any, *, landmarks: int = DEFAULT_LANDMARKS
    ):
        v, f = _check_arrays(vertices, faces)
        warn_if_x64_disabled(v)
        _check_faces(v, f)
        edges, edge_faces, face_edges, consistent = _edges(f)
        _check_vertex_fans(f, v.shape[0])
        if not consistent:
            f = _orient(f, edges, edge_faces)
            edges, edge_faces, face_edges, _ = _edges(f)
        adjacency = sp.coo_matrix(
            (
                np.ones(int((edge_faces[:, 1] >= 0).sum())),
                tuple(edge_faces[edge_faces[:, 1] >= 0].T),
            ),
            shape=(f.shape[0], f.shape[0]),
        )
        _, component = connected_components(adjacency, directed=False)
        lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
        self.vertices = jnp.asarray(v)
        self.faces = jnp.asarray(f, dtype=jnp.int32)
        self.edges = jnp.asarray(edges, dtype=jnp.int32)
        self.edge_faces = jnp.asarray(edge_faces, dtype=jnp.int32)
        self.face_edges = jnp.asarray(face_edges, dtype=jnp.int32)
        self.vertex_faces = jnp.asarray(_vertex_faces(f, v.shape[0]), jnp.int32)
        self.face_component = jnp.asarray(component, dtype=jnp.int32)
        self.mean_edge_length = jnp.asarray(lengths.mean(), dtype=self.vertices.dtype)
        fans = vertex_fans(f, edge_faces, face_edges, v.shape[0])
        self.fan_faces = jnp.asarray(fans["fan_faces"])
        self.fan_spokes = jnp.asarray(fans["fan_spokes"])
        self.fan_size = jnp.asarray(fans["fan_size"])
        self.fan_closed = jnp.asarray(fans["fan_closed"])
        self.corner_fan_pos = jnp.asarray(fans["corner_fan_pos"])
        vertex_component = np.where(
            fans["fan_size"] > 0, component[np.maximum(fans["fan_faces"][:, 0], 0)], -1
        )
        forests = landmark_forests(
            v, f, edges, face_edges, vertex_component, max(int(landmarks), 1)
        )
        self.landmark_pred_vertex = jnp.asarray(forests["pred_vertex"])
        self.landmark_pred_edge = jnp.asarray(forests["pred_edge"])
        self.landmark_dist = jnp.asarray(forests["dist_vertex"])

    @property
    def n_vertices(self) -> int:
        return self.vertices.shape[0]

    @property
    def n_faces(self) -> int:
        return self.faces.shape[0]

    @property
    def n_edges(self) -> int:
        return self.edges.shape[0]

    @property
    def boundary_edges(self) -> Int[Array, " B"]:
        """Indices of the edges with a single face (not jit-able: variable size)."""
        return jnp.flatnonzero(self.edge_faces[:, 1] < 0)

    @property
    def boundary_next(self) -> Int[Array, " V"]:
        """For a boundary vertex the next vertex of its boundary loop, −1 for any
        other (jit-able): the first spoke of an open fan (`jaxgeo._fans`)."""
        return jnp.where(self.fan_closed, -1, self.fan_spokes[:, 0])

    def boundary_next_at(self, v: Int[ArrayLike, "*B"]) -> Int[Array, "*B"]:
        """`boundary_next[v]`, reading only the rows of `v` (for loop bodies)."""
        return jnp.where(self.fan_closed[v], -1, self.fan_spokes[v, 0])

    @property
    def is_boundary_vertex(self) -> Bool[Array, " V"]:
        """Whether each vertex lies on a boundary edge (jit-able)."""
        return self.boundary_next >= 0

    @property
    def size_class(self) -> SizeClass:
        """The padded counts the solvers compile for (see **Size classes**):
        `(vertices, faces, edges, boundary, fan)`."""
        return class_of(self)

    def padded(self) -> Mesh:
        """This mesh with its arrays padded to its `size_class` (what the jitted
        solvers take; cached per mesh; differentiable in `vertices`)."""
        return padded(self)

    def with_vertices(self, vertices: Float[Array, "V 3"]) -> Mesh:
        """The same connectivity with new vertex positions (no re-validation), for
        instance a tracer under `jax.grad`."""
        if jnp.shape(vertices) != self.vertices.shape:
            _fail(
                f"with_vertices: expected shape {self.vertices.shape}, "
                f"got {jnp.shape(vertices)}"
            )
        return eqx.tree_at(lambda m: m.vertices, self, vertices)

    @classmethod
    def from_trimesh(
        cls, mesh: trimesh.Trimesh, *, merge_vertices: bool = False
    ) -> Mesh:
        """Build from a `trimesh.Trimesh`: its vertices and faces as they are, or
        with coincident vertices merged as `load_mesh` does (`merge_vertices`).

        `trimesh.load` keeps vertices apart along texture seams (a textured OBJ):
        such a mesh needs `merge_vertices=True`, or `jaxgeo.load_mesh(path)`."""
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        if merge_vertices and v.ndim == 2 and f.dtype.kind in "iu":
            v, f, _ = _merge_coincident(v, f)
        try:
            return cls(v, f)
        except JaxgeoError as e:
            if merge_vertices or v.ndim != 2 or len(np.unique(v, axis=0)) == len(v):
                raise
            raise JaxgeoError(
                f"{e}; the trimesh has vertices at shared positions (trimesh.load "
                "keeps them apart at texture seams): Mesh.from_trimesh(mesh, "
                "merge_vertices=True) or jaxgeo.load_mesh(path) merges them"
            ) from e

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(
            np.asarray(self.vertices), np.asarray(self.faces), process=False
        )


def load_mesh(
    path: str | os.PathLike,
    *,
    merge_vertices: bool = True,
    repair: bool | Literal["split", "remove"] = False,
) -> Mesh:
    """Read a triangle mesh file (OBJ, PLY, STL, OFF, … anything trimesh reads).

    **Arguments:**

    - `path`: the file; its extension selects the format.
    - `merge_vertices`: merge vertices with bit-identical coordinates (STL stores
      every triangle separately; OBJ files split vertices at texture seams),
      except where merging would make the mesh non-manifold (sheets that touch at
      a point or along an edge, solids that share a face): those vertices are
      kept apart, with a warning naming them. The first occurrence keeps its
      place, so files without duplicates keep their vertex numbering.
    - `repair`: merge every position (when `merge_vertices`), then remove
      degenerate and duplicate faces, separate the faces
      of non-manifold edges and split bow-tie vertices (`jaxgeo.repair_mesh`;
      `"remove"` removes the smallest faces of non-manifold edges instead), with
      a warning saying what changed.

    Polygons (quads, …) are triangulated by trimesh. The result is validated by
    `Mesh`.

    **Raises** `JaxgeoError` naming the file and the problem when the file is
    missing, cannot be parsed, holds less than its header promises (PLY, OFF,
    binary STL) or an OBJ face index 0, holds no triangles, or fails `Mesh`
    validation.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        _fail(f"mesh file not found: {path}")
    if not os.path.isfile(path):
        _fail(f"mesh path is not a file: {path}")
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if not ext:
        _fail(
            f"cannot tell the format of mesh file {path}: it has no extension "
            "(expected .obj, .ply, .stl, .off, …)"
        )
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as e:
        raise JaxgeoError(f"could not read mesh file {path}: {e}") from e
    if not data.strip():
        _fail(f"mesh file {path} is empty")
    if ext == "obj":
        data = _obj_text(_utf8(data), path)
    elif ext == "off":
        data = _utf8(data)
        _check_off_counts(data, path)
    elif ext == "ply":
        _check_ply_counts(data, path)
    elif ext == "stl":
        data = _stl_bytes(data, path)
    trimesh_log = logging.getLogger("trimesh")
    level = trimesh_log.level
    try:
        # trimesh logs (and then swallows or re-raises) parse failures; the
        # JaxgeoError below says the same once.
        trimesh_log.setLevel(logging.CRITICAL)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy warnings on garbage numbers
            loaded = trimesh.load(
                io.BytesIO(data), file_type=ext, force="mesh", process=False
            )
        if not isinstance(loaded, trimesh.Trimesh):
            _fail(f"mesh file {path} holds no triangle mesh")
        vertices = np.asarray(loaded.vertices)
        faces = np.asarray(loaded.faces)
    except JaxgeoError:
        raise
    except Exception as e:  # trimesh raises many types on malformed files
        raise JaxgeoError(
            f"could not read mesh file {path} as {ext.upper()}: {type(e).__name__}: {e}"
        ) from e
    finally:
        trimesh_log.setLevel(level)
    if faces.size == 0:
        _fail(f"mesh file {path} holds no triangles")
    if merge_vertices and vertices.ndim == 2 and faces.dtype.kind in "iu":
        # repair separates what a plain merge joins wrongly, and more (walls)
        vertices, faces, apart = _merge_coincident(vertices, faces, safe=not repair)
        if apart:
            _warn_kept_apart(path, apart)
    try:
        if repair:
            from .repair import repair_mesh

            how = "split" if repair is True else repair
            vertices, faces, report = repair_mesh(
                vertices, faces, nonmanifold=how, warn=False
            )
            if report.changed:
                warnings.warn(
                    f"repaired {path}: {report}", stacklevel=_caller_stacklevel()
                )
        return Mesh(vertices, faces)
    except JaxgeoError as e:
        raise JaxgeoError(f"invalid mesh in {path}: {e}") from e


#: An OBJ face token whose vertex index is 0 (indices start at 1; −1 is the last).
_OBJ_ZERO_INDEX = re.compile(rb"(?m)^f [^\r\n#]*?(?<= )[-+]?0+(?=[ /\r\n#]|$)")


def _obj_text(data: bytes, path: str) -> bytes:
    """An OBJ as trimesh reads it: tabs are spaces and lines lose their leading
    blanks (trimesh reads `v\\t1\\t2\\t3` as nothing); a face index 0 refuses."""
    data = re.sub(rb"(?m)^[ ]+", b"", data.replace(b"\t", b" "))
    bad = _OBJ_ZERO_INDEX.search(data)
    if bad:
        line = data.count(b"\n", 0, bad.start()) + 1
        end = data.find(b"\n", bad.start())
        text = data[bad.start() : None if end < 0 else end]
        text = text.decode("utf-8", "replace").strip()
        n = len(_OBJ_ZERO_INDEX.findall(data))
        _fail(
            f"OBJ file {path} has a face with vertex index 0 on line {line} "
            f"({text!r}; {n} such face(s) in all): OBJ indices start at 1 "
            "(negative ones count back from the last vertex), so the file is "
            "corrupt or was written 0-based"
        )
    return data


def _data_lines(text: bytes) -> list[bytes]:
    """The non-empty lines of `text`, comments (`#` …) removed."""
    lines = (line.split(b"#", 1)[0].strip() for line in text.splitlines())
    return [line for line in lines if line]


def _short_of(path: str, fmt: str, counts: dict[str, int], held: int, unit: str):
    """Refuse a file whose header promises more elements than it holds `held`
    lines (or bytes) for."""
    promised = ", ".join(f"{n} {name}" for name, n in counts.items())
    _fail(
        f"{fmt} file {path} is truncated or its header lies: the header promises "
        f"{promised}, but the file holds {held} {unit} of data after it"
    )


def _check_off_counts(data: bytes, path: str) -> None:
    """An ASCII OFF must hold the vertex and face lines its count line promises
    (trimesh reads a short file's face lines as vertices, or fewer faces)."""
    head = re.search(rb"(?:C|N|ST)?OFF", data)
    if head is None:
        return  # not an OFF: trimesh says so
    lines = _data_lines(data[head.end() :])
    if not lines:
        return
    try:
        nv, nf = (int(x) for x in lines[0].split()[:2])
    except ValueError:
        return  # a malformed count line: trimesh says so
    held = len(lines) - 1
    if held < nv:
        _short_of(path, "OFF", {"vertices": nv}, held, "lines")
    if held < nv + nf:
        _short_of(path, "OFF", {"vertices": nv, "faces": nf}, held, "lines")


#: Bytes of the PLY scalar types.
_PLY_SIZES = {
    **dict.fromkeys([b"char", b"uchar", b"int8", b"uint8"], 1),
    **dict.fromkeys([b"short", b"ushort", b"int16", b"uint16"], 2),
    **dict.fromkeys([b"int", b"uint", b"float", b"int32", b"uint32", b"float32"], 4),
    **dict.fromkeys([b"double", b"float64"], 8),
}


def _check_ply_counts(data: bytes, path: str) -> None:
    """A PLY must hold the elements its header promises: one line each in ASCII;
    in binary at least their bytes (a list of face indices: 3 or more each)."""
    end = re.search(rb"end_header[^\n]*\n", data[:65536])
    if not data.startswith(b"ply") or end is None:
        return  # not a PLY: trimesh says so
    header = _data_lines(data[: end.start()].replace(b"comment", b"#"))
    fmt = next((line.split() for line in header if line.startswith(b"format")), [])
    elements: list[list] = []  # [name, count, bytes per row at least]
    for line in header:
        words = line.split()
        if words[0] == b"element" and len(words) == 3 and words[2].isdigit():
            elements.append([words[1].decode("ascii", "replace"), int(words[2]), 0])
        elif words[0] == b"property" and elements:
            if len(words) >= 5 and words[1] == b"list":
                count, item = _PLY_SIZES.get(words[2]), _PLY_SIZES.get(words[3])
                if count is None or item is None:
                    return  # an unknown type: trimesh says so
                indices = words[4] in (b"vertex_indices", b"vertex_index")
                elements[-1][2] += count + (3 * item if indices else 0)
            elif len(words) >= 3 and words[1] in _PLY_SIZES:
                elements[-1][2] += _PLY_SIZES[words[1]]
            else:
                return
    if not elements:
        return
    counts = {name: n for name, n, _ in elements}
    least = sum(n * size for _, n, size in elements)
    body = data[end.end() :]
    if len(fmt) >= 2 and fmt[1] == b"ascii":
        held = len(_data_lines(body))
        if held < sum(counts.values()):
            _short_of(path, "PLY", counts, held, "lines")
    elif len(body) < least:
        _short_of(path, "PLY", counts, len(body), "bytes")


def _utf8(data: bytes) -> bytes:
    """Text formats as valid UTF-8: undecodable bytes (a Latin-1 comment, binary
    garbage) become U+FFFD, so trimesh never needs to guess the encoding."""
    return data.decode("utf-8", errors="replace").encode("utf-8")


def _stl_bytes(data: bytes, path: str) -> bytes:
    """Check a binary STL's triangle count against its length (84-byte header,
    then 50 bytes per triangle). Two mismatches are harmless and read with a
    warning: a count of 0 over whole triangles (some exporters never fill it in)
    and bytes after the counted triangles; a count the file does not hold is
    refused (the file is truncated, or the count is garbage)."""
    n = len(data)
    count = int.from_bytes(data[80:84], "little") if n >= 84 else -1
    if count >= 0 and n == 84 + 50 * count:
        return data  # a consistent binary STL
    if data.lstrip()[:5].lower() == b"solid":
        return _utf8(data)  # ASCII STL
    if n < 84:
        _fail(
            f"mesh file {path} is neither an ASCII STL (no 'solid' keyword) nor a "
            f"binary STL (only {n} bytes, a binary STL header takes 84)"
        )
    if n > 84 + 50 * count > 84:
        warnings.warn(
            f"binary STL {path}: ignoring {n - 84 - 50 * count} bytes after its "
            f"{count} triangles",
            stacklevel=_caller_stacklevel(),
        )
        return data[: 84 + 50 * count]
    held, rest = divmod(n - 84, 50)
    if count == 0 and held > 0 and rest == 0:
        warnings.warn(
            f"binary STL {path}: the header says 0 triangles but the file "
            f"holds {held}; reading {held}",
            stacklevel=_caller_stacklevel(),
        )
        return data[:80] + held.to_bytes(4, "little") + data[84:]
    _fail(
        f"binary STL {path} is truncated or corrupt: its header says {count} "
        f"triangles ({84 + 50 * count} bytes) but the file has {n} bytes"
        + (f" ({held} whole triangles)" if rest == 0 else "")
    )
    raise AssertionError  # unreachable: _fail raises


def _problem_vertices(f: np.ndarray, n_vertices: int) -> np.ndarray:
    """Vertices of what validation would refuse in the connectivity alone: faces
    with a repeated vertex, duplicate faces, edges of three or more faces, and
    vertices with several fans. A boolean mask over the vertices."""
    bad = np.zeros(n_vertices, bool)
    bad[f[_repeated_mask(f) | _duplicate_mask(f)].ravel()] = True
    half = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    edges, counts = _unique_pairs(half, return_counts=True)
    bad[edges[counts > 2].ravel()] = True
    bad[_fan_counts(f, n_vertices) > 1] = True
    return bad


def _merge_coincident(
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
        labels = _corner_fans(ids[f])
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


def _warn_kept_apart(path: str, apart: list[np.ndarray]) -> None:
    shown = ", ".join("(" + ", ".join(str(int(i)) for i in g) + ")" for g in apart[:10])
    more = f", … ({len(apart)} in all)" if len(apart) > 10 else ""
    warnings.warn(
        f"{path}: {len(apart)} positions hold several vertices that were kept "
        "apart, since merging them would make the mesh non-manifold (sheets that "
        f"touch at a point or an edge, solids that share a face): vertices {shown}"
        f"{more}. A 3-D endpoint there is ambiguous: pass a jaxgeo.SurfacePoint "
        "on the intended side",
        stacklevel=_caller_stacklevel(),
    )
