"""Figures of the reassembly check: stress deviation over the design surface and
over each cut cloth (matplotlib; `Figure` objects, no pyplot state, so they
work in scripts, the CLI and notebooks alike)."""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from .compensate import CutCloth
from .reassembly import Reassembly

__all__ = ["deviation_figure"]


def deviation_figure(
    cloths: list[CutCloth], check: Reassembly, title: str = ""
) -> Figure:
    """Two panels: the deviation `d` (kN/m) per triangle on the 3-D design
    surface, and on the cut cloths (in rows, warp along x)."""
    from .fabricate import make_pieces, nest_rows

    d_all = np.concatenate(check.deviation)
    norm = Normalize(0.0, float(d_all.max()) or 1.0)
    cmap = colormaps["viridis"]
    fig = Figure(figsize=(12, 5.5), layout="constrained")
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    for c, d in zip(cloths, check.deviation):
        tri = c.cloth.vertices3d[c.faces]
        ax3.add_collection3d(
            Poly3DCollection(tri, facecolors=cmap(norm(d)), edgecolors="none")
        )
    v = np.concatenate([c.cloth.vertices3d for c in cloths])
    lo, hi = v.min(0), v.max(0)
    ax3.set_xlim(lo[0], hi[0])
    ax3.set_ylim(lo[1], hi[1])
    ax3.set_zlim(lo[2], hi[2])
    ax3.set_box_aspect(np.maximum(hi - lo, 1e-3 * (hi - lo).max()))
    ax3.set_axis_off()
    ax3.set_title("stress deviation on the design surface")
    ax2 = fig.add_subplot(1, 2, 2)
    placed, _ = nest_rows(make_pieces(cloths))
    for c, p, d in zip(cloths, placed, check.deviation):
        shift = p.net.min(axis=0) - c.uv[np.asarray(c.cloth.outline)].min(axis=0)
        uv = c.uv + shift
        ax2.tripcolor(uv[:, 0], uv[:, 1], c.faces, facecolors=d, cmap=cmap, norm=norm)
        # (pyright misreads *args of unknown length followed by more arguments)
        ax2.text(*p.label_at, p.name, ha="center", va="center", fontsize=7)  # pyright: ignore[reportCallIssue]
    ax2.set_aspect("equal")
    ax2.set_title("on the cut cloths (warp along x)")
    fig.colorbar(
        ScalarMappable(norm, cmap),
        ax=[ax3, ax2],
        label="|σ − p| (kN/m)",
        shrink=0.7,
    )
    if title:
        fig.suptitle(title)
    return fig
