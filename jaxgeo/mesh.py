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
import sys
import warnings
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph  # noqa: F401
import trimesh
from jaxtyping import Array, Float, Int
from scipy.sparse.csgraph import connected_components

from ._errors import JaxgeoError
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


def _fail(problem: str, indices: Any = None, *, limit: int = 10) -> None:
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


def _check_faces(v: np.ndarray, f: np.ndarray) -> None:
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    if repeated.any():
        _fail(
            "degenerate faces (a vertex repeated within the face)",
            np.flatnonzero(repeated),
        )
    a, b, c = (v[f[:, i]].astype(np.float64) for i in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)  # twice the area
    longest2 = np.max(
        [np.sum((b - a) ** 2, 1), np.sum((c - b) ** 2, 1), np.sum((a - c) ** 2, 1)],
        axis=0,
    )
    zero = area2 <= 2 * _ZERO_AREA_RATIO * longest2
    if zero.any():
        _fail(
            "degenerate faces with zero area (collinear or coincident vertices)",
            np.flatnonzero(zero),
        )
    needle = area2 <= 2 * DEGENERATE_AREA_RATIO * longest2
    if needle.any():
        _fail(
            "near-degenerate needle faces (area below "
            f"{DEGENERATE_AREA_RATIO:g} x longest edge squared)",
            np.flatnonzero(needle),
        )
    key = np.sort(f, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    dup = counts[inverse.ravel()] > 1
    if dup.any():
        _fail("duplicate faces (the same three vertices)", np.flatnonzero(dup))


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
    edges, inverse, counts = np.unique(
        key, axis=0, return_inverse=True, return_counts=True
    )
    inverse = inverse.ravel()
    if (counts > 2).any():
        _fail(
            "non-manifold edges (shared by more than two faces) between vertices",
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
    directed = np.unique(half, axis=0, return_counts=True)[1]
    consistent = not (directed > 1).any()
    face_edges = inverse.reshape(n_faces, 3)
    return edges, edge_faces, face_edges, consistent


def _check_vertex_fans(
    f: np.ndarray, edges: np.ndarray, edge_faces: np.ndarray, n_vertices: int
) -> None:
    """Every vertex's faces must form one fan (no bow-tie / non-manifold vertex).

    The corners of a vertex are linked across each interior edge through it; a
    vertex whose corners fall into more than one connected group is non-manifold.
    """
    inner = edge_faces[:, 1] >= 0
    fa, fb = edge_faces[inner, 0], edge_faces[inner, 1]
    rows, cols = [], []
    for end in (0, 1):
        vert = edges[inner, end]
        rows.append(3 * fa + np.argmax(f[fa] == vert[:, None], axis=1))
        cols.append(3 * fb + np.argmax(f[fb] == vert[:, None], axis=1))
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    n_corners = 3 * f.shape[0]
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)), (n_corners, n_corners))
    _, labels = connected_components(graph, directed=False)
    # one (vertex, label) pair per fan
    fans = np.unique(np.stack([f.ravel(), labels]), axis=1)[0]
    bad = np.flatnonzero(np.bincount(fans, minlength=n_vertices) > 1)
    if bad.size:
        _fail("non-manifold vertices (faces around them form several fans)", bad)


def _caller_stacklevel() -> int:
    """The `stacklevel` that points a warning at the first frame outside jaxgeo and
    equinox (whose module machinery wraps `Mesh.__init__`)."""
    here = os.path.dirname(os.path.abspath(__file__))
    internal = (here, os.path.dirname(os.path.abspath(eqx.__file__)))
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(
        internal
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

    def __init__(self, vertices: Any, faces: Any):
        v, f = _check_arrays(vertices, faces)
        warn_if_x64_disabled(v)
        _check_faces(v, f)
        edges, edge_faces, face_edges, consistent = _edges(f)
        _check_vertex_fans(f, edges, edge_faces, v.shape[0])
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
    def from_trimesh(cls, mesh: trimesh.Trimesh) -> Mesh:
        """Build from a `trimesh.Trimesh` (its vertices and faces as they are)."""
        return cls(np.asarray(mesh.vertices), np.asarray(mesh.faces))

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(
            np.asarray(self.vertices), np.asarray(self.faces), process=False
        )


def load_mesh(path: str | os.PathLike, *, merge_vertices: bool = True) -> Mesh:
    """Read a triangle mesh file (OBJ, PLY, STL, OFF, … anything trimesh reads).

    **Arguments:**

    - `path`: the file; its extension selects the format.
    - `merge_vertices`: merge vertices with bit-identical coordinates (STL stores
      every triangle separately; OBJ files split vertices at texture seams). The
      first occurrence keeps its place, so files without duplicates keep their
      vertex numbering.

    Polygons (quads, …) are triangulated by trimesh. The result is validated by
    `Mesh`.

    **Raises** `JaxgeoError` naming the file and the problem when the file is
    missing, cannot be parsed, holds no triangles, or fails `Mesh` validation.
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
    if ext in ("obj", "off"):
        data = _utf8(data)
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
        vertices, faces = _merge_identical(vertices, faces)
    try:
        return Mesh(vertices, faces)
    except JaxgeoError as e:
        raise JaxgeoError(f"invalid mesh in {path}: {e}") from e


def _utf8(data: bytes) -> bytes:
    """Text formats as valid UTF-8: undecodable bytes (a Latin-1 comment, binary
    garbage) become U+FFFD, so trimesh never needs to guess the encoding."""
    return data.decode("utf-8", errors="replace").encode("utf-8")


def _stl_bytes(data: bytes, path: str) -> bytes:
    """Check a binary STL's triangle count against its length (84-byte header,
    then 50 bytes per triangle) and repair the two harmless mismatches: a wrong
    count over a whole number of triangles, and trailing bytes after them."""
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
    if (n - 84) % 50 == 0 and n > 84:
        held = (n - 84) // 50
        warnings.warn(
            f"binary STL {path}: the header says {count} triangles but the file "
            f"holds {held}; reading {held}",
            stacklevel=_caller_stacklevel(),
        )
        return data[:80] + held.to_bytes(4, "little") + data[84:]
    _fail(
        f"binary STL {path} is truncated or corrupt: its header says {count} "
        f"triangles ({84 + 50 * count} bytes) but the file has {n} bytes"
    )
    raise AssertionError  # unreachable: _fail raises


def _merge_identical(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices with equal coordinates; the first occurrence keeps its place.

    Faces indexing a vertex that does not exist are left for `Mesh` to report."""
    key = v + 0.0  # −0.0 → +0.0, so both merge
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if first.size == v.shape[0]:
        return v, f
    # renumber the unique vertices in order of first occurrence
    rank = np.empty(first.size, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size)
    remap = rank[inverse]
    inside = (f >= 0) & (f < v.shape[0])
    f = np.where(inside, remap[np.clip(f, 0, v.shape[0] - 1)], -1 - np.abs(f))
    return v[np.sort(first)], f
