"""Seam layouts, their tracing and the seam-width optimisation: the old home of
these names, kept so that `from jaxgeo import seams` and `jaxgeo.seams.X` keep
working. The code lives in the cutting sub-package (issue 16, one job per module):

- `jaxgeo.cutting.layout`: `Layout`, `radial_layout`, `peaks_layout`,
  `bridged_layout`, `parallel_layout`, `trace_seams`, `unbatch`, `INSET`;
- `jaxgeo.cutting.cut`: `cut` (trace a layout's seams and cut the mesh);
- `jaxgeo.cutting.seam_width`: the width/length objective (`Weights`,
  `cloth_widths`, `objective`), its BFGS (`optimise`, `Result`) and `fit_roll`.

New code should import from those modules.
"""

from .boundary import boundary_loops as boundary_loops
from .cutting.cut import cut as cut
from .cutting.layout import (
    INSET as INSET,
    Layout as Layout,
    bridged_layout as bridged_layout,
    parallel_layout as parallel_layout,
    peaks_layout as peaks_layout,
    radial_layout as radial_layout,
    trace_seams as trace_seams,
    unbatch as unbatch,
)
from .cutting.seam_width import (
    Result as Result,
    Weights as Weights,
    cloth_widths as cloth_widths,
    fit_roll as fit_roll,
    objective as objective,
    optimise as optimise,
)

__all__ = [
    "INSET",
    "Layout",
    "Result",
    "Weights",
    "boundary_loops",
    "cloth_widths",
    "cut",
    "fit_roll",
    "objective",
    "optimise",
    "bridged_layout",
    "parallel_layout",
    "peaks_layout",
    "radial_layout",
    "trace_seams",
    "unbatch",
]
