"""Export of cutting patterns: DXF (ezdxf), SVG, and seams as OBJ polylines.

`write_dxf` and `write_svg` take either a `cutting.flatten.Pattern` (written without
compensation, warp along each cloth's strip of least width, the same allowance on
welds and boundaries) or a list of `cutting.fabricate.Piece` (compensated cut
pieces). The writers and the layer list are in `jaxgeo.cutting.export`: one
polyline per cut outline, per seam side and per boundary stretch.
"""

from __future__ import annotations

import os

import numpy as np

from .cutting.compensate import compensate_pattern
from .cutting.export import LAYERS, write_dxf as _write_dxf, write_svg as _write_svg
from .cutting.fabricate import Piece, make_pieces
from .cutting.flatten import Pattern
from .cutting.material import Compensation
from .io import obj_polylines

__all__ = [
    "LAYERS",
    "pieces",
    "write_dxf",
    "write_seams_obj",
    "write_svg",
]


def pieces(pattern: Pattern, allowance: float = 0.0) -> list[Piece]:
    """Uncompensated pieces of a pattern, warp along the strip of least width."""
    cut = compensate_pattern(pattern, Compensation(0.0, 0.0), warp="strip")
    return make_pieces(cut, allowance, allowance)


def _as_pieces(pattern, allowance: float) -> list[Piece]:
    return pieces(pattern, allowance) if isinstance(pattern, Pattern) else pattern


def write_dxf(
    pattern: Pattern | list[Piece],
    path: str | os.PathLike,
    seam_allowance: float = 0.0,
    layout: str = "roll",
) -> None:
    """Write the cloths to a DXF file (`jaxgeo.cutting.export.write_dxf`);
    `seam_allowance` applies to a `Pattern` only."""
    _write_dxf(_as_pieces(pattern, seam_allowance), path, layout)


def write_svg(pattern: Pattern | list[Piece], path: str | os.PathLike) -> None:
    """Write the cloths nested in rows to an SVG file."""
    _write_svg(_as_pieces(pattern, 0.0), path)


def write_seams_obj(polylines: list[np.ndarray], path: str | os.PathLike) -> None:
    """Write 3-D seam polylines as OBJ, one object `seam_K` and `l` element per
    seam (`jaxgeo.io.obj_polylines`)."""
    names = [f"seam_{k}" for k in range(len(polylines))]
    with open(path, "w") as f:
        f.write(obj_polylines(polylines, names))
