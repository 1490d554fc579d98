"""Cutting patterns: cut a mesh along seam polylines into cloths and flatten each.

1. **Cut** (`cut_mesh`): every seam is a traced `Path` (edge crossings, vertices,
   endpoints). Each face a seam crosses is split: its corners and the seam points on
   its sides form a convex polygon, the seam segments are chords of it, the chords
   split it into convex pieces, and pieces with more than three corners are fanned
   from their centroid. Faces joined across a non-seam edge belong to one cloth.
2. **Flatten** (`flatten_cloth`): least-squares conformal map (LSCM, Lévy et al.
   2002) by sparse least squares, then the edge-length strain
   Σ w_e ((|x_i − x_j| − L_e)/L_e)² minimised by `scipy.optimize.least_squares`
   (seam edges weighted 10×, so the two flattened copies of a seam keep its 3-D
   length and sew together).
3. **Measures**: per cloth edge-length strain (max, RMS), area change, flattened
   seam lengths, and the roll width the cloth needs: the smallest width of a strip
   between two parallel lines containing it (rotating calipers on the convex hull).

All of this is numpy/scipy: it runs once per layout, after the optimisation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.optimize
import scipy.sparse as sp
from jaxtyping import Float, Int
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull

from ._errors import JaxgeoError
from .locate import SurfacePoint
from .mesh import Mesh
from .path import EDGE, FACE, VERTEX, Path

__all__ = [
    "Cloth",
    "CutMesh",
    "Pattern",
    "cut_mesh",
    "flatten_cloth",
    "make_pattern",
    "strip_width",
]

#: Seam points closer than this (edge parameter) to a vertex are snapped to it.
SNAP = 1e-4
#: Weight of seam edges, relative to interior edges, in the strain least squares.
SEAM_WEIGHT = 10.0


# ----------------------------------------------------------------------- cutting


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
    mesh_np, path: Path, ends: tuple[SurfacePoint, SurfacePoint]
) -> list[tuple]:
    """A seam as a list of (location, path index): ('v', vertex) or
    ('e', edge, u) locations; the endpoints `ends` are
    snapped onto the nearest side of their face (seam ends lie on the boundary,
    possibly inset by a hair for the laser ray)."""
    faces, edges, face_edges = mesh_np
    n = int(path.count)
    kinds = np.asarray(path.kinds)[:n]
    elems = np.asarray(path.elements)[:n]
    params = np.asarray(path.params)[:n]
    out: list[tuple] = []
    for j in range(n):
        k, el = int(kinds[j]), int(elems[j])
        if k == VERTEX:
            loc = ("v", el)
        elif k == EDGE:
            loc = ("e", el, float(params[j]))
        elif k == FACE:
            end = ends[0 if j == 0 else 1]
            el = int(np.asarray(end.face))
            bary = np.asarray(end.bary, float)
            c = int(np.argmin(bary))
            e = int(face_edges[el, c])
            a = faces[el, (c + 1) % 3]
            w = bary[(c + 2) % 3] / max(bary[(c + 1) % 3] + bary[(c + 2) % 3], 1e-300)
            # point = (1-w)·a + w·b, as a parameter from edges[e, 0]
            loc = ("e", e, float(w if edges[e, 0] == a else 1.0 - w))
        else:
            raise JaxgeoError(f"unknown path point kind {k}")
        if loc[0] == "e":
            e, u = loc[1], loc[2]
            if u < SNAP:
                loc = ("v", int(edges[e, 0]))
            elif u > 1 - SNAP:
                loc = ("v", int(edges[e, 1]))
        if not out or out[-1][0] != loc:
            out.append((loc, j))
    return out


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
    mesh_np = (faces, edges, face_edges)
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
        located = _locations(mesh_np, *_path_and_ends(seam))
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


# ----------------------------------------------------------------------- flattening


def _lscm(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Least-squares conformal map of a disk-like mesh, two far vertices pinned."""
    n = len(V)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1 = b - a
    e2 = c - a
    x1 = np.linalg.norm(e1, axis=1)
    ex = e1 / x1[:, None]
    nrm = np.cross(e1, e2)
    area2 = np.linalg.norm(nrm, axis=1)
    ey = np.cross(nrm / area2[:, None], ex)
    # local 2-D coordinates: a=(0,0), b=(x1,0), c=(x2,y2)
    x2 = np.einsum("ij,ij->i", e2, ex)
    y2 = np.einsum("ij,ij->i", e2, ey)
    # gradient operator rows (per face): grad phi = G @ [phi_a, phi_b, phi_c]
    gx = np.stack([-y2, y2, np.zeros_like(x1)], 1) / area2[:, None]
    gy = np.stack([x2 - x1, -x2, x1], 1) / area2[:, None]
    w = np.sqrt(area2 / 2)[:, None]
    m = len(F)
    rows = np.repeat(np.arange(m), 3)
    cols = F.ravel()
    Gx = sp.csr_matrix(((gx * w).ravel(), (rows, cols)), shape=(m, n))
    Gy = sp.csr_matrix(((gy * w).ravel(), (rows, cols)), shape=(m, n))
    # conformal: grad v = J grad u, J = rot90: (vx, vy) = (-uy, ux)
    A = sp.vstack([sp.hstack([Gy, Gx]), sp.hstack([-Gx, Gy])]).tocsc()
    bnd = np.unique(_boundary_edges(F))
    far = bnd[np.argmax(np.linalg.norm(V[bnd] - V[bnd[0]], axis=1))]
    p0 = bnd[np.argmax(np.linalg.norm(V[bnd] - V[far], axis=1))]
    pins = np.array([p0, far])
    d = np.linalg.norm(V[far] - V[p0])
    pin_uv = np.array([[0.0, 0.0], [d, 0.0]])
    free = np.setdiff1d(np.arange(n), pins)
    fixed_cols = np.concatenate([pins, pins + n])
    free_cols = np.concatenate([free, free + n])
    rhs = -A[:, fixed_cols] @ np.concatenate([pin_uv[:, 0], pin_uv[:, 1]])
    Af = A[:, free_cols]
    sol = sp.linalg.spsolve((Af.T @ Af).tocsc(), Af.T @ rhs)
    uv = np.zeros((n, 2))
    uv[pins] = pin_uv
    uv[free, 0] = sol[: len(free)]
    uv[free, 1] = sol[len(free) :]
    return uv


def _boundary_edges(F: np.ndarray) -> np.ndarray:
    uniq, inv = edge_table(F)
    counts = np.bincount(inv, minlength=len(uniq))
    return uniq[counts == 1]


def _signed_areas(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    a, b, c = uv[F[:, 0]], uv[F[:, 1]], uv[F[:, 2]]
    return 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])


def flatten_cloth(
    V: np.ndarray, F: np.ndarray, seam_mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Flatten a disk-like cloth `(V, F)`: LSCM, then least edge-length strain.

    **Arguments:** `seam_mask` marks, per unique edge (`edge_table(F)` order),
    the seam edges, weighted `SEAM_WEIGHT` in the strain fit.

    **Returns:** `(uv, edges)`: the 2-D positions `(V, 2)` (orientation
    preserved: positive signed areas) and the unique edges used.
    """
    uv = _lscm(V, F)
    if np.sum(_signed_areas(uv, F)) < 0:
        uv[:, 1] *= -1
    edges, _ = edge_table(F)
    L = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    l2 = np.linalg.norm(uv[edges[:, 0]] - uv[edges[:, 1]], axis=1)
    uv *= np.sum(L * l2) / np.sum(l2 * l2)  # best uniform scale
    w = np.ones(len(edges))
    if seam_mask is not None:
        w[seam_mask] = SEAM_WEIGHT
    w = np.sqrt(w) / L
    i, j = edges[:, 0], edges[:, 1]
    n = len(V)

    def res(x):
        p = x.reshape(n, 2)
        return w * (np.linalg.norm(p[i] - p[j], axis=1) - L)

    def jac(x):
        p = x.reshape(n, 2)
        d = p[i] - p[j]
        u = d / np.linalg.norm(d, axis=1)[:, None] * w[:, None]
        r = np.repeat(np.arange(len(edges)), 4)
        c = np.stack([2 * i, 2 * i + 1, 2 * j, 2 * j + 1], 1).ravel()
        v = np.stack([u[:, 0], u[:, 1], -u[:, 0], -u[:, 1]], 1).ravel()
        return sp.csr_matrix((v, (r, c)), shape=(len(edges), 2 * n))

    sol = scipy.optimize.least_squares(
        res,
        uv.ravel(),
        jac=jac,
        method="trf",
        x_scale="jac",
        xtol=1e-10,
        ftol=1e-10,
        gtol=1e-10,
        max_nfev=30,
        tr_solver="lsmr",
    )
    return sol.x.reshape(n, 2), edges


def strip_width(points: Float[np.ndarray, "N 2"]) -> tuple[float, float]:
    """The smallest width of a strip between two parallel lines containing
    `points`, and the angle (radians) of the strip's direction."""
    hull = points[ConvexHull(points).vertices]
    d = np.roll(hull, -1, axis=0) - hull
    d /= np.linalg.norm(d, axis=1)[:, None]
    normal = np.stack([-d[:, 1], d[:, 0]], 1)
    proj = np.einsum("kj,ij->ki", normal, hull)
    widths = proj.max(axis=1) - proj.min(axis=1)
    k = int(np.argmin(widths))
    return float(widths[k]), float(np.arctan2(d[k, 1], d[k, 0]))


# ----------------------------------------------------------------------- pattern


@dataclasses.dataclass
class Cloth:
    """One flattened cloth.

    - `vertices3d`, `faces`, `uv`: the cloth's own mesh and its flattening, rotated
      so the strip of least width runs along x (the roll), width along y, min at 0.
    - `outline`: vertex ids of its boundary loop (closed polygon, counter-clockwise).
    - `seams`: seam id → list of its edges in this cloth (vertex pairs).
    - `width`: the roll width it needs; `strain_max`, `strain_rms`: edge-length
      strain |l₂ − l₃|/l₃; `area_change`: A₂/A₃ − 1.
    - `seam_lengths`: seam id → (3-D length, flattened length).
    """

    vertices3d: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    outline: np.ndarray
    seams: dict[int, np.ndarray]
    width: float
    strain_max: float
    strain_rms: float
    area_change: float
    seam_lengths: dict[int, tuple[float, float]]
    #: the cloth's vertices as ids of `CutMesh.vertices`
    vertex_ids: np.ndarray | None = None

    def summary(self) -> dict:
        return {
            "width": self.width,
            "strain_max": self.strain_max,
            "strain_rms": self.strain_rms,
            "area_change": self.area_change,
            "seams": sorted(self.seams),
            "seam_lengths": {int(k): list(v) for k, v in self.seam_lengths.items()},
        }


@dataclasses.dataclass
class Pattern:
    cut: CutMesh
    cloths: list[Cloth]

    def seam_copy_difference(self) -> dict[int, float]:
        """Per seam, the relative difference of its flattened lengths in the
        cloths on either side: |a − b| / mean (seams with two copies)."""
        copies: dict[int, list[float]] = {}
        for c in self.cloths:
            for s, (_, l2) in c.seam_lengths.items():
                copies.setdefault(s, []).append(l2)
        return {
            s: abs(v[0] - v[1]) / (0.5 * (v[0] + v[1]))
            for s, v in copies.items()
            if len(v) == 2
        }

    @property
    def widths(self) -> np.ndarray:
        return np.array([c.width for c in self.cloths])


def _outline(F: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The longest boundary loop of a cloth, counter-clockwise in uv."""
    half = np.stack([F, np.roll(F, -1, axis=1)], -1).reshape(-1, 2)
    key = {(a, b) for a, b in half.tolist()}
    bnd = [(a, b) for a, b in half.tolist() if (b, a) not in key]
    nxt = dict(bnd)
    loops, seen = [], set()
    for s in nxt:
        if s in seen:
            continue
        lp, v = [], s
        while v not in seen:
            seen.add(v)
            lp.append(v)
            v = nxt[v]
        loops.append(np.asarray(lp))

    def perim(lp):
        q = uv[lp]
        return np.linalg.norm(np.roll(q, -1, 0) - q, axis=1).sum()

    return max(loops, key=perim)


def make_pattern(cut: CutMesh) -> Pattern:
    """Flatten every cloth of `cut` and measure it."""
    cloths = []
    seam_key = {}
    for (a, b), s in zip(cut.seam_edges.tolist(), cut.seam_of_edge.tolist()):
        seam_key[(min(a, b), max(a, b))] = s
    for c in range(cut.n_cloths):
        Fg = cut.faces[cut.cloth_of_face == c]
        used, Fl = np.unique(Fg, return_inverse=True)
        Fl = Fl.reshape(-1, 3)
        V = cut.vertices[used]
        edges, _ = edge_table(Fl)
        bnd = {tuple(e) for e in _boundary_edges(Fl).tolist()}
        gl = used[edges]
        sid = np.array(
            [
                seam_key.get((min(a, b), max(a, b)), -1) if tuple(e) in bnd else -1
                for (a, b), e in zip(gl.tolist(), edges.tolist())
            ]
        )
        uv, _ = flatten_cloth(V, Fl, sid >= 0)
        L = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
        l2 = np.linalg.norm(uv[edges[:, 0]] - uv[edges[:, 1]], axis=1)
        strain = np.abs(l2 - L) / L
        a3 = 0.5 * np.linalg.norm(
            np.cross(V[Fl[:, 1]] - V[Fl[:, 0]], V[Fl[:, 2]] - V[Fl[:, 0]]), axis=1
        )
        area_change = _signed_areas(uv, Fl).sum() / a3.sum() - 1
        width, angle = strip_width(uv)
        rot = np.array(
            [[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]]
        )
        uv = uv @ rot.T
        uv -= uv.min(axis=0)
        seams = {int(s): edges[sid == s] for s in np.unique(sid[sid >= 0])}
        lengths = {
            s: (float(L[sid == s].sum()), float(l2[sid == s].sum())) for s in seams
        }
        cloths.append(
            Cloth(
                V,
                Fl,
                uv,
                _outline(Fl, uv),
                seams,
                width,
                float(strain.max()),
                float(np.sqrt(np.mean(strain**2))),
                float(area_change),
                lengths,
                used,
            )
        )
    return Pattern(cut, cloths)
