"""Face corridors: the combinatorial side of exact geodesics (numpy, outside jit).

A *corridor* is a sequence of face ids in which consecutive faces share an edge,
from a face holding the start point to a face holding the end point. This module
holds the per-mesh tables the corridor algorithms need (`Topology`), walks around
vertex fans, cleans corridors (no immediate back-tracks, no useless faces at the
ends) and builds a corridor from a Dijkstra shortest path on the edge graph.
"""

from __future__ import annotations

import hashlib
import weakref
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, depth_first_order, dijkstra

from ._errors import JaxgeoError
from .mesh import Mesh

#: An interior vertex whose angle sum is 2π less at most this counts as flat.
CURVATURE_TOL = 1e-9


class EndPoint:
    """A surface point as a face and barycentric coordinates, plus its *support*:
    the vertices with a positive coordinate (one for a vertex, two for a point on
    an edge, three inside a face)."""

    def __init__(self, topo: Topology, face: int, bary: np.ndarray):
        face = int(face)
        if not 0 <= face < topo.faces.shape[0]:
            raise JaxgeoError(f"face index {face} out of range")
        bary = np.asarray(bary, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(bary)) or np.any(bary < 0) or bary.sum() <= 0:
            raise JaxgeoError(
                f"barycentric coordinates must be finite, >= 0 and not all 0, "
                f"got {bary}"
            )
        self.face = face
        self.bary = bary / bary.sum()
        corners = topo.faces[face]
        self.support = {int(corners[i]): float(self.bary[i]) for i in range(3)}
        self.support = {v: w for v, w in self.support.items() if w > 0}
        self.xyz = self.bary @ topo.vertices[corners]

    @property
    def vertex(self) -> int:
        """The mesh vertex the point sits on, or -1."""
        return next(iter(self.support)) if len(self.support) == 1 else -1

    def in_face(self, topo: Topology, face: int) -> bool:
        """Whether the point lies in the closure of `face`."""
        return set(self.support) <= set(topo.faces[face].tolist())

    def faces(self, topo: Topology) -> set[int]:
        """The faces whose closure holds the point (all faces round a vertex, both
        faces of an edge, or the one face)."""
        out = None
        for v in self.support:
            around = topo.vertex_faces[v]
            ring = set(around[around >= 0].tolist())
            out = ring if out is None else out & ring
        return out or {self.face}


class Topology:
    """Per-mesh numpy tables: face adjacency, corner angles, vertex angle sums,
    boundary vertices and the weighted edge graph (for Dijkstra).

    **Arguments:**

    - `mesh`: a concrete `Mesh` (not a tracer).
    """

    def __init__(self, mesh: Mesh):
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        edges = np.asarray(mesh.edges, dtype=np.int64)
        edge_faces = np.asarray(mesh.edge_faces, dtype=np.int64)
        face_edges = np.asarray(mesh.face_edges, dtype=np.int64)
        self.vertices, self.faces, self.edges = v, f, edges
        self._face_list = f.tolist()
        self.face_edges = face_edges
        across = edge_faces[face_edges]  # (F, 3, 2)
        me = np.arange(f.shape[0])[:, None]
        #: adj[f, i]: the face across the edge opposite corner i (-1: boundary)
        self.adj = np.where(across[..., 0] == me, across[..., 1], across[..., 0])
        p = v[f]
        angles = np.empty(f.shape, dtype=np.float64)
        for i in range(3):
            a = p[:, (i + 1) % 3] - p[:, i]
            b = p[:, (i + 2) % 3] - p[:, i]
            angles[:, i] = np.arctan2(
                np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)
            )
        self.corner_angle = angles
        self.angle_sum = np.bincount(f.ravel(), angles.ravel(), minlength=v.shape[0])
        self.boundary_vertex = np.zeros(v.shape[0], dtype=bool)
        self.boundary_vertex[edges[edge_faces[:, 1] < 0].ravel()] = True
        self.max_valence = int(np.bincount(f.ravel()).max())
        self.vertex_faces = np.asarray(mesh.vertex_faces, dtype=np.int64)
        self.mean_edge_length = float(np.asarray(mesh.mean_edge_length))
        lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
        self._graph = (
            np.concatenate([edges[:, 0], edges[:, 1]]),
            np.concatenate([edges[:, 1], edges[:, 0]]),
            np.concatenate([lengths, lengths]),
        )
        #: No interior vertex of positive curvature (angle sum under 2π): the
        #: surface is locally CAT(0), so each homotopy class of paths between two
        #: points holds exactly one locally-shortest path (Cartan–Hadamard).
        interior = ~self.boundary_vertex & (
            np.bincount(f.ravel(), minlength=len(v)) > 0
        )
        self.nonpositive = bool(
            np.all(self.angle_sum[interior] >= 2.0 * np.pi - CURVATURE_TOL)
        )
        self._potential_tree = None
        # plain lists: the fan walks index them one element at a time
        self._adj_list = self.adj.tolist()
        self._corner_angle_list = angles.tolist()
        vf = self.vertex_faces
        self._vertex_face_list = [
            row[:k].tolist() for row, k in zip(vf, (vf >= 0).sum(1).tolist())
        ]
        n = v.shape[0]
        r0, c0, d0 = self._graph
        self._csr = sp.csr_matrix((d0, (r0, c0)), shape=(n + 2, n + 2))

    # ------------------------------------------------------------- homotopy

    def _tree(self):
        """A spanning forest of the edge graph rooted at the boundary vertices (one
        root per component without boundary), as a preorder with subtree sizes."""
        if self._potential_tree is None:
            n = self.vertices.shape[0]
            roots = np.flatnonzero(self.boundary_vertex)
            comp_n, comp = connected_components(
                sp.csr_matrix(
                    (np.ones(len(self._graph[0])), self._graph[:2]), shape=(n, n)
                ),
                directed=False,
            )
            closed = np.setdiff1d(np.arange(comp_n), comp[roots])
            first = np.full(comp_n, -1)
            first[comp[::-1]] = np.arange(n)[::-1]
            roots = np.concatenate([roots, first[closed]])
            r0, c0, _ = self._graph
            keep = ~np.isin(c0, roots)  # roots hang from the super-root only
            r0, c0 = r0[keep], c0[keep]
            rows = np.concatenate([r0, np.full(roots.size, n)])
            cols = np.concatenate([c0, roots])
            graph = sp.csr_matrix(
                (np.ones(rows.size), (rows, cols)), shape=(n + 1,) * 2
            )
            order, pred = depth_first_order(graph, n, directed=True)
            size = np.ones(n + 1, dtype=np.int64)
            for x in order[:0:-1].tolist():
                size[pred[x]] += size[x]
            pos = np.empty(n + 1, dtype=np.int64)
            pos[order] = np.arange(order.size)
            self._potential_tree = (pred[:n], pos[:n], size[:n])
        return self._potential_tree

    def homotopic(self, a: Sequence[int], b: Sequence[int], start, end) -> bool:
        """Whether two corridors between the same endpoints are homologous: the
        closed walk `a`, then `b` backwards, crosses the edges as the coboundary
        of a vertex potential that vanishes on the boundary (the rings of interior
        vertices span the null-homologous walks). On a disk or an annulus this is
        homotopy; on other surfaces homology, which it implies."""
        walk = list(a) + self._join(a[-1], b[-1], end) + list(b[::-1])
        walk += self._join(b[0], a[0], start) + [a[0]]
        f = np.asarray(walk, dtype=np.int64)
        f0, f1 = f[:-1], f[1:]
        step = f0 != f1
        f0, f1 = f0[step], f1[step]
        if f0.size == 0:
            return True
        shared = self.adj[f0] == f1[:, None]
        if not np.all(shared.any(1)):
            return False
        edge = self.face_edges[f0, np.argmax(shared, axis=1)]
        p, q = self.edges[edge, 0], self.edges[edge, 1]
        # f0 left of p -> q when its corners hold (p, q) in counter-clockwise order
        c = np.argmax(self.faces[f0] == p[:, None], axis=1)
        left = self.faces[f0, (c + 1) % 3] == q
        w = np.bincount(edge, np.where(left, 1.0, -1.0), minlength=len(self.edges))
        pred, pos, size = self._tree()
        n = self.vertices.shape[0]
        # tree edges (parent -> child) carrying w raise the child's subtree
        hit = np.flatnonzero(w)
        a_, b_ = self.edges[hit, 0], self.edges[hit, 1]
        diff = np.zeros(n + 2)
        for e, x, y in zip(hit.tolist(), a_.tolist(), b_.tolist()):
            if pred[y] == x:  # x -> y, child y: phi(y) = phi(x) + w
                child, val = y, w[e]
            elif pred[x] == y:  # child x: phi(x) = phi(y) - w
                child, val = x, -w[e]
            else:
                continue
            diff[pos[child]] += val
            diff[pos[child] + size[child]] -= val
        phi = np.cumsum(diff)[pos]
        return bool(np.all(phi[self.edges[:, 1]] - phi[self.edges[:, 0]] == w))

    def _join(self, f: int, g: int, point) -> list[int]:
        """Faces from `f` to `g` (both holding `point`), ends excluded."""
        if f == g:
            return []
        if g in self._adj_list[f]:
            return []
        v = point.vertex
        if v >= 0:
            for ccw in (True, False):
                fan = self.fan(v, f, g, ccw)
                if fan is not None:
                    return fan[1:-1]
        raise JaxgeoError("corridor ends do not meet round the endpoint")

    # ------------------------------------------------------------------ fans

    def corner(self, face: int, vertex: int) -> int:
        """The corner (0, 1, 2) of `face` at `vertex`, or -1."""
        corners = self._face_list[face]
        return corners.index(vertex) if vertex in corners else -1

    def angle_at(self, face: int, vertex: int) -> float:
        """The corner angle of `face` at `vertex` (a corner of it)."""
        corners = self._face_list[face]
        return self._corner_angle_list[face][corners.index(vertex)]

    def rotate(self, face: int, vertex: int, ccw: bool) -> int:
        """The next face around `vertex` from `face`, counter-clockwise (seen from
        the side the faces' orientation points to) or clockwise; -1 at a boundary."""
        c = self.corner(face, vertex)
        return self._adj_list[face][(c + 1) % 3 if ccw else (c + 2) % 3]

    def fan(self, vertex: int, first: int, last: int, ccw: bool) -> list[int] | None:
        """Faces around `vertex` from `first` to `last` (both included) turning one
        way, or None when that way crosses the boundary."""
        out = [first]
        face = first
        while face != last:
            face = self.rotate(face, vertex, ccw)
            if face < 0 or len(out) > self.max_valence:
                return None
            out.append(face)
        return out

    def edge_face(self, vertex: int, other: int, after: bool, ccw: bool) -> int:
        """The face of edge (vertex, other) lying just after (or before) the edge
        when turning around `vertex` in the given sense; -1 if none."""
        for f in self._edge_faces(vertex, other):
            c = self.corner(f, vertex)
            # in a counter-clockwise face (v, a, b), turning ccw around v goes
            # edge (v, a) -> face -> edge (v, b)
            corners = self._face_list[f]
            a, b = corners[(c + 1) % 3], corners[(c + 2) % 3]
            first_edge_end = a if ccw else b
            if (first_edge_end == other) == after:
                return int(f)
        return -1

    def _edge_faces(self, a: int, b: int) -> list[int]:
        return [f for f in self._vertex_face_list[a] if b in self._face_list[f]]

    # ------------------------------------------------------------ Dijkstra

    def vertex_paths(
        self, start: EndPoint, end: EndPoint, n_via: int = 0
    ) -> list[list[int]]:
        """Shortest paths on the edge graph from the start point to the end point:
        the shortest one, then up to `n_via` shortest ones through other *via*
        vertices, picked at mid-distance (d_start ≈ d_end) by increasing
        d_start + d_end and at least one mean edge length apart, to start the
        corridor search from more than one side.

        A point that is not a vertex becomes an extra node joined to the corners of
        its face (node `V` for the start, `V + 1` for the end).
        """
        n = self.vertices.shape[0]
        rows, cols, data = (list(x) for x in ([], [], []))
        nodes = []
        for k, p in enumerate((start, end)):
            if p.vertex >= 0:
                nodes.append(p.vertex)
                continue
            node = n + k
            nodes.append(node)
            for c in self.faces[p.face]:
                d = float(np.linalg.norm(self.vertices[c] - p.xyz))
                rows += [node, int(c)]
                cols += [int(c), node]
                data += [d, d]
        if nodes[0] >= n and nodes[1] >= n and start.face == end.face:
            d = float(np.linalg.norm(start.xyz - end.xyz))
            rows += [nodes[0], nodes[1]]
            cols += [nodes[1], nodes[0]]
            data += [d, d]
        if nodes[0] == nodes[1]:
            return [[nodes[0]]]
        graph = self._csr
        if rows:
            extra = sp.csr_matrix((data, (rows, cols)), shape=(n + 2, n + 2))
            graph = graph + extra
        dist, pred = dijkstra(
            graph, indices=nodes, return_predecessors=True, min_only=False
        )

        def walk(k: int, node: int) -> list[int]:
            out = [node]
            while out[-1] != nodes[k]:
                prev = int(pred[k, out[-1]])
                if prev < 0:
                    raise JaxgeoError(
                        "the start and end points lie on different connected components"
                    )
                out.append(prev)
            return out

        paths = [walk(0, nodes[1])[::-1]]
        if n_via > 0 and np.isfinite(dist[0, nodes[1]]):
            da, db = dist[0, :n], dist[1, :n]
            band = np.flatnonzero(np.abs(da - db) <= self.mean_edge_length)
            band = band[np.argsort(da[band] + db[band])]
            # a via vertex at least a mean edge from every vertex of the paths
            # already picked (a via next to one of them, or on it, repeats it)
            used = [x for x in paths[0] if x < n]
            for v in band.tolist():
                if len(paths) > n_via:
                    break
                x = self.vertices[v]
                near = np.linalg.norm(self.vertices[used] - x, axis=1)
                if near.size and near.min() < self.mean_edge_length:
                    continue
                # a via vertex at a dead end is reached and left by the same edge:
                # drop such spurs (the corridor of a path that doubles back on
                # itself cannot be built)
                path: list[int] = []
                for x in walk(0, v)[::-1] + walk(1, v)[1:]:
                    if len(path) >= 2 and path[-2] == x:
                        path.pop()
                    else:
                        path.append(x)
                if path in paths:
                    continue
                paths.append(path)
                used += [x for x in path if x < n]
        return paths

    def vertex_path_corridor(
        self, path: Sequence[int], start: EndPoint, end: EndPoint
    ) -> list[int]:
        """A face corridor along a vertex path (as from `vertex_path`).

        Around every interior vertex of the path the corridor takes the fan of faces
        between the incoming and the outgoing edge on the side of the smaller angle
        (the side a straightened path can cut across).
        """
        n = self.vertices.shape[0]
        m = len(path) - 1
        if m == 0:
            return [start.face] if start.vertex < 0 else [end.face]
        if m == 1:
            if path[0] >= n:
                return [start.face]
            if path[1] >= n:
                return [end.face]
            return self._edge_faces(path[0], path[1])[:1]
        out: list[int] = []
        for t in range(1, m):
            v = path[t]
            best, best_angle = None, np.inf
            for ccw in (True, False):
                if path[t - 1] >= n:
                    first = start.face
                else:
                    first = self.edge_face(v, path[t - 1], after=True, ccw=ccw)
                if path[t + 1] >= n:
                    last = end.face
                else:
                    last = self.edge_face(v, path[t + 1], after=False, ccw=ccw)
                if first < 0 or last < 0:
                    continue
                fan = self.fan(v, first, last, ccw)
                if fan is None:
                    continue
                angle = sum(self.angle_at(f, v) for f in fan)
                if angle < best_angle:
                    best, best_angle = fan, angle
            if best is None:
                raise JaxgeoError(f"no fan of faces around vertex {v} joins the path")
            out += best
        return _drop_backtracks(out)


_CACHE: dict[int, tuple[weakref.ref, Topology]] = {}
#: By content: a `pure_callback` rebuilds the mesh from fresh arrays on every call.
_BY_CONTENT: dict[tuple, Topology] = {}
_BY_CONTENT_SIZE = 4


def topology(mesh: Mesh) -> Topology:
    """The `Topology` of a mesh, cached while the mesh object lives, and by the
    content of its vertex and face arrays (the last few meshes)."""
    key = id(mesh)
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is mesh:
        return hit[1]
    for k in [k for k, (ref, _) in _CACHE.items() if ref() is None]:
        del _CACHE[k]
    v = np.ascontiguousarray(np.asarray(mesh.vertices))
    f = np.ascontiguousarray(np.asarray(mesh.faces))
    digest = hashlib.blake2b(v.tobytes(), digest_size=16)
    digest.update(f.tobytes())
    content = (v.shape, v.dtype.str, f.shape, f.dtype.str, digest.digest())
    topo = _BY_CONTENT.pop(content, None)
    if topo is None:
        topo = Topology(mesh)
        while len(_BY_CONTENT) >= _BY_CONTENT_SIZE:
            del _BY_CONTENT[next(iter(_BY_CONTENT))]
    _BY_CONTENT[content] = topo  # most recent last
    _CACHE[key] = (weakref.ref(mesh), topo)
    return topo


def check_corridor(topo: Topology, corridor: Sequence[int]) -> np.ndarray:
    """Validate a corridor: face ids in range, consecutive faces sharing an edge."""
    c = np.asarray(corridor, dtype=np.int64).ravel()
    if c.size == 0:
        raise JaxgeoError("empty face corridor")
    if c.min() < 0 or c.max() >= topo.faces.shape[0]:
        raise JaxgeoError("face corridor holds out-of-range face ids")
    if c.size > 1:
        a, b = topo.faces[c[:-1]], topo.faces[c[1:]]
        shared = (a[:, :, None] == b[:, None, :]).any(-1).sum(1)
        bad = np.flatnonzero((shared != 2) & (c[:-1] != c[1:]))
        if bad.size:
            raise JaxgeoError(
                f"faces {c[bad[0]]} and {c[bad[0] + 1]} of the corridor do not "
                "share an edge"
            )
    return c


def clean_corridor(
    corridor: Sequence[int], start: EndPoint, end: EndPoint, topo: Topology
) -> list[int]:
    """Drop repeated faces (a, a -> a), back-tracks (a, b, a -> a) and the faces at
    either end that the path need not cross (while the next face also holds the
    end point)."""
    stack = _drop_backtracks(corridor)
    lo, hi = 0, len(stack) - 1
    while lo < hi and start.in_face(topo, stack[lo + 1]):
        lo += 1
    while hi > lo and end.in_face(topo, stack[hi - 1]):
        hi -= 1
    return stack[lo : hi + 1]


def _drop_backtracks(corridor: Sequence[int]) -> list[int]:
    """Remove repeated faces (a, a -> a) and back-tracks (a, b, a -> a)."""
    stack: list[int] = []
    for f in corridor:
        f = int(f)
        if stack and stack[-1] == f:
            continue
        if len(stack) >= 2 and stack[-2] == f:
            stack.pop()
            continue
        stack.append(f)
    return stack
