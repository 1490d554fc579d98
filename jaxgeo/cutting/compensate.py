"""Warp direction per cloth and the compensated (cut) shape of each cloth.

A flattened cloth (`jaxgeo.pattern.Cloth`, design lengths) is turned so its warp
runs along +x (the roll) and shrunk in its warp/weft frame by the compensation
(`material.Compensation`): every face's target map is
`A_t = diag(1/(1 + c_w), 1/(1 + c_f))`, and the cut shape `u` solves the linear
least squares

    min_u  Σ_t Σ_{edges ij of t}  |(u_j − u_i) − A_t (X_j − X_i)|² / |X_j − X_i|²

(`X` the flattened cloth). For uniform compensation the residual is zero and `u`
is `X` scaled exactly; a varying field is met in the least-squares sense.

**Warp direction** (`warp=`): `"principal"` (default) the major principal axis of
the flat cloth's area (second moment), `"strip"` the direction of its strip of
least width (least roll width), a number per cloth (angle in radians in the
cloth's `uv` frame), or a 3-D direction shared by all cloths (projected onto
each face and mapped into the flat cloth, area-weighted mean).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jaxtyping import Float, Int

from .._errors import JaxgeoError
from .flatten import Cloth, Pattern
from .material import Compensation

__all__ = [
    "CutCloth",
    "compensate_cloth",
    "compensate_pattern",
    "principal_angle",
    "rotate",
    "warp_angle_of_direction",
]


def rotate(uv: np.ndarray, angle: float) -> np.ndarray:
    """Points turned by −`angle`: a direction at `angle` ends up along +x."""
    c, s = np.cos(angle), np.sin(angle)
    return uv @ np.array([[c, -s], [s, c]])


def _areas(uv: np.ndarray, faces: np.ndarray) -> np.ndarray:
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    return 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])


def principal_angle(uv: Float[np.ndarray, "V 2"], faces: Int[np.ndarray, "F 3"]):
    """Angle of the major principal axis of the flat region's area (second moment
    of area about the centroid, exact for triangles)."""
    a = _areas(uv, faces)
    p = uv[faces]  # (F, 3, 2)
    c = p.mean(axis=1)
    centroid = (a[:, None] * c).sum(0) / a.sum()
    q = p - centroid
    # ∫ x xᵀ over a triangle = A/12 (Σ q_i q_iᵀ + (Σ q_i)(Σ q_i)ᵀ)
    s = q.sum(axis=1)
    m = np.einsum("fki,fkj->fij", q, q) + np.einsum("fi,fj->fij", s, s)
    m = (a[:, None, None] / 12.0 * m).sum(0)
    w, v = np.linalg.eigh(m)
    d = v[:, np.argmax(w)]
    return float(np.arctan2(d[1], d[0]))


def warp_angle_of_direction(cloth: Cloth, direction: np.ndarray) -> float:
    """The flat angle of a 3-D direction in `cloth` (module docstring)."""
    d = np.asarray(direction, float)
    x, u, f = cloth.vertices3d, cloth.uv, cloth.faces
    e3 = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], -1)  # (F,3,2)
    e2 = np.stack([u[f[:, 1]] - u[f[:, 0]], u[f[:, 2]] - u[f[:, 0]]], -1)  # (F,2,2)
    m = e3 @ np.linalg.inv(e2)  # (F, 3, 2): flat → 3-D, per face
    # the flat direction whose image is nearest to d (least squares per face)
    t = np.einsum("fij,j->fi", np.linalg.pinv(m), d)
    n = np.linalg.norm(t, axis=1)
    if not np.all(n > 0):
        raise JaxgeoError("the warp direction is normal to the surface somewhere")
    t = t / n[:, None]
    # average an axis (sign-free): doubled angles
    w = np.abs(_areas(u, f)) * n
    two = 2.0 * np.arctan2(t[:, 1], t[:, 0])
    ang2 = np.arctan2((w * np.sin(two)).sum(), (w * np.cos(two)).sum())
    return float(0.5 * ang2)


@dataclasses.dataclass
class CutCloth:
    """One cloth ready to cut.

    - `cloth`: the flattened cloth (design lengths, `jaxgeo.pattern.Cloth`).
    - `warp_angle`: warp direction in `cloth.uv` (radians).
    - `flat`: `cloth.uv` turned so the warp runs along +x, `(V, 2)`.
    - `uv`: the compensated cut shape in the same frame, lowest corner at 0.
    - `compensation`: per face `(c_w, c_f)` (strains, not %).
    """

    cloth: Cloth
    warp_angle: float
    flat: np.ndarray
    uv: np.ndarray
    compensation: np.ndarray

    @property
    def faces(self) -> np.ndarray:
        return self.cloth.faces

    @property
    def net_width(self) -> float:
        """Extent across the warp of the compensated cloth (no allowances)."""
        return float(np.ptp(self.uv[:, 1]))


def compensate_cloth(
    flat: Float[np.ndarray, "V 2"],
    faces: Int[np.ndarray, "F 3"],
    comp: Float[np.ndarray, "F 2"],
) -> np.ndarray:
    """The cut shape of a flat cloth (warp along x) for per-face compensation
    strains `comp` (module docstring); exact scaling when `comp` is uniform."""
    comp = np.asarray(comp, float)
    if np.all(comp == comp[0]):
        return flat / (1.0 + comp[0])
    n = len(flat)
    rows, cols, vals, rhs = [], [], [], []
    r = 0
    for k in range(3):
        i, j = faces[:, k], faces[:, (k + 1) % 3]
        d = flat[j] - flat[i]
        w = 1.0 / np.linalg.norm(d, axis=1)
        for ax in range(2):
            idx = np.arange(len(faces)) + r
            rows += [idx, idx]
            cols += [2 * j + ax, 2 * i + ax]
            vals += [w, -w]
            rhs.append(w * d[:, ax] / (1.0 + comp[:, ax]))
            r += len(faces)
    # gauge: the centroid stays where the uniformly scaled one would be
    for ax in range(2):
        rows.append(np.full(n, r))
        cols.append(2 * np.arange(n) + ax)
        vals.append(np.full(n, 1.0 / n))
        r += 1
    rhs.append(flat.mean(axis=0) / (1.0 + comp.mean(axis=0)))
    A = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(r, 2 * n),
    )
    sol = spla.spsolve((A.T @ A).tocsc(), A.T @ np.concatenate(rhs))
    return sol.reshape(n, 2)


def _warp_angles(pattern: Pattern, warp) -> list[float]:
    cl = pattern.cloths
    if warp is None or (isinstance(warp, str) and warp == "principal"):
        return [principal_angle(c.uv, c.faces) for c in cl]
    if isinstance(warp, str) and warp == "strip":
        return [0.0] * len(cl)
    if isinstance(warp, str):
        raise JaxgeoError(
            f"unknown warp {warp!r}; use 'principal', 'strip', one angle per "
            "cloth or a 3-D direction"
        )
    w = np.asarray(warp, float)
    if w.shape == (3,):
        return [warp_angle_of_direction(c, w) for c in cl]
    if w.shape == (len(cl),):
        return w.tolist()
    raise JaxgeoError(
        f"warp must be one angle per cloth ({len(cl)}) or a 3-D direction, "
        f"got shape {w.shape}"
    )


def compensate_pattern(
    pattern: Pattern,
    compensation: Compensation,
    warp: str | Sequence[float] | np.ndarray | None = "principal",
) -> list[CutCloth]:
    """Every cloth of `pattern` turned to its warp and compensated."""
    out = []
    for c, ang in zip(pattern.cloths, _warp_angles(pattern, warp)):
        flat = rotate(c.uv, ang)
        centroids = c.vertices3d[c.faces].mean(axis=1)
        comp = compensation.at(centroids)
        uv = compensate_cloth(flat, c.faces, comp)
        shift = uv.min(axis=0)
        out.append(CutCloth(c, float(ang), flat - shift, uv - shift, comp))
    return out
