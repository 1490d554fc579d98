"""Cutting patterns a fabricator can cut: material and prestress compensation,
warp direction, allowances and export, the reassembly stress check, the
differentiable seam objective and its optimiser.

One job per module: `layout` (seam layouts and their tracing), `cut` (the mesh cut
along the seams), `flatten` (LSCM and the strain fit: cloths), `seam_width` (the
roll-width objective and its BFGS), `material` (orthotropic membrane, prestress,
compensation),
`compensate` (warp frame and cut shape), `reassembly` (CST stress check),
`fabricate` (allowances, weld matching, DXF/SVG),
`objective` and `optimise` (the differentiable loop), `plots` (figures).
(`formfinding` re-exports `jaxgeo.formfinding`, its old home.)
"""

from .compensate import CutCloth as CutCloth, compensate_pattern as compensate_pattern
from .material import (
    BoundaryCompensation as BoundaryCompensation,
    Compensation as Compensation,
    Material as Material,
    Prestress as Prestress,
)
from .objective import Settings as Settings
from .optimise import StressResult as StressResult, optimise_seams as optimise_seams
from .reassembly import Reassembly as Reassembly, reassemble as reassemble
