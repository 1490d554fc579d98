"""jaxgeo: differentiable geodesics on triangle meshes, in JAX."""

# (`seams` and `pattern` only re-export names of `cutting`'s modules, which import
# nothing from them; `tests/test_seams.py` imports them first in a fresh interpreter.)
from . import cutting as cutting
from ._cache import enable_compilation_cache as enable_compilation_cache
from ._errors import JaxgeoError as JaxgeoError
from ._precision import PrecisionWarning as PrecisionWarning
from .batch import shortest_paths as shortest_paths
from .data import example_mesh_path as example_mesh_path
from .geodesic import path_length as path_length, shortest_path as shortest_path
from .loading import load_mesh as load_mesh
from .locate import SurfacePoint as SurfacePoint, locate as locate
from .mesh import Mesh as Mesh
from .methods import Exact as Exact, Laser as Laser, Smooth as Smooth
from .normals import vertex_normals as vertex_normals
from .path import Path as Path, Status as Status
from .repair import RepairReport as RepairReport, repair_mesh as repair_mesh
from .trace import TraceOptions as TraceOptions

__version__ = "0.1.0"
