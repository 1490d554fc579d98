"""Fabrication geometry of each cut cloth: weld and boundary lines, allowances,
warp arrow, label position, weld-length matching, and nesting on a sheet.

- The **net outline** of a cut cloth (compensated, warp along +x) is split into
  runs: one open polyline per seam side (a weld line) and one per stretch of the
  design boundary (an edge-cable line).
- The **cut line** adds the weld allowance outside every weld run and the
  boundary allowance outside every boundary run: the union of the net polygon
  with each run buffered by its allowance (shapely, mitred joins, flat caps)
  and, at each corner between runs, the mitre of their two offset lines
  (limited to 4 allowances).
- **Weld matching**: the two sides of a seam belong to two cloths; their cut
  (compensated) lengths differ when the cloths are flattened or compensated
  differently. Each side carries match marks at the same fractions of its
  length, so the welder aligns them and spreads the difference evenly; the
  difference is reported per seam and, per cloth, its largest.
- **Label**: at the pole of inaccessibility of the net polygon (shapely
  `polylabel`), sized to the largest circle inside the cloth.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.ops import polylabel

from .compensate import CutCloth

__all__ = [
    "Piece",
    "make_pieces",
    "nest_rows",
    "weld_mismatch",
]

BOUNDARY = -1


@dataclasses.dataclass
class Run:
    """A stretch of a cloth's net outline: `seam` id (or `BOUNDARY`) and its
    points `(K, 2)` in the cloth frame."""

    seam: int
    points: np.ndarray

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


@dataclasses.dataclass
class Piece:
    """One cloth as it is cut (cloth frame, warp along +x, metres).

    - `net`: closed net outline `(N, 2)` (counter-clockwise, not repeated);
    - `cut`: closed cut line with allowances `(M, 2)`;
    - `runs`: weld and boundary runs of the net outline;
    - `marks`: per weld run, match-mark segments `(k, 2, 2)`;
    - `arrow`: warp arrow polyline `(5, 2)`; `label_at`, `label_size`;
    - `width`: extent across the warp of the cut line (the roll width it needs);
      `length`: extent along the warp; `area`: net area (m²).
    """

    name: str
    net: np.ndarray
    cut: np.ndarray
    runs: list[Run]
    marks: dict[int, np.ndarray]
    arrow: np.ndarray
    label_at: np.ndarray
    label_size: float
    width: float
    length: float
    area: float

    def moved(self, offset: np.ndarray) -> Piece:
        o = np.asarray(offset, float)
        return dataclasses.replace(
            self,
            net=self.net + o,
            cut=self.cut + o,
            runs=[Run(r.seam, r.points + o) for r in self.runs],
            marks={k: m + o for k, m in self.marks.items()},
            arrow=self.arrow + o,
            label_at=self.label_at + o,
        )


def _runs(c: CutCloth) -> list[Run]:
    loop = np.asarray(c.cloth.outline)
    seam_of = {}
    for s, edges in c.cloth.seams.items():
        for a, b in np.asarray(edges).tolist():
            seam_of[frozenset((a, b))] = s
    ids = [
        seam_of.get(frozenset((int(a), int(b))), BOUNDARY)
        for a, b in zip(loop, np.roll(loop, -1))
    ]
    n = len(ids)
    change = [k for k in range(n) if ids[k] != ids[k - 1]]
    if not change:  # one run all round
        return [Run(ids[0], c.uv[np.r_[loop, loop[:1]]])]
    runs = []
    for a, b in zip(change, change[1:] + [change[0] + n]):
        idx = [loop[k % n] for k in range(a, b + 1)]
        runs.append(Run(ids[a], c.uv[idx]))
    return runs


def _marks(run: Run, spacing: float, size: float) -> np.ndarray:
    """Match marks: short ticks normal to the run at equal fractions of its
    length, `ceil(L/spacing)` intervals (ends excluded)."""
    p = run.points
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    k = max(int(np.ceil(cum[-1] / spacing)), 1)
    t = cum[-1] * np.arange(1, k) / k
    pts = np.column_stack([np.interp(t, cum, p[:, 0]), np.interp(t, cum, p[:, 1])])
    i = np.clip(np.searchsorted(cum, t) - 1, 0, len(seg) - 1)
    d = (p[i + 1] - p[i]) / np.maximum(seg[i], 1e-300)[:, None]
    n = np.column_stack([d[:, 1], -d[:, 0]])  # outward for a CCW outline
    return np.stack([pts, pts + size * n], axis=1)


def _corner(p, ta, tb, da, db) -> Polygon | None:
    """The mitred corner between the offsets of two runs meeting at `p` (end
    direction `ta` of the first, start direction `tb` of the second)."""
    na, nb = np.array([ta[1], -ta[0]]), np.array([tb[1], -tb[0]])
    a, b = p + da * na, p + db * nb
    m = np.column_stack([ta, -tb])
    if abs(np.linalg.det(m)) < 1e-9:
        return None
    s = np.linalg.solve(m, b - a)
    mitre = a + s[0] * ta
    limit = 4.0 * max(da, db)
    if np.linalg.norm(mitre - p) > limit:
        mitre = p + limit * (mitre - p) / np.linalg.norm(mitre - p)
    poly = Polygon([p, a, mitre, b])
    return poly if poly.is_valid and poly.area > 0 else poly.buffer(0)


def _outline_with_allowances(net, runs, weld, boundary) -> np.ndarray:
    poly = Polygon(net)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
    parts = [poly]

    def dist(r):
        return weld if r.seam != BOUNDARY else boundary

    def unit(v):
        return v / max(np.linalg.norm(v), 1e-300)

    for r in runs:
        if dist(r) > 0:
            line = LineString(r.points)
            parts.append(line.buffer(dist(r), cap_style="flat", join_style="mitre"))
    for ra, rb in zip(runs, runs[1:] + runs[:1]):
        da, db = dist(ra), dist(rb)
        if max(da, db) > 0 and len(runs) > 1:
            ta = unit(ra.points[-1] - ra.points[-2])
            tb = unit(rb.points[1] - rb.points[0])
            c = _corner(ra.points[-1], ta, tb, da, db)
            if c is not None:
                parts.append(c)
    # Parts meet along shared lines (a run's flat cap and its corner's side):
    # rounding leaves cracks of width ~1e-17 between them, and the union's
    # outline then ran down such a crack to the net corner (one cloth of the
    # cone tent lost 42 % of its boundary allowance). A grid of 1e-9 of the
    # cloth's size closes them and moves no vertex by more than that.
    grid = 1e-9 * float(np.ptp(np.asarray(net), axis=0).max())
    shape = shapely.union_all(parts, grid_size=grid)
    if shape.geom_type != "Polygon":  # keep the largest piece
        # (shapely types union_all's result as BaseGeometry: a Polygon or a collection)
        shape = max(shape.geoms, key=lambda g: g.area)  # pyright: ignore[reportAttributeAccessIssue]
    ext = np.asarray(shape.exterior.coords)[:-1]  # pyright: ignore[reportAttributeAccessIssue]
    return ext if shapely.LinearRing(ext).is_ccw else ext[::-1]


def make_pieces(
    cloths: list[CutCloth],
    weld: float = 0.0,
    boundary: float = 0.0,
    mark_spacing: float = 0.5,
) -> list[Piece]:
    """The fabrication geometry of every cut cloth (module docstring).

    **Arguments:** `weld`, `boundary`: allowances (m) outside weld and boundary
    runs; `mark_spacing`: largest distance between match marks (m)."""
    pieces = []
    for k, c in enumerate(cloths):
        runs = _runs(c)
        net = c.uv[np.asarray(c.cloth.outline)]
        cut = _outline_with_allowances(net, runs, weld, boundary)
        poly = Polygon(net).buffer(0)
        at = np.asarray(polylabel(poly, tolerance=1e-3 * np.sqrt(poly.area)).coords)[0]
        radius = float(poly.exterior.distance(shapely.Point(at)))
        size = max(radius, 1e-3)
        marks = {
            i: _marks(r, mark_spacing, 0.5 * max(weld, 0.2 * size))
            for i, r in enumerate(runs)
            if r.seam != BOUNDARY
        }
        length = float(np.ptp(net[:, 0]))
        a = min(0.3 * length, 2.0 * size)
        x0 = at[0] - 0.5 * a
        y0 = at[1] - 0.6 * size
        h = 0.15 * a
        arrow = np.array(
            [[x0, y0], [x0 + a, y0], [x0 + a - h, y0 + 0.5 * h], [x0 + a, y0],
             [x0 + a - h, y0 - 0.5 * h]]
        )  # fmt: skip
        pieces.append(
            Piece(
                f"C{k}",
                net,
                cut,
                runs,
                marks,
                arrow,
                at,
                size,
                float(np.ptp(cut[:, 1])),
                float(np.ptp(cut[:, 0])),
                float(poly.area),
            )
        )
    return pieces


def weld_mismatch(pieces: list[Piece]) -> tuple[dict[int, float], list[float]]:
    """Per seam, the cut lengths of its two sides differ by this much (m,
    signed: first cloth minus second), and per cloth the largest |difference|
    over its seams."""
    sides: dict[int, list[tuple[int, float]]] = {}
    for k, p in enumerate(pieces):
        for r in p.runs:
            if r.seam != BOUNDARY:
                sides.setdefault(r.seam, []).append((k, r.length))
    per_seam, per_cloth = {}, [0.0] * len(pieces)
    for s, v in sides.items():
        if len(v) != 2:
            continue
        (ka, la), (kb, lb) = v
        per_seam[s] = la - lb
        for k in (ka, kb):
            per_cloth[k] = max(per_cloth[k], abs(la - lb))
    return per_seam, per_cloth


def nest_rows(
    pieces: list[Piece], aspect: float = np.sqrt(2.0), gap: float | None = None
) -> tuple[list[Piece], tuple[float, float]]:
    """Place the pieces (warp along x, unrotated) in rows on a sheet of about the
    given width/height `aspect`: longest first, rows filled left to right
    (shelf packing). Returns the moved pieces and the sheet size."""
    lo = [p.cut.min(axis=0) for p in pieces]
    size = [np.ptp(p.cut, axis=0) for p in pieces]
    gap = 0.05 * max(s[1] for s in size) if gap is None else gap
    area = sum((s[0] + gap) * (s[1] + gap) for s in size)
    sheet_w = max(np.sqrt(area * aspect), max(s[0] for s in size) + gap)
    order = sorted(range(len(pieces)), key=lambda k: -size[k][0])
    out: list[Piece | None] = [None] * len(pieces)
    x = y = row_h = 0.0
    width_used = 0.0
    for k in order:
        w, h = size[k]
        if x > 0 and x + w > sheet_w:
            # (gap is a float from its first line on)
            x, y, row_h = 0.0, y + row_h + gap, 0.0  # pyright: ignore[reportOperatorIssue]
        out[k] = pieces[k].moved(np.array([x, y]) - lo[k])
        x += w + gap
        width_used = max(width_used, x - gap)
        row_h = max(row_h, h)
    # (no None is left: order is a permutation)
    return out, (width_used, y + row_h)  # pyright: ignore[reportReturnType]
