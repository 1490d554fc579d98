"""The validation suites: meshes of the sphere and the catenoid, and vertex pairs on
them whose analytic geodesic length is known (`analytic`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import NamedTuple

import numpy as np

from .._errors import JaxgeoError
from .analytic import catenoid_geodesic_length, default_c, great_circle_length


class Pair(NamedTuple):
    """An endpoint pair of a validation suite: two mesh vertices on the analytic
    surface, so `analytic` is the exact length between them."""

    pair: str
    kind: str
    v1: int
    v2: int
    analytic: float


@dataclass(frozen=True)
class Suite:
    """A mesh of an analytic surface and its endpoint pairs.

    `resolution` is the refinement level (see `sphere_suite`, `catenoid_suite`);
    `mesh_size` the mean edge length.
    """

    name: str
    resolution: int
    vertices: np.ndarray
    faces: np.ndarray
    pairs: tuple[Pair, ...]

    @property
    def mesh_size(self) -> float:
        e = self.vertices[self.faces] - self.vertices[np.roll(self.faces, 1, axis=1)]
        return float(np.linalg.norm(e, axis=-1).mean())


#: Target arc angles (degrees) of the sphere pairs; 90° is the paper's Fig. 8 arc
#: (a quarter of a great circle on the hemisphere).
SPHERE_ANGLES = (10.0, 20.0, 30.0, 45.0, 60.0, 90.0, 120.0, 160.0)
#: Subdivision level whose vertices are the sphere pairs' endpoints (every finer
#: icosphere contains them), so the pairs are identical at every resolution ≥ 3.
_SPHERE_BASE_LEVEL = 3

#: Catenoid pairs: (id, kind, (θ₁°, z₁), (θ₂°, z₂)). Rings of radius 1 at z = ±0.5.
#: C3 is the paper's arc ABC (1.0876: ring to ring, Δθ ≈ 15.8°), C7 its arc BE
#: (1.332569 = a quarter of the neck circle, c·π/2).
CATENOID_PAIRS = (
    ("C1", "meridian, ring to ring", (0.0, -0.5), (0.0, 0.5)),
    ("C2", "meridian", (30.0, -0.25), (30.0, 0.5)),
    ("C3", "across neck 15° (paper's ABC)", (0.0, -0.5), (15.0, 0.5)),
    ("C4", "across neck 60°", (0.0, -0.5), (60.0, 0.5)),
    ("C5", "across neck 120°", (0.0, -0.5), (120.0, 0.5)),
    ("C6", "across neck 90°", (0.0, -0.25), (90.0, 0.25)),
    ("C7", "neck circle 90° (paper's BE)", (0.0, 0.0), (90.0, 0.0)),
    ("C8", "neck to ring 60°", (0.0, 0.0), (60.0, 0.5)),
    ("C9", "turning point 90°", (0.0, 0.5), (90.0, 0.5)),
    ("C10", "turning point 150°", (0.0, 0.5), (150.0, 0.5)),
    ("C11", "turning point 60°", (0.0, 0.25), (60.0, 0.25)),
    ("C12", "turning point 120°, below", (0.0, -0.5), (120.0, -0.25)),
    ("C13", "across neck 165°", (0.0, -0.5), (165.0, 0.5)),
)


def _check_resolution(resolution: int, minimum: int) -> int:
    if int(resolution) != resolution or resolution < minimum:
        raise JaxgeoError(
            f"resolution must be an integer >= {minimum}, got {resolution}"
        )
    return int(resolution)


def _nearest_vertex(vertices: np.ndarray, x: np.ndarray) -> int:
    d = np.linalg.norm(vertices - x, axis=1)
    i = int(np.argmin(d))
    if d[i] > 1e-9:
        raise JaxgeoError(f"no mesh vertex at {x} (nearest {d[i]:.3g} away)")
    return i


@cache
def _sphere_pair_points() -> tuple[tuple[float, np.ndarray, np.ndarray], ...]:
    """(target angle, p, q) for `SPHERE_ANGLES`, p and q vertices of the level-3
    icosphere. Start vertices are spread over the sphere (the vertices nearest to a
    Fibonacci lattice of directions); each end vertex is the one whose arc angle from
    its start is nearest to the target (ties to the lower index)."""
    from ..surfaces import icosphere

    v, _ = icosphere(_SPHERE_BASE_LEVEL)
    n = len(SPHERE_ANGLES)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for k, target in enumerate(SPHERE_ANGLES):
        zk = 1.0 - 2.0 * (k + 0.5) / n
        rk = math.sqrt(1.0 - zk * zk)
        d = np.array([rk * math.cos(golden * k), rk * math.sin(golden * k), zk])
        i = int(np.argmax(v @ d))
        ang = np.degrees(great_circle_length(v[i], v))
        j = int(np.argmin(np.abs(ang - target)))
        out.append((target, v[i], v[j]))
    return tuple(out)


def sphere_suite(resolution: int = 4) -> Suite:
    """Unit icosphere with `resolution` subdivisions (20·4**resolution faces; at
    least 3) and 8 vertex pairs at about 10°–160° of arc (`SPHERE_ANGLES`), the same
    points at every resolution. Analytic length: the great circle."""
    from ..surfaces import icosphere

    resolution = _check_resolution(resolution, _SPHERE_BASE_LEVEL)
    v, f = icosphere(resolution)
    pairs = []
    for k, (_, p, q) in enumerate(_sphere_pair_points()):
        i, j = _nearest_vertex(v, p), _nearest_vertex(v, q)
        length = float(great_circle_length(v[i], v[j]))
        kind = f"great circle {math.degrees(length):.0f}°"
        if k == SPHERE_ANGLES.index(90.0):
            kind += " (Fig. 8)"
        pairs.append(Pair(f"S{k + 1}", kind, i, j, length))
    return Suite("sphere", resolution, v, f, tuple(pairs))


def catenoid_mesh(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """The catenoid (rings of radius 1 at distance 1) at a refinement level:
    `6·2**resolution` vertices around, `2**(resolution + 1)` bands in height
    (3 → 48 × 16, 1536 faces; 4 → 96 × 32, 6144 faces), mean edge length close
    to that of the icosphere of the same level."""
    from ..surfaces import catenoid

    return catenoid(n_around=6 * 2**resolution, n_height=2 ** (resolution + 1))


def catenoid_suite(resolution: int = 4) -> Suite:
    """The catenoid of `catenoid_mesh(resolution)` (at least 2) and the 13 vertex
    pairs of `CATENOID_PAIRS` (θ multiples of 15°, z ∈ {0, ±0.25, ±0.5}: mesh
    vertices at every level ≥ 2). Analytic length: `catenoid_geodesic_length`."""
    resolution = _check_resolution(resolution, 2)
    v, f = catenoid_mesh(resolution)
    c = default_c()
    pairs = []
    for pid, kind, a, b in CATENOID_PAIRS:
        idx = []
        for deg, z in (a, b):
            th = math.radians(deg)
            r = c * math.cosh(z / c)
            idx.append(
                _nearest_vertex(v, np.array([r * math.cos(th), r * math.sin(th), z]))
            )
        length = catenoid_geodesic_length(v[idx[0]], v[idx[1]], c)
        pairs.append(Pair(pid, kind, idx[0], idx[1], length))
    return Suite("catenoid", resolution, v, f, tuple(pairs))


SUITES = {"sphere": sphere_suite, "catenoid": catenoid_suite}
