"""Cutting a mesh along seams and flattening the cloths: the old home of these
names, kept so that `from jaxgeo.pattern import make_pattern` keeps working. The
code lives in the cutting sub-package (issue 16, one job per module):

- `jaxgeo.cutting.cut`: `cut_mesh`, `CutMesh`, `edge_table`, `SNAP`;
- `jaxgeo.cutting.flatten`: `make_pattern`, `Pattern`, `Cloth`, `flatten_cloth`
  (LSCM, then the least edge-length strain), `strip_width`, `SEAM_WEIGHT`.

New code should import from those modules.
"""

from .cutting.cut import (
    SNAP as SNAP,
    CutMesh as CutMesh,
    LegacySeam as LegacySeam,
    cut_mesh as cut_mesh,
    edge_table as edge_table,
)
from .cutting.flatten import (
    SEAM_WEIGHT as SEAM_WEIGHT,
    Cloth as Cloth,
    Pattern as Pattern,
    flatten_cloth as flatten_cloth,
    make_pattern as make_pattern,
    strip_width as strip_width,
)

__all__ = [
    "SEAM_WEIGHT",
    "SNAP",
    "Cloth",
    "CutMesh",
    "LegacySeam",
    "Pattern",
    "cut_mesh",
    "edge_table",
    "flatten_cloth",
    "make_pattern",
    "strip_width",
]
