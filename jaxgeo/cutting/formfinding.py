"""The old import path of force-density form finding: re-exports
`jaxgeo.formfinding`'s public names.

The form finder moved out of `cutting` to the mesh layer, because the built-in
`surfaces.four_point_sail` is made by it: from here, `surfaces` imported the
`cutting` package, which sits above it.
"""

from ..formfinding import (
    Sail as Sail,
    force_density as force_density,
    four_point_sail as four_point_sail,
)

__all__ = ["Sail", "force_density", "four_point_sail"]
