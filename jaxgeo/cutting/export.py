"""DXF (ezdxf) and SVG files of cut pieces (`fabricate.Piece`).

DXF layers, one entity per line a cutter follows:

- `CUT`: one closed LWPOLYLINE per cloth, the cut line (allowances included);
- `WELD`: one open LWPOLYLINE per seam side, the net weld line;
- `BOUNDARY`: one open LWPOLYLINE per boundary stretch (edge cable line);
- `MARKS`: match marks across the weld lines (two-point lines);
- `WARP`: the warp arrow of each cloth;
- `LABEL`: the cloth name inside each cloth and the seam number on each weld.

Units are metres (`$INSUNITS` = 6). `layout="roll"` lays the cloths one after
another along x, warp along the roll, as they are cut from it;
`layout="rows"` nests them in rows on a sheet (`fabricate.nest_rows`), which is
what the SVG shows.
"""

from __future__ import annotations

import os

import ezdxf
import numpy as np
from ezdxf.enums import TextEntityAlignment

from .fabricate import BOUNDARY, Piece, nest_rows

__all__ = ["LAYERS", "place", "write_dxf", "write_svg"]

#: layer name → ACI colour
LAYERS = {
    "CUT": 7,
    "WELD": 1,
    "BOUNDARY": 4,
    "MARKS": 6,
    "WARP": 3,
    "LABEL": 5,
}


def place(pieces: list[Piece], layout: str = "roll") -> list[Piece]:
    """Pieces moved to their place on the roll (`"roll"`) or sheet (`"rows"`)."""
    if layout == "rows":
        return nest_rows(pieces)[0]
    gap = 0.05 * max(p.width for p in pieces)
    out, x = [], 0.0
    for p in pieces:
        lo = p.cut.min(axis=0)
        out.append(p.moved(np.array([x, 0.0]) - lo))
        x += p.length + gap
    return out


def _run_label(points: np.ndarray) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    t = 0.5 * cum[-1]
    return np.array([np.interp(t, cum, points[:, k]) for k in range(2)])


def write_dxf(
    pieces: list[Piece], path: str | os.PathLike, layout: str = "roll"
) -> None:
    """Write the pieces to a DXF file (layers in the module docstring)."""
    # (ezdxf's public new() is not in its __all__)
    doc = ezdxf.new(setup=True, units=6)  # pyright: ignore[reportPrivateImportUsage]
    for name, color in LAYERS.items():
        doc.layers.add(name, color=color)
    msp = doc.modelspace()
    for p in place(pieces, layout):
        msp.add_lwpolyline(p.cut.tolist(), close=True, dxfattribs={"layer": "CUT"})
        for r in p.runs:
            layer = "BOUNDARY" if r.seam == BOUNDARY else "WELD"
            msp.add_lwpolyline(r.points.tolist(), dxfattribs={"layer": layer})
            if r.seam != BOUNDARY:
                msp.add_text(
                    f"S{r.seam}",
                    height=0.3 * p.label_size,
                    dxfattribs={"layer": "LABEL"},
                ).set_placement(
                    tuple(_run_label(r.points)), align=TextEntityAlignment.MIDDLE_CENTER
                )
        for m in p.marks.values():
            for a, b in m:
                msp.add_line(tuple(a), tuple(b), dxfattribs={"layer": "MARKS"})
        msp.add_lwpolyline(p.arrow.tolist(), dxfattribs={"layer": "WARP"})
        msp.add_text(
            p.name, height=0.6 * p.label_size, dxfattribs={"layer": "LABEL"}
        ).set_placement(tuple(p.label_at), align=TextEntityAlignment.MIDDLE_CENTER)
    doc.saveas(os.fspath(path))


def write_svg(pieces: list[Piece], path: str | os.PathLike, px: float = 800.0) -> None:
    """Write the pieces nested in rows on a sheet to an SVG file, `px` pixels
    wide; cut line black, weld lines red, boundary lines blue, warp arrows green,
    labels inside each cloth."""
    placed, (w, h) = nest_rows(pieces)
    s = px / w
    pad = 10.0

    def pts(q):
        return " ".join(f"{pad + s * x:.2f},{pad + s * (h - y):.2f}" for x, y in q)

    parts = []
    for p in placed:
        parts.append(
            f'<polygon points="{pts(p.cut)}" fill="#eef" stroke="black" '
            'stroke-width="0.8"/>'
        )
        for r in p.runs:
            colour = "#1565c0" if r.seam == BOUNDARY else "#c62828"
            parts.append(
                f'<polyline points="{pts(r.points)}" fill="none" stroke="{colour}" '
                'stroke-width="0.6"/>'
            )
        parts.append(
            f'<polyline points="{pts(p.arrow)}" fill="none" stroke="#2e7d32" '
            'stroke-width="0.8"/>'
        )
        x, y = pad + s * p.label_at[0], pad + s * (h - p.label_at[1])
        size = max(min(0.9 * s * p.label_size, 0.25 * s * p.width), 4.0)
        parts.append(
            f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size:.1f}" '
            f'text-anchor="middle" dominant-baseline="central">{p.name}</text>'
        )
    head = (
        '<svg xmlns="http://www.w3.org/2000/svg" '
        f'width="{px + 2 * pad:.0f}" height="{s * h + 2 * pad:.0f}" '
        f'viewBox="0 0 {px + 2 * pad:.1f} {s * h + 2 * pad:.1f}">'
    )
    with open(path, "w") as f:
        f.write("\n".join([head, *parts, "</svg>\n"]))
