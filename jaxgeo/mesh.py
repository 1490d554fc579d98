"""The `Mesh` pytree: vertices, faces and the connectivity every algorithm needs.

Construction validates its input (in numpy, once, outside any JAX transformation,
by the checks of `jaxgeo._mesh_checks`) and raises `JaxgeoError` naming the
problem. The connectivity arrays are integer leaves, so a `Mesh` passes through
`jax.jit`, `jax.vmap` and `jax.grad` as it is; `Mesh.with_vertices` swaps the
vertex array (for instance for a tracer) without re-validating. Files are read by
`jaxgeo.loading.load_mesh`.
"""

from __future__ import annotations

import warnings
from typing import Any

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph  # noqa: F401
import trimesh
from jaxtyping import Array, ArrayLike, Bool, Float, Int
from scipy.sparse.csgraph import connected_components

from . import _curvature
from ._cuts import annuli, annulus_cuts, annulus_systoles
from ._errors import JaxgeoError
from ._fans import vertex_fans
from ._landmarks import DEFAULT_LANDMARKS, landmark_forests
from ._merge import merge_coincident
from ._mesh_checks import (
    DEGENERATE_AREA_RATIO as DEGENERATE_AREA_RATIO,
    REPAIR_HINT,
    check_arrays,
    check_faces,
    check_vertex_fans,
    fail,
    unique_pairs,
)
from ._numerics import corner_angles, corner_angles_host
from ._padding import SizeClass, class_of, padded
from ._precision import warn_if_x64_disabled
from ._stacklevel import caller_stacklevel


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
    edges, inverse, counts = unique_pairs(key, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    if (counts > 2).any():
        fail(
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
    directed = unique_pairs(half, return_counts=True)[1]
    consistent = not (directed > 1).any()
    face_edges = inverse.reshape(n_faces, 3)
    return edges, edge_faces, face_edges, consistent


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
        fail(
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
        stacklevel=caller_stacklevel(),
    )
    return np.where(flip[:, None], f[:, ::-1], f)


def _certificate_geometry(faces, angles, fans, dtype):
    """Θ(v) and the per-component "no cone vertex" of the certificate
    (`jaxgeo._curvature`), in numpy or JAX as the arguments are; `fans`:
    `(face_component, fan_faces, fan_size, fan_closed)`."""
    face_component, fan_faces, fan_size, fan_closed = fans
    theta = _curvature.angle_sums(faces, angles, fan_size.shape[0])
    tol = _curvature.cone_tolerance(dtype)
    free = _curvature.cone_free(
        face_component, fan_faces, fan_size, fan_closed, theta, tol
    )
    return theta, free


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
    - `edge_cut`: `(E,)` ±1 on the edges of a cut across every annulus
      component, 0 elsewhere: how the exact method tells a path's winding
      (`jaxgeo._cuts`).
    - `corner_angles`: `(F, 3)` the angle of every face at each corner, which
      the exact method's flips and starts read (computed here and by
      `with_vertices` rather than per query: 1.7 ms of a 12 ms path on a 20k-face
      mesh). Change the vertices with `with_vertices`, which recomputes it.
    - `vertex_angle_sums`: `(V,)` Θ(v), the sum of the face angles at each
      vertex; `component_cone_free`, `component_disc`, `component_annulus`:
      `(F,)` per component label, whether it has no interior cone vertex
      (Θ < 2π), is a disc, or is an annulus with a cut: the facts of the exact
      method's certificate (`jaxgeo._curvature`; scatters over the whole mesh
      when computed per query). `with_vertices` recomputes the first two.
    - `component_systole`: `(F,)` per component label, a lower bound of the
      length of every closed curve winding round it where it is an annulus, 0
      elsewhere (`jaxgeo._cuts`): the exact method certifies a path at most half
      as long globally shortest. `with_vertices` recomputes it (0, no bound,
      for traced vertices).

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
    edge_cut: Int[Array, " E"]
    corner_angles: Float[Array, "F 3"]
    vertex_angle_sums: Float[Array, " V"]
    component_cone_free: Bool[Array, " F"]
    component_disc: Bool[Array, " F"]
    component_annulus: Bool[Array, " F"]
    component_systole: Float[Array, " F"]

    def __init__(
        self, vertices: Any, faces: Any, *, landmarks: int = DEFAULT_LANDMARKS
    ):
        v, f = check_arrays(vertices, faces)
        warn_if_x64_disabled(v)
        check_faces(v, f)
        edges, edge_faces, face_edges, consistent = _edges(f)
        check_vertex_fans(f, v.shape[0])
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
        vertex_component = np.asarray(
            _curvature.vertex_component(component, fans["fan_faces"], fans["fan_size"])
        )
        forests = landmark_forests(
            v, f, edges, face_edges, vertex_component, max(int(landmarks), 1)
        )
        self.landmark_pred_vertex = jnp.asarray(forests["pred_vertex"])
        self.landmark_pred_edge = jnp.asarray(forests["pred_edge"])
        self.landmark_dist = jnp.asarray(forests["dist_vertex"])
        rings = annuli(edges, edge_faces, component, vertex_component)
        cuts = annulus_cuts(v, f, edges, edge_faces, rings)
        self.edge_cut = jnp.asarray(cuts, jnp.int32)
        angles = corner_angles_host(v, f)
        self.corner_angles = jnp.asarray(angles, v.dtype)
        fan_arrays = tuple(fans[k] for k in ("fan_faces", "fan_size", "fan_closed"))
        theta, free = _certificate_geometry(
            f, angles, (component, *fan_arrays), v.dtype
        )
        self.vertex_angle_sums = jnp.asarray(theta, v.dtype)
        self.component_cone_free = jnp.asarray(free)
        disc, annulus = _curvature.discs_and_annuli(
            component, vertex_component, edge_faces, cuts
        )
        self.component_disc = jnp.asarray(disc)
        self.component_annulus = jnp.asarray(annulus)
        self.component_systole = jnp.asarray(
            annulus_systoles(v, edges, rings, f.shape[0]), v.dtype
        )

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

    def with_vertices(self, vertices: Float[ArrayLike, "V 3"]) -> Mesh:
        """The same connectivity with new vertex positions (no re-validation), for
        instance a tracer under `jax.grad`."""
        if jnp.shape(vertices) != self.vertices.shape:
            fail(
                f"with_vertices: expected shape {self.vertices.shape}, "
                f"got {jnp.shape(vertices)}"
            )
        vertices = jnp.asarray(vertices)
        fans = (self.face_component, self.fan_faces, self.fan_size, self.fan_closed)
        # (no systole bound for traced vertices: the exact method then runs the
        # other windings' starts, as without a certificate)
        systole = jnp.zeros_like(self.component_systole)
        if not jnp.issubdtype(vertices.dtype, jnp.floating):
            # (refused where the mesh is used: `_checks.check_mesh_vertices`)
            angles = jnp.full_like(self.corner_angles, jnp.nan)
            theta = jnp.full_like(self.vertex_angle_sums, jnp.nan)
            free = self.component_cone_free
        elif isinstance(vertices, jax.core.Tracer):
            angles = corner_angles(vertices, self.faces)
            theta, free = _certificate_geometry(
                self.faces, jax.lax.stop_gradient(angles), fans, vertices.dtype
            )
        else:
            faces = np.asarray(self.faces)
            host = corner_angles_host(np.asarray(vertices), faces)
            theta, free = _certificate_geometry(
                faces, host, tuple(np.asarray(x) for x in fans), vertices.dtype
            )
            angles = jnp.asarray(host, vertices.dtype)
            component, edges = np.asarray(self.face_component), np.asarray(self.edges)
            labels = np.asarray(
                _curvature.vertex_component(
                    component, np.asarray(self.fan_faces), np.asarray(self.fan_size)
                )
            )
            rings = annuli(edges, np.asarray(self.edge_faces), component, labels)
            systole = annulus_systoles(
                np.asarray(vertices), edges, rings, component.shape[0]
            )
        return eqx.tree_at(
            lambda m: (
                m.vertices,
                m.corner_angles,
                m.vertex_angle_sums,
                m.component_cone_free,
                m.component_systole,
            ),
            self,
            (
                vertices,
                angles,
                jnp.asarray(theta, vertices.dtype),
                jnp.asarray(free),
                jnp.asarray(systole, vertices.dtype),
            ),
        )

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
            v, f, _ = merge_coincident(v, f)
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
