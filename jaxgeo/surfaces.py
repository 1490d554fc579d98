"""Deterministic test and demo meshes whose vertices lie exactly on analytic surfaces.

Every generator returns `(vertices, faces)`: `vertices` a float64 array `(V, 3)`,
`faces` an int64 array `(F, 3)`. The meshes are manifold, consistently oriented
(outward normals for closed surfaces, "up"/outward for open ones), free of
degenerate faces and reproducible (no randomness). Because every vertex is a point
of the analytic surface (up to rounding), analytic geodesic lengths
(`jaxgeo.validation`) apply to mesh points.

Surfaces of revolution are built from rings of vertices; alternate rings are turned
by half an angular step, so each band between two rings is a zig-zag of triangles
with no preferred diagonal direction.
"""

from __future__ import annotations

import math
import os

import numpy as np
import scipy.optimize
import trimesh
from jaxtyping import Float, Int

from ._errors import JaxgeoError
from ._grids import grid_faces as grid_faces
from .formfinding import four_point_sail as _form_found_sail

__all__ = [
    "catenoid",
    "catenoid_parameter",
    "catenoid_parameter_roots",
    "cone_tent",
    "four_point_sail",
    "icosphere",
    "saddle",
    "save",
    "SURFACES",
    "twin_peak_tent",
    "uv_sphere",
]

Vertices = Float[np.ndarray, "V 3"]
Faces = Int[np.ndarray, "F 3"]


# --------------------------------------------------------------------------- helpers


def _band_faces(lower: np.ndarray, upper: np.ndarray, lower_shift: float) -> np.ndarray:
    """Triangles of the periodic band between two rings of equal size `n`.

    Vertex `lower[i]` sits at angular position `i + lower_shift` and `upper[i]` at
    `i + 0.5 - lower_shift` (in units of the angular step), with `lower_shift` 0 or
    0.5: the rings are offset by half a step. Triangles are counter-clockwise in the
    (angle, ring) parameter plane, angle first.
    """
    n = len(lower)
    i = np.arange(n)
    j = (i + 1) % n
    if lower_shift == 0.0:  # upper[i] lies between lower[i] and lower[i + 1]
        t1 = np.stack([lower[i], lower[j], upper[i]], axis=1)
        t2 = np.stack([lower[j], upper[j], upper[i]], axis=1)
    else:  # upper[i + 1] lies between lower[i] and lower[i + 1]
        t1 = np.stack([lower[i], lower[j], upper[j]], axis=1)
        t2 = np.stack([lower[i], upper[j], upper[i]], axis=1)
    return np.concatenate([t1, t2])


def _ring_grid_faces(n_rings: int, n_around: int) -> np.ndarray:
    """Faces of `n_rings` stacked rings of `n_around` vertices (ring `k` holds indices
    `k*n_around ... (k+1)*n_around - 1`), ring `k` turned by `k % 2` half steps."""
    idx = np.arange(n_rings * n_around).reshape(n_rings, n_around)
    if n_rings < 2:
        return np.zeros((0, 3), dtype=np.int64)
    bands = [_band_faces(idx[k], idx[k + 1], 0.5 * (k % 2)) for k in range(n_rings - 1)]
    return np.concatenate(bands).astype(np.int64)


def _ring_angles(n_rings: int, n_around: int) -> np.ndarray:
    """Angles `(n_rings, n_around)`: `2π(i + (k % 2)/2)/n_around` for ring `k`."""
    k = np.arange(n_rings)[:, None]
    i = np.arange(n_around)[None, :]
    return 2.0 * np.pi * (i + 0.5 * (k % 2)) / n_around


# --------------------------------------------------------------------------- spheres


def icosphere(subdivisions: int = 3, radius: float = 1.0) -> tuple[Vertices, Faces]:
    """Subdivided icosahedron on the sphere |x| = radius, normals outward.

    `20·4**subdivisions` faces (3 → 1280, 4 → 5120, 5 → 20480). trimesh's vertices
    are re-projected, x ← radius·x/|x|, so that they lie on the sphere to rounding.
    """
    tm = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.asarray(tm.vertices, dtype=np.float64)
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return v, np.asarray(tm.faces, dtype=np.int64)


def uv_sphere(
    n_lat: int = 24, n_lon: int = 48, radius: float = 1.0
) -> tuple[Vertices, Faces]:
    """Latitude-longitude sphere x = radius·(sin φ cos θ, sin φ sin θ, cos φ).

    `n_lat - 1` rings at φ_k = kπ/n_lat (k = 1 … n_lat - 1) of `n_lon` vertices each
    (alternate rings turned by half a step), and the two poles as single vertices, so
    no face is degenerate: `2·n_lon·(n_lat - 1)` faces. Normals point outward.
    """
    if n_lat < 2 or n_lon < 3:
        raise JaxgeoError("uv_sphere needs n_lat >= 2 and n_lon >= 3")
    n_rings = n_lat - 1
    # rings from south to north, so that (θ, ring) counter-clockwise is outward
    phi = np.pi - np.pi * np.arange(1, n_lat)[:, None] / n_lat
    theta = _ring_angles(n_rings, n_lon)
    ring_v = np.stack(
        [
            np.sin(phi) * np.cos(theta),
            np.sin(phi) * np.sin(theta),
            np.cos(phi) + 0 * theta,
        ],
        axis=-1,
    ).reshape(-1, 3)
    south = 0
    north = n_rings * n_lon + 1
    v = np.concatenate([[[0.0, 0.0, -1.0]], ring_v, [[0.0, 0.0, 1.0]]]) * radius
    faces = [_ring_grid_faces(n_rings, n_lon) + 1]
    i = np.arange(n_lon)
    j = (i + 1) % n_lon
    first = 1 + i
    last = 1 + (n_rings - 1) * n_lon + i
    faces.append(np.stack([np.full(n_lon, south), first[j], first], 1))
    faces.append(np.stack([np.full(n_lon, north), last, last[j]], 1))
    faces = np.concatenate(faces).astype(np.int64)
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return v, faces


# --------------------------------------------------------------------------- catenoid


def _catenoid_residual(c: float, ring_radius: float, ring_distance: float) -> float:
    return c * math.cosh(ring_distance / (2.0 * c)) - ring_radius


def catenoid_parameter_roots(
    ring_radius: float = 1.0, ring_distance: float = 1.0
) -> tuple[float, float]:
    """Both roots c_small < c_large of c·cosh(d/(2c)) = R (R = ring_radius,
    d = ring_distance).

    g(c) = c·cosh(d/(2c)) is convex in c > 0 with its minimum where x·tanh x = 1,
    x = d/(2c) (x* ≈ 1.19968); two catenoids span the rings when g(c*) < R, i.e.
    d/R < 2x*/cosh x* ≈ 1.3255. For R = d = 1: c ≈ 0.235095 and c ≈ 0.848338.
    Raises `JaxgeoError` when the rings are too far apart for any catenoid.
    """
    d, big_r = float(ring_distance), float(ring_radius)
    x_star = scipy.optimize.brentq(
        lambda x: x * math.tanh(x) - 1.0, 0.5, 2.0, xtol=1e-15
    )
    c_star = d / (2.0 * x_star)
    if _catenoid_residual(c_star, big_r, d) >= 0.0:
        raise JaxgeoError(
            f"no catenoid joins rings of radius {big_r} at distance {d} "
            f"(needs distance/radius < {2 * x_star / math.cosh(x_star):.6f})"
        )
    # larger root in (c*, R]: g(R) = R·cosh(d/(2R)) ≥ R
    c_large = scipy.optimize.brentq(
        _catenoid_residual, c_star, big_r, args=(big_r, d), xtol=1e-15, rtol=1e-15
    )
    # smaller root in (0, c*): g → ∞ as c → 0; g(d/(2·x)) for x large enough is > R
    lo = c_star
    while _catenoid_residual(lo, big_r, d) < 0.0:
        lo *= 0.5
    c_small = scipy.optimize.brentq(
        _catenoid_residual, lo, c_star, args=(big_r, d), xtol=1e-15, rtol=1e-15
    )
    return c_small, c_large


def catenoid_parameter(ring_radius: float = 1.0, ring_distance: float = 1.0) -> float:
    """The waist radius c of the catenoid r(z) = c·cosh(z/c) spanning two coaxial
    rings of radius R at z = ±d/2: the LARGER root of c·cosh(d/(2c)) = R.

    The equation has two roots (R = d = 1: c ≈ 0.235095 and c ≈ 0.848338); the larger
    one is the stable, area-minimising catenoid, the smaller one an unstable
    minimal surface with a thin neck. See `catenoid_parameter_roots`.
    """
    return catenoid_parameter_roots(ring_radius, ring_distance)[1]


def catenoid(
    n_around: int = 72,
    n_height: int = 27,
    ring_radius: float = 1.0,
    ring_distance: float = 1.0,
) -> tuple[Vertices, Faces]:
    """Catenoid x = (r cos θ, r sin θ, z), r(z) = c·cosh(z/c), z ∈ [-d/2, d/2].

    c = `catenoid_parameter(ring_radius, ring_distance)` (the larger root, so the
    boundary rings have radius exactly `ring_radius`). `n_height + 1` rings, equally
    spaced in z, of `n_around` vertices (alternate rings turned by half a step):
    `2·n_around·n_height` faces (default 72 × 27 → 3888). Open mesh with two boundary
    rings; normals point outward (away from the axis).
    """
    if n_around < 3 or n_height < 1:
        raise JaxgeoError("catenoid needs n_around >= 3 and n_height >= 1")
    c = catenoid_parameter(ring_radius, ring_distance)
    half = 0.5 * ring_distance
    z = np.linspace(-half, half, n_height + 1)[:, None]
    theta = _ring_angles(n_height + 1, n_around)
    r = c * np.cosh(z / c)
    v = np.stack([r * np.cos(theta), r * np.sin(theta), z + 0 * theta], axis=-1)
    return v.reshape(-1, 3), _ring_grid_faces(n_height + 1, n_around)


# --------------------------------------------------------------------------- tents


def cone_tent(
    n_around: int = 64,
    n_radial: int = 24,
    outer_radius: float = 1.0,
    inner_radius: float = 0.15,
    height: float = 0.6,
) -> tuple[Vertices, Faces]:
    """Cone tent: membrane of revolution from a low outer ring to a raised inner ring.

    z(r) = H·ln(R/r)/ln(R/r₀) for r₀ ≤ r ≤ R (R = outer_radius, r₀ = inner_radius,
    H = height): the radial solution of Laplace's equation (the small-slope minimal
    surface), z = 0 on the outer ring and z = H on the inner one; the meridian sags.
    Rings are spaced geometrically, r_k = R·(r₀/R)^(k/n_radial), so z_k = H·k/n_radial
    and the triangles keep their shape from rim to peak. `2·n_around·n_radial` faces;
    open mesh with two boundary loops; normals point up.
    """
    if not 0.0 < inner_radius < outer_radius:
        raise JaxgeoError("cone_tent needs 0 < inner_radius < outer_radius")
    if n_around < 3 or n_radial < 1:
        raise JaxgeoError("cone_tent needs n_around >= 3 and n_radial >= 1")
    k = np.arange(n_radial + 1)[:, None] / n_radial
    r = outer_radius * (inner_radius / outer_radius) ** k
    r[-1] = inner_radius
    # z from the formula at the stored r, so the vertices satisfy it to rounding
    z = height * np.log(outer_radius / r) / math.log(outer_radius / inner_radius)
    theta = _ring_angles(n_radial + 1, n_around)
    v = np.stack([r * np.cos(theta), r * np.sin(theta), z + 0 * theta], axis=-1)
    return v.reshape(-1, 3), _ring_grid_faces(n_radial + 1, n_around)


def twin_peak_height(
    x: np.ndarray,
    y: np.ndarray,
    peak_offset: float = 1.0,
    inner_radius: float = 0.15,
    height: float = 0.6,
    decay: float = 1.0,
) -> np.ndarray:
    """Height field of `twin_peak_tent`: z = H·(φ₁ + φ₂ − φ₁φ₂), φᵢ = (r₀/ρᵢ)^decay,
    ρᵢ the distance from (x, y) to the peak centre (±peak_offset, 0).

    φᵢ = 1 on ring i, so z = H exactly on both inner rings; the blend a + b − ab is
    smooth and stays in [0, H]."""
    p1 = (inner_radius / np.hypot(x - peak_offset, y)) ** decay
    p2 = (inner_radius / np.hypot(x + peak_offset, y)) ** decay
    return height * (p1 + p2 - p1 * p2)


def _box_perimeter(half_x: float, half_y: float, n_x: int, n_y: int) -> np.ndarray:
    """Counter-clockwise points on the boundary of [-hx, hx] × [-hy, hy], starting
    at (hx, -hy): `2·n_x` segments along x sides, `2·n_y` along y sides."""
    sx = np.linspace(-half_x, half_x, 2 * n_x + 1)[:-1]
    sy = np.linspace(-half_y, half_y, 2 * n_y + 1)[:-1]
    right = np.stack([np.full_like(sy, half_x), sy], 1)
    top = np.stack([-sx, np.full_like(sx, half_y)], 1)
    left = np.stack([np.full_like(sy, -half_x), -sy], 1)
    bottom = np.stack([sx, np.full_like(sx, -half_y)], 1)
    return np.concatenate([right, top, left, bottom])


def twin_peak_tent(
    peak_offset: float = 1.0,
    half_width: float = 1.0,
    inner_radius: float = 0.15,
    height: float = 0.6,
    decay: float = 1.0,
    n_side: int = 12,
    n_radial: int = 16,
) -> tuple[Vertices, Faces]:
    """Twin-peak tent: a membrane over the rectangle [-2a, 2a] × [-b, b] (a =
    peak_offset, b = half_width) with two raised inner rings of radius r₀ centred at
    (±a, 0), height field z = `twin_peak_height(x, y)` = H·(φ₁ + φ₂ − φ₁φ₂),
    φᵢ = (r₀/ρᵢ)^decay. z = H on both inner rings, low (not level) on the outer
    boundary; no rotational symmetry.

    Each half [0, 2a] × [-b, b] (and its mirror image) is meshed as rings between the
    box boundary (sampled with `2·n_side` segments per side, scaled by the aspect)
    and the inner circle: ring points at distance r₀·(ρ_box/r₀)^t from the centre
    along the ray to the box point, t = 1 … 0 (geometric spacing), cells split along
    alternating diagonals. The halves share the line x = 0, where their vertices
    coincide and are merged. Open, manifold, three boundary loops; normals point up.
    """
    a, b = float(peak_offset), float(half_width)
    if not 0.0 < inner_radius < min(a, b):
        raise JaxgeoError(
            "twin_peak_tent needs 0 < inner_radius < min(peak_offset, half_width)"
        )
    n_x = n_side
    n_y = max(1, round(n_side * b / a))
    box = _box_perimeter(a, b, n_x, n_y)  # relative to the right peak's centre
    n_around = len(box)
    rho_box = np.linalg.norm(box, axis=1)
    unit = box / rho_box[:, None]
    t = np.linspace(1.0, 0.0, n_radial + 1)[:, None]  # ring 0 = box, last = circle
    rho = inner_radius * (rho_box / inner_radius)[None, :] ** t
    pts = unit[None, :, :] * rho[:, :, None]
    pts[0] = box
    pts[-1] = inner_radius * unit
    pts = pts.reshape(-1, 2) + np.array([a, 0.0])
    # quads between ring k (outer) and k + 1: (box direction) × (inward) is up
    idx = np.arange((n_radial + 1) * n_around).reshape(n_radial + 1, n_around)
    faces = []
    for k in range(n_radial):
        lo, up = idx[k], idx[k + 1]
        i = np.arange(n_around)
        j = (i + 1) % n_around
        even = (i + k) % 2 == 0
        t1 = np.where(
            even[:, None],
            np.stack([lo[i], lo[j], up[j]], 1),
            np.stack([lo[i], lo[j], up[i]], 1),
        )
        t2 = np.where(
            even[:, None],
            np.stack([lo[i], up[j], up[i]], 1),
            np.stack([lo[j], up[j], up[i]], 1),
        )
        faces += [t1, t2]
    right_faces = np.concatenate(faces)
    n_half = len(pts)
    mirrored = pts * np.array([-1.0, 1.0]) + 0.0  # no -0.0
    xy = np.concatenate([pts, mirrored])
    all_faces = np.concatenate([right_faces, right_faces[:, ::-1] + n_half])
    # merge the coincident vertices on x = 0 (exactly equal coordinates)
    _, first, inverse = np.unique(xy, axis=0, return_index=True, return_inverse=True)
    order = np.sort(first)
    remap = np.empty(len(first), dtype=np.int64)
    remap[np.argsort(first)] = np.arange(len(first))
    new_index = remap[inverse.ravel()]
    xy = xy[order]
    all_faces = new_index[all_faces]
    z = twin_peak_height(xy[:, 0], xy[:, 1], a, inner_radius, height, decay)
    v = np.column_stack([xy, z])
    return v, all_faces.astype(np.int64)


# --------------------------------------------------------------------------- saddle


def saddle(
    n: int = 32, size: float = 1.0, height: float = 0.5
) -> tuple[Vertices, Faces]:
    """Hyperbolic paraboloid z = h·(x² − y²)/size² over the square [-size, size]²,
    an `(n + 1) × (n + 1)` vertex grid with alternating diagonals: `2n²` faces,
    normals up (positive z component)."""
    if n < 1:
        raise JaxgeoError("saddle needs n >= 1")
    s = np.linspace(-size, size, n + 1)
    x, y = np.meshgrid(s, s, indexing="ij")
    z = height * (x**2 - y**2) / size**2
    v = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    return v, grid_faces(n, n)


# --------------------------------------------------------------------------- sail


def four_point_sail(
    n: int = 16,
    span: float = 6.0,
    high: float = 2.0,
    low: float = 0.0,
    q_cable: float = 6.0,
    q_membrane: float = 1.0,
) -> tuple[Vertices, Faces]:
    """Four-point sail (hypar) form-found by the force density method over the
    square [0, span]² in plan, corners alternately at `low` and `high`, edge-cable
    force density `q_cable`, membrane `q_membrane` (`jaxgeo.formfinding`,
    which also gives the four edge cables by name). `2n²` faces, one boundary
    loop, normals up. Unlike the other surfaces its vertices lie on no analytic
    surface: it is an equilibrium shape."""
    sail = _form_found_sail(n, span, high, low, q_cable, q_membrane)
    return sail.vertices, sail.faces


# --------------------------------------------------------------------------- export

#: The generators `save` (and `jaxgeo surface NAME`) can write, by name.
SURFACES = {
    "catenoid": catenoid,
    "cone_tent": cone_tent,
    "four_point_sail": four_point_sail,
    "icosphere": icosphere,
    "saddle": saddle,
    "twin_peak_tent": twin_peak_tent,
    "uv_sphere": uv_sphere,
}

#: Decimals of OBJ coordinates: 17 keeps a coordinate to ~1e-17 absolute (below
#: float64 rounding for |x| >= 0.1), so a written surface reads back on the surface.
OBJ_DIGITS = 17


def save(name: str, path: str | os.PathLike, **params) -> str:
    """Write the built-in surface `name` (a key of `SURFACES`) to `path`.

    `params` are the generator's keyword arguments, e.g.
    `save("cone_tent", "tent.obj", n_around=48, n_radial=12)`. The format follows
    the extension (anything trimesh writes: .obj, .ply, .stl, .off, ...); vertex
    order is kept. Returns the path written.
    """
    if name not in SURFACES:
        raise JaxgeoError(
            f"unknown surface {name!r}; expected one of {', '.join(sorted(SURFACES))}"
        )
    try:
        v, f = SURFACES[name](**params)
    except TypeError as e:  # a keyword the generator does not take
        raise JaxgeoError(f"surfaces.{name}: {e}") from e
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    if not ext:
        raise JaxgeoError(f"{path}: no extension to choose the format (e.g. .obj)")
    tm = trimesh.Trimesh(v, f, process=False)
    args = ", ".join(f"{k}={val!r}" for k, val in params.items())
    try:
        if ext == "obj":
            # (trimesh imports trimesh.exchange itself)
            text = trimesh.exchange.obj.export_obj(  # pyright: ignore[reportAttributeAccessIssue]
                tm,
                include_normals=False,
                include_color=False,
                include_texture=False,
                digits=OBJ_DIGITS,
                header=f"jaxgeo.surfaces.{name}({args})",
            )
            with open(path, "w") as fh:
                fh.write(text)
        else:
            tm.export(path, file_type=ext)
    except (OSError, ValueError, KeyError) as e:
        raise JaxgeoError(f"could not write {path}: {type(e).__name__}: {e}") from e
    return path
