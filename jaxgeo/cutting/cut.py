"""Cut a mesh along traced seams into cloths.

Every seam is a traced `Path` (edge crossings, vertices, endpoints). Each face a
seam crosses is split: its corners and the seam points on its sides form a convex
polygon, the seam segments are chords of it, the chords split it into convex
pieces, and pieces with more than three corners are fanned from their centroid.
Faces joined across a non-seam edge belong to one cloth (`cut_mesh`). `cut` traces
a `Layout`'s seams and cuts along them. numpy/scipy on the host; the seams'
tracing is JAX.

(Moved here from `jaxgeo.pattern` and `jaxgeo.seams`, which still re-export the
public names.)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Float, Int
from scipy.sparse.csgraph import connected_components

from .._errors import JaxgeoError
from ..locate import SurfacePoint
from ..mesh import Mesh
from ..methods import Method
from ..path import EDGE, VERTEX, Path, Status
from ..trace import TraceOptions
from .layout import Layout, trace_seams

__all__ = ["SNAP", "CutMesh", "LegacySeam", "cut", "cut_mesh", "edge_table"]

#: Seam points closer than this (edge parameter) to a vertex are snapped to it:
#: 1 % of the edge moves a seam by at most that (0.3 mm on a 3 cm edge). At 1e-4
#: a seam passing a vertex cut sliver triangles (edges 7e-5 of the median edge on
#: the twin-peak tent's width-only layout, `cutting.compare`) whose least-strain
#: flattening did not converge and whose reassembly stress is arbitrary; at 1e-3
#: edges of 1.9e-3 remained (RMS deviation 6,065 kN/m there, max 1.1e6), at 1e-2
#: of 1.3e-2, and every cloth's flattening converged.
SNAP = 1e-2


@dataclasses.dataclass
class CutMesh:
    """The mesh re-triangulated along the seams.

    - `vertices`, `faces`: the split mesh (original vertices first).
    - `seam_edges`: `(K, 2)` vertex pairs along the seams; `seam_of_edge`: `(K,)`.
    - `cloth_of_face`: `(F',)` cloth label of each face.
    - `seam_points`: per seam, the vertex ids of its polyline in order.
    """

    vertices: Float[np.ndarray, "V 3"]
    faces: Int[np.ndarray, "F 3"]
    seam_edges: Int[np.ndarray, "K 2"]
    seam_of_edge: Int[np.ndarray, " K"]
    cloth_of_face: Int[np.ndarray, " F"]
    seam_points: list[np.ndarray]
    #: how each vertex is made (see `sources`): an original vertex `("v", i)`,
    #: seam `s`'s path point `j` `("p", s, j)`, or the centroid `("c", ids)`
    origin: list[tuple] = dataclasses.field(default_factory=list)

    @property
    def n_cloths(self) -> int:
        return int(self.cloth_of_face.max()) + 1

    def sources(
        self, n_mesh_vertices: int, max_points: int, k: int = 8
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each vertex as a weighted sum of at most `k` rows of
        `[mesh.vertices; paths.points.reshape(-1, 3)]` (paths of capacity
        `max_points`): `(index, weight)`, each `(V', k)`, so that the cut
        vertices follow the seams differentiably (`jaxgeo.cutting.objective`)."""
        n = len(self.vertices)
        idx = np.zeros((n, k), np.int64)
        w = np.zeros((n, k))
        rows: list[dict[int, float]] = []
        for o in self.origin:
            if o[0] == "v":
                rows.append({o[1]: 1.0})
            elif o[0] == "p":
                rows.append({n_mesh_vertices + o[1] * max_points + o[2]: 1.0})
            else:
                acc: dict[int, float] = {}
                for i in o[1]:
                    for key, val in rows[i].items():
                        acc[key] = acc.get(key, 0.0) + val / len(o[1])
                rows.append(acc)
        for i, r in enumerate(rows):
            if len(r) > k:
                raise JaxgeoError(f"cut vertex {i} depends on {len(r)} > {k} points")
            idx[i, : len(r)] = list(r)
            w[i, : len(r)] = list(r.values())
        return idx, w

    def cloth_seams(self) -> list[list[int]]:
        """Per cloth, the seams on its boundary (sorted)."""
        uniq, inv = edge_table(self.faces)
        face_of_half = np.repeat(np.arange(len(self.faces)), 3)
        index = {tuple(r): i for i, r in enumerate(uniq.tolist())}
        cloths_of_edge: dict[int, set[int]] = {}
        for e, f in zip(inv.tolist(), face_of_half.tolist()):
            cloths_of_edge.setdefault(e, set()).add(int(self.cloth_of_face[f]))
        out: list[set[int]] = [set() for _ in range(self.n_cloths)]
        for (a, b), s in zip(self.seam_edges.tolist(), self.seam_of_edge.tolist()):
            e = index.get((min(a, b), max(a, b)))
            # (e is None for no edge, and .get then gives ())
            for c in cloths_of_edge.get(e, ()):  # pyright: ignore[reportCallIssue, reportArgumentType]
                out[c].add(int(s))
        return [sorted(c) for c in out]


def _locations(
    mesh: Mesh, path: Path, ends: tuple[SurfacePoint, SurfacePoint]
) -> list[tuple]:
    """A seam as a list of (location, path index), the cutter's hashable keys:
    `("v", vertex)` or `("e", edge, u)`, one per run of equal locations. Each
    node is read as the element it lies on (`_node_elements`); an edge
    parameter within `SNAP` of an end is that vertex."""
    n = int(path.count)
    edges = np.asarray(mesh.edges)
    kinds, index, t = (np.asarray(x)[:n] for x in _node_elements(mesh, path, *ends))
    out: list[tuple] = []
    for j, (k, i, u) in enumerate(zip(kinds.tolist(), index.tolist(), t.tolist())):
        if k == VERTEX:
            loc = ("v", i)
        elif k == EDGE and u < SNAP:
            loc = ("v", int(edges[i, 0]))
        elif k == EDGE and u > 1 - SNAP:
            loc = ("v", int(edges[i, 1]))
        elif k == EDGE:
            loc = ("e", i, u)
        else:
            raise JaxgeoError(f"seam point {j} lies on no edge nor vertex")
        if not out or out[-1][0] != loc:
            out.append((loc, j))
    return out


@eqx.filter_jit
def _node_elements(mesh: Mesh, path: Path, start: SurfacePoint, end: SurfacePoint):
    """`(kind, index, t)` of each node of `path` (`Path.surface_points`, read by
    `SurfacePoint.element`), its endpoints `start` and `end` snapped onto the
    nearest side of their face first: seam ends lie on the boundary, possibly
    inset by a hair for the laser ray."""
    ends = tuple(_on_nearest_side(p) for p in (start, end))
    path = eqx.tree_at(
        lambda p: (p.start, p.end), path, ends, is_leaf=lambda x: x is None
    )
    return path.surface_points(mesh).element(mesh)


def _on_nearest_side(p: SurfacePoint) -> SurfacePoint:
    bary = jnp.asarray(p.bary)
    side = jnp.arange(3) == jnp.argmin(bary, axis=-1)[..., None]
    return SurfacePoint(jnp.asarray(p.face, jnp.int32), jnp.where(side, 0, bary))


#: A seam as `cut_mesh` used to take it: `(path, bary_start, bary_end)`.
LegacySeam = tuple[Path, Float[np.ndarray, " 3"], Float[np.ndarray, " 3"]]


def cut_mesh(mesh: Mesh, seams: Path | Sequence[Path | LegacySeam]) -> CutMesh:
    """Split `mesh` along seams and label the cloths.

    **Arguments:**

    - `seams`: the traced seams, a batched `Path` (one row per seam, as
      `jaxgeo.seams.trace_seams` gives) or a list of single `Path`s; each
      path's `start` and `end` (`SurfacePoint`s) say where it begins and ends.
      (A `(path, bary_start, bary_end)` tuple, the older form, is still
      accepted: its barycentric coordinates replace the path's.)

    **Returns:** a `CutMesh`.
    """
    if isinstance(seams, Path):  # a batch's rows, or a single path
        rows = [seams] if np.ndim(seams.count) == 0 else list(seams)
    else:
        rows = list(seams)
    V = np.asarray(mesh.vertices, np.float64)
    faces = np.asarray(mesh.faces)
    edges = np.asarray(mesh.edges)
    edge_faces = np.asarray(mesh.edge_faces)
    face_edges = np.asarray(mesh.face_edges)
    pts = [p for p in V]
    origin: list[tuple] = [("v", i) for i in range(len(V))]
    edge_points: dict[int, list[tuple[float, int]]] = {}
    chords: dict[int, list[tuple[int, int, int]]] = {}
    seam_pairs: list[tuple[int, int, int]] = []
    seam_points: list[np.ndarray] = []

    def vid(loc, sid: int, j: int) -> int:
        if loc[0] == "v":
            return loc[1]
        e, u = loc[1], loc[2]
        pts.append((1 - u) * V[edges[e, 0]] + u * V[edges[e, 1]])
        origin.append(("p", sid, j))
        edge_points.setdefault(e, []).append((u, len(pts) - 1))
        return len(pts) - 1

    def faces_of(loc) -> set[int]:
        if loc[0] == "e":
            return {int(f) for f in edge_faces[loc[1]] if f >= 0}
        return {int(f) for f in np.flatnonzero((faces == loc[1]).any(axis=1))}

    def verts_of(loc) -> set[int]:
        return {loc[1]} if loc[0] == "v" else set(edges[loc[1]].tolist())

    for sid, seam in enumerate(rows):
        located = _locations(mesh, *_path_and_ends(seam))
        locs = [loc for loc, _ in located]
        ids = [vid(loc, sid, j) for loc, j in located]
        seam_points.append(np.asarray(ids))
        for (la, a), (lb, b) in zip(zip(locs, ids), zip(locs[1:], ids[1:])):
            seam_pairs.append((a, b, sid))
            # along an existing edge: no face to split
            if len(verts_of(la) | verts_of(lb)) <= 2:
                continue
            common = faces_of(la) & faces_of(lb)
            if len(common) != 1:
                raise JaxgeoError(
                    f"seam {sid}: consecutive points {la} and {lb} share "
                    f"{len(common)} faces"
                )
            chords.setdefault(common.pop(), []).append((a, b, sid))

    new_faces = []
    for f in range(len(faces)):
        corners = faces[f]
        on_sides = [face_edges[f, (c + 2) % 3] for c in range(3)]  # side c -> c+1
        if f not in chords and not any(e in edge_points for e in on_sides):
            new_faces.append(corners)
            continue
        poly: list[int] = []
        for c in range(3):
            a = int(corners[c])
            poly.append(a)
            e = int(on_sides[c])
            here = sorted(edge_points.get(e, []))
            if edges[e, 0] != a:
                here = here[::-1]
            poly += [i for _, i in here]
        pieces = [poly]
        for a, b, _ in chords.get(f, []):
            for k, pc in enumerate(pieces):
                if a in pc and b in pc:
                    ia, ib = sorted((pc.index(a), pc.index(b)))
                    p1 = pc[ia : ib + 1]
                    p2 = pc[ib:] + pc[: ia + 1]
                    pieces[k : k + 1] = [p for p in (p1, p2) if len(p) >= 3]
                    break
            else:
                raise JaxgeoError(f"seam chord {a}-{b} does not split face {f}")
        for pc in pieces:
            if len(pc) == 3:
                new_faces.append(pc)
                continue
            pts.append(np.mean([pts[i] for i in pc], axis=0))
            origin.append(("c", list(pc)))
            c = len(pts) - 1
            new_faces += [[pc[i], pc[(i + 1) % len(pc)], c] for i in range(len(pc))]
    F = np.asarray(new_faces, np.int64)
    P = np.asarray(pts)
    pairs = np.asarray([(a, b) for a, b, _ in seam_pairs], np.int64).reshape(-1, 2)
    sids = np.asarray([s for _, _, s in seam_pairs], np.int64)
    labels = _cloth_labels(F, pairs)
    cut = CutMesh(P, F, pairs, sids, labels, seam_points, origin)
    # canonical cloth order (by seam lists), stable across layouts of one topology
    order = sorted(range(cut.n_cloths), key=lambda c: cut.cloth_seams()[c])
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    cut.cloth_of_face = rank[labels]
    return cut


def _path_and_ends(
    seam: Path | LegacySeam,
) -> tuple[Path, tuple[SurfacePoint, SurfacePoint]]:
    """A seam's path and its two endpoints."""
    if isinstance(seam, Path):
        if seam.start is None or seam.end is None:
            raise JaxgeoError(
                "a seam's Path must carry its endpoints (start, end): trace it "
                "with shortest_path, shortest_paths or seams.trace_seams"
            )
        return seam, (seam.start, seam.end)
    path, b0, b1 = seam
    n = int(path.count)
    f0, f1 = int(np.asarray(path.elements)[0]), int(np.asarray(path.elements)[n - 1])
    return path, (SurfacePoint(f0, np.asarray(b0)), SurfacePoint(f1, np.asarray(b1)))


def edge_table(F: np.ndarray):
    """Unique undirected edges of faces `F` and, per face corner side, its edge."""
    half = np.stack([F, np.roll(F, -1, axis=1)], axis=-1).reshape(-1, 2)
    key = np.sort(half, axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    return uniq, inv.reshape(-1)


def _cloth_labels(F: np.ndarray, seam_pairs: np.ndarray) -> np.ndarray:
    uniq, inv = edge_table(F)
    face_of_half = np.repeat(np.arange(len(F)), 3)
    cut = np.zeros(len(uniq), bool)
    if len(seam_pairs):
        sk = np.sort(seam_pairs, axis=1)
        idx = {tuple(r): i for i, r in enumerate(uniq.tolist())}
        for r in sk.tolist():
            i = idx.get(tuple(r))
            if i is not None:
                cut[i] = True
    order = np.argsort(inv, kind="stable")
    e_sorted = inv[order]
    f_sorted = face_of_half[order]
    same = (e_sorted[1:] == e_sorted[:-1]) & ~cut[e_sorted[1:]]
    a, b = f_sorted[:-1][same], f_sorted[1:][same]
    adj = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(len(F), len(F)))
    _, labels = connected_components(adj, directed=False)
    return labels


def cut(
    mesh: Mesh,
    layout: Layout,
    options: TraceOptions | None = None,
    method: Method = "exact",
):
    """Trace the seams of `layout` with `method` (exact by default) and cut
    `mesh` along them (`cut_mesh`). Returns `(cut_mesh, paths)`."""
    paths = trace_seams(mesh, layout, options, method)
    bad = np.flatnonzero(np.asarray(paths.status) != Status.SUCCESS)
    if bad.size:
        raise JaxgeoError(f"seams {bad.tolist()} could not be traced")
    return cut_mesh(mesh, paths), paths
