"""Export of cutting patterns: DXF (ezdxf), SVG, and seams as OBJ polylines.

DXF layers: `CUT` one closed LWPOLYLINE per cloth (its outline, offset outward by
the seam allowance when one is given), `SEAM` the seam lines of each cloth (open
polylines, the sewing lines), `OUTLINE` the net outline when an allowance is
added, `LABEL` the cloth numbers. Cloths are laid side by side along x, each
turned so the roll runs along x and its width is along y.
"""

from __future__ import annotations

import os

import ezdxf
import numpy as np

from .pattern import Cloth, Pattern

__all__ = [
    "offset_polygon",
    "placed_cloths",
    "write_dxf",
    "write_seams_obj",
    "write_svg",
]


def offset_polygon(poly: np.ndarray, d: float) -> np.ndarray:
    """Offset a counter-clockwise polygon outward by `d` (mitred corners, the
    miter limited to 4·d)."""
    p = np.asarray(poly, float)
    e_in = p - np.roll(p, 1, axis=0)
    e_out = np.roll(p, -1, axis=0) - p

    def normal(e):
        n = np.stack([e[:, 1], -e[:, 0]], 1)
        return n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]

    n1, n2 = normal(e_in), normal(e_out)
    bis = n1 + n2
    bis /= np.maximum(np.linalg.norm(bis, axis=1), 1e-300)[:, None]
    cos = np.maximum(np.einsum("ij,ij->i", bis, n2), 0.25)
    return p + bis * (d / cos)[:, None]


def placed_cloths(pattern: Pattern, gap: float | None = None) -> list[np.ndarray]:
    """Per cloth an x-offset vector placing the cloths side by side."""
    widths = [c.uv[:, 0].max() for c in pattern.cloths]
    gap = 0.05 * max(widths) if gap is None else gap
    x, out = 0.0, []
    for w in widths:
        out.append(np.array([x, 0.0]))
        x += w + gap
    return out


def _seam_lines(c: Cloth) -> dict[int, list[np.ndarray]]:
    return {s: [c.uv[e] for e in edges] for s, edges in c.seams.items()}


def write_dxf(
    pattern: Pattern, path: str | os.PathLike, seam_allowance: float = 0.0
) -> None:
    """Write the flattened cloths to a DXF file (layers in the module docstring)."""
    doc = ezdxf.new(setup=True)
    for name, color in (("CUT", 7), ("SEAM", 1), ("OUTLINE", 3), ("LABEL", 5)):
        doc.layers.add(name, color=color)
    msp = doc.modelspace()
    for k, (c, off) in enumerate(zip(pattern.cloths, placed_cloths(pattern))):
        outline = c.uv[c.outline] + off
        cut = offset_polygon(outline, seam_allowance) if seam_allowance else outline
        msp.add_lwpolyline(cut.tolist(), close=True, dxfattribs={"layer": "CUT"})
        if seam_allowance:
            msp.add_lwpolyline(
                outline.tolist(), close=True, dxfattribs={"layer": "OUTLINE"}
            )
        for segs in _seam_lines(c).values():
            for seg in segs:
                msp.add_lwpolyline((seg + off).tolist(), dxfattribs={"layer": "SEAM"})
        centre = outline.mean(axis=0)
        msp.add_text(
            f"{k}", height=0.2 * c.width, dxfattribs={"layer": "LABEL"}
        ).set_placement(tuple(centre))
    doc.saveas(os.fspath(path))


def write_svg(pattern: Pattern, path: str | os.PathLike, scale: float = 100.0) -> None:
    """Write the flattened cloths to an SVG file (units: `scale` px per unit)."""
    offs = placed_cloths(pattern)
    parts = []
    xmax = ymax = 0.0
    for k, (c, off) in enumerate(zip(pattern.cloths, offs)):
        q = (c.uv[c.outline] + off) * scale
        xmax, ymax = max(xmax, q[:, 0].max()), max(ymax, q[:, 1].max())
        pts = " ".join(f"{x:.3f},{-y:.3f}" for x, y in q)
        parts.append(f'<polygon points="{pts}" fill="#eef" stroke="black"/>')
        for segs in _seam_lines(c).values():
            for seg in segs:
                (x0, y0), (x1, y1) = (seg + off) * scale
                parts.append(
                    f'<line x1="{x0:.3f}" y1="{-y0:.3f}" x2="{x1:.3f}" '
                    f'y2="{-y1:.3f}" stroke="red"/>'
                )
        cx, cy = q.mean(axis=0)
        parts.append(f'<text x="{cx:.1f}" y="{-cy:.1f}" font-size="12">{k}</text>')
    head = (
        '<svg xmlns="http://www.w3.org/2000/svg" '
        f'viewBox="-10 {-ymax - 10:.1f} {xmax + 20:.1f} {ymax + 20:.1f}">'
    )
    with open(path, "w") as f:
        f.write("\n".join([head, *parts, "</svg>\n"]))


def write_seams_obj(polylines: list[np.ndarray], path: str | os.PathLike) -> None:
    """Write 3-D seam polylines as OBJ `v`/`l` records, one `l` per seam."""
    lines, base = [], 1
    for k, pl in enumerate(polylines):
        lines.append(f"o seam_{k}")
        lines += [f"v {x:.12g} {y:.12g} {z:.12g}" for x, y, z in pl]
        lines.append("l " + " ".join(str(base + i) for i in range(len(pl))))
        base += len(pl)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
