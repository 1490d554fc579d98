"""`repair_mesh`: remove what makes a real mesh file unusable, and say what changed.

Scans, CAD exports and hand-made models often hold a few faces that `Mesh`
refuses: needle or zero-area faces, the same face twice, an edge shared by three
or more faces (a fin, a stray triangle, two sheets glued along a line), a vertex
where two fans of faces touch (a bow-tie). `repair_mesh` fixes exactly these, with
the criteria `Mesh` validates by, so its output passes them:

1. degenerate faces (a repeated vertex, zero area, or a needle below
   `jaxgeo.mesh.DEGENERATE_AREA_RATIO`) are removed;
2. of faces with the same three vertices, the first is kept, except where they
   come in both orientations and the kept one's edges would still have more
   than two faces: a wall between two solids that touch (STL and voxel exports
   of assemblies), where both copies go and the solids become one;
3. edges of more than two faces (sheets or solids that touch along an edge, a
   fin, a wall inside a solid), by `nonmanifold`:
   - `"split"` (default): every vertex whose faces form several fans (linked
     across edges of two faces) is split into one copy per fan, the fan with the
     vertex's first corner keeping its index. A fan is a strip of faces, so it
     holds at most two faces of any edge through its vertex: this separates
     every such edge, and bow-ties, without removing a face;
   - `"remove"`: on each such edge the smallest faces are removed until two
     remain (MeshLab's "Repair non Manifold Edges by removing faces": a stray
     triangle is usually smaller than the surface it sticks to); then bow-ties
     are split as above.
   Split keeps touching solids whole (an STL of 668 cubes that share edges loads
   as 668 closed cubes; remove takes 1312 of its faces) but opens a solid along
   a wall inside it, which remove closes again.

Vertex indices of the input stay valid (vertices are only appended, never
removed or renumbered); `RepairReport.faces` maps the output faces to the input's.
Problems repair cannot fix (bad shapes, NaN, out-of-range indices) raise
`JaxgeoError` as `Mesh` does; a non-orientable surface is left for `Mesh` to
report.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any, Literal

import numpy as np
from jaxtyping import Float, Int

from ._errors import JaxgeoError
from ._mesh_checks import check_arrays, corner_fans, degenerate_mask, unique_pairs
from ._stacklevel import caller_stacklevel


@dataclasses.dataclass(frozen=True)
class RepairReport:
    """What `repair_mesh` changed.

    - `degenerate_faces`: faces removed as degenerate (repeated vertex, zero area,
      needle).
    - `duplicate_faces`: faces removed as copies of an earlier face.
    - `nonmanifold_faces`: faces removed from edges of more than two faces.
    - `split_vertices`: bow-tie vertices split; `added_vertices`: the copies made
      (appended after the input's vertices).
    - `faces`: for each output face, the index of the input face it is.
    """

    degenerate_faces: int
    duplicate_faces: int
    nonmanifold_faces: int
    split_vertices: int
    added_vertices: int
    faces: np.ndarray = dataclasses.field(repr=False)

    @property
    def changed(self) -> bool:
        return bool(
            self.degenerate_faces
            + self.duplicate_faces
            + self.nonmanifold_faces
            + self.split_vertices
        )

    def __str__(self) -> str:
        if not self.changed:
            return "nothing to repair"
        parts = [
            (self.degenerate_faces, "degenerate faces removed"),
            (self.duplicate_faces, "duplicate faces removed"),
            (self.nonmanifold_faces, "faces on non-manifold edges removed"),
            (
                self.split_vertices,
                f"non-manifold vertices split into {self.added_vertices} "
                "added vertices",
            ),
        ]
        return "; ".join(f"{n} {what}" for n, what in parts if n)


def _edge_counts(f: np.ndarray) -> np.ndarray:
    """For each face, the most faces any of its edges has."""
    half = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    _, edge, counts = unique_pairs(half, return_inverse=True, return_counts=True)
    return counts[edge.ravel()].reshape(3, -1).max(axis=0)


def _unique_faces(f: np.ndarray) -> np.ndarray:
    """Indices of the faces to keep of each set with the same three vertices: the
    first; none where the set holds both orientations and the kept face's edges
    would have more than two faces (a wall between two solids that touch: both
    copies go, and the solids become one)."""
    key = np.sort(f, axis=1)
    # a face runs the same way round as its sorted key iff it is a rotation of it
    even = (np.roll(key, 1, axis=1) == f).all(1) | (np.roll(key, 2, axis=1) == f).all(1)
    even |= (key == f).all(1)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    both = np.zeros(first.size, bool)
    both[group[even]] = True
    both &= np.isin(np.arange(first.size), group[~even])
    first = np.sort(first)
    wall = both[group[first]] & (_edge_counts(f[first]) > 2)
    return first[~wall]


def _nonmanifold_excess(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Faces to remove so that no edge has more than two faces: on each edge of
    three or more, all but its two largest (ties: the earlier face stays)."""
    drop = np.zeros(f.shape[0], bool)
    a, b, c = (v[f[:, i]].astype(np.float64) for i in range(3))
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    while True:
        live = np.flatnonzero(~drop)
        half = np.sort(
            np.concatenate(
                [f[live][:, [0, 1]], f[live][:, [1, 2]], f[live][:, [2, 0]]]
            ),
            axis=1,
        )
        face = np.tile(live, 3)
        _, edge, counts = unique_pairs(half, return_inverse=True, return_counts=True)
        edge = edge.ravel()
        over = counts[edge] > 2
        if not over.any():
            return drop
        edge, face = edge[over], face[over]
        order = np.lexsort((face, -area[face], edge))  # per edge: largest first
        edge, face = edge[order], face[order]
        rank = np.arange(edge.size) - np.searchsorted(edge, edge, side="left")
        drop[face[rank >= 2]] = True


def _split_fans(f: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """One vertex per fan (the fan holding a vertex's first corner keeps its
    index): returns the faces and the input vertex of each appended copy."""
    labels = corner_fans(f)
    corner_vertex = f.ravel()
    # fans of each vertex, ordered by the fan's first corner
    first_corner = np.full(labels.max() + 1, labels.size)
    np.minimum.at(first_corner, labels, np.arange(labels.size))
    fan_vertex = np.zeros(labels.max() + 1, np.int64)
    fan_vertex[labels] = corner_vertex
    fans = np.unique(labels)
    order = np.lexsort((first_corner[fans], fan_vertex[fans]))
    fans = fans[order]
    owner = fan_vertex[fans]
    rank = np.arange(fans.size) - np.searchsorted(owner, owner, side="left")
    extra = rank > 0
    new_index = np.empty(labels.max() + 1, np.int64)
    new_index[fans] = owner
    new_index[fans[extra]] = n_vertices + np.arange(int(extra.sum()))
    return new_index[labels].reshape(f.shape), owner[extra]


def repair_mesh(
    vertices: Any,
    faces: Any,
    *,
    nonmanifold: Literal["split", "remove"] = "split",
    warn: bool = True,
) -> tuple[Float[np.ndarray, "V2 3"], Int[np.ndarray, "F2 3"], RepairReport]:
    """Remove degenerate and duplicate faces, separate (or remove) the faces of
    non-manifold edges and split bow-tie vertices (module docstring: the rules).

    **Arguments:**

    - `vertices`, `faces`: `(V, 3)` coordinates and `(F, 3)` vertex indices, as
      for `Mesh`.
    - `nonmanifold`: `"split"` or `"remove"`: how edges of more than two faces
      are repaired (module docstring, step 3).
    - `warn`: emit a `UserWarning` saying what changed (when anything did).

    **Returns** `(vertices, faces, report)`: numpy arrays ready for `Mesh`, and a
    `RepairReport`. The first `V` output vertices are the input's.

    **Raises** `JaxgeoError` for input `Mesh` would refuse for other reasons than
    these (shapes, dtypes, NaN or infinite coordinates, out-of-range indices).
    """
    if nonmanifold not in ("split", "remove"):
        raise JaxgeoError(
            f"nonmanifold must be 'split' or 'remove', not {nonmanifold!r}"
        )
    v, f = check_arrays(vertices, faces)
    kept = np.arange(f.shape[0])
    degenerate = degenerate_mask(v, f)
    kept = kept[~degenerate]
    if kept.size == 0:
        raise JaxgeoError(
            f"repair_mesh: no face is left: all {f.shape[0]} faces are degenerate"
        )
    n_kept = kept.size
    kept = kept[_unique_faces(f[kept])]
    duplicate = n_kept - kept.size
    excess = np.zeros(kept.size, bool)
    if nonmanifold == "remove":
        excess = _nonmanifold_excess(v, f[kept])
        kept = kept[~excess]
    out_f, copies = _split_fans(f[kept], v.shape[0])
    out_v = np.concatenate([v, v[copies]])
    report = RepairReport(
        degenerate_faces=int(degenerate.sum()),
        duplicate_faces=int(duplicate),
        nonmanifold_faces=int(excess.sum()),
        split_vertices=int(np.unique(copies).size),
        added_vertices=int(copies.size),
        faces=kept,
    )
    if warn and report.changed:
        warnings.warn(f"repair_mesh: {report}", stacklevel=caller_stacklevel())
    return out_v, out_f, report
