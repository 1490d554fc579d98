"""Membrane material, design prestress and prestress compensation.

Units: membrane forces and moduli per unit width (kN/m), strains dimensionless,
compensation in percent. Voigt order in a cloth's warp frame: (warp, weft, shear),
stress `(σ_w, σ_f, τ)`, strain `(ε_w, ε_f, γ)` with engineering shear `γ = 2ε_wf`.

**Orthotropic plane stress** (the usual linear model of woven PVC-polyester and
PTFE-glass fabrics, e.g. Forster & Mollaert, *European Design Guide for Tensile
Surface Structures*, 2004, §4): compliance

    S = [[ 1/E_w,   −ν/E_w, 0  ],
         [ −ν/E_w,  1/E_f,  0  ],
         [ 0,       0,      1/G]],

`ν = ν_wf` the Poisson ratio of weft contraction under warp stress; reciprocity
gives `ν_fw = ν E_f/E_w`, so S is symmetric. The stiffness is `Q = S⁻¹`.

**Compensation** `c` (per direction): the cut cloth is the flattened one shrunk so
that, stretched back onto the design surface, its engineering strain in that
direction is `c`: cut length = design length / (1 + c). (Tools that cut at
design length × (1 − c) differ from this by O(c²), 0.1% of c at c = 1%.)
`Compensation` holds a uniform value and optional linear variations towards
boundary lines, as Dlubal RF-CUTTING-PATTERN does: within `reach` of a line the
value blends linearly from the line's own value (at the line) to the uniform one.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import JaxgeoError

__all__ = ["BoundaryCompensation", "Compensation", "Material", "Prestress"]


def _positive(name: str, value: float) -> None:
    if not np.isfinite(value) or value <= 0:
        raise JaxgeoError(f"{name} must be positive and finite, got {value}")


class Material(eqx.Module):
    """An orthotropic plane-stress membrane: warp and weft moduli `e_warp`,
    `e_weft` (kN/m), Poisson ratio `nu` (ν_wf), shear modulus `g` (kN/m)."""

    e_warp: float
    e_weft: float
    nu: float
    g: float

    def __check_init__(self):
        for name in ("e_warp", "e_weft", "g"):
            _positive(name, float(getattr(self, name)))
        nu_fw = self.nu * self.e_weft / self.e_warp
        if not (np.isfinite(self.nu) and self.nu >= 0 and self.nu * nu_fw < 1):
            raise JaxgeoError(
                f"Poisson ratio {self.nu} is not admissible: need 0 <= nu and "
                f"nu² E_f/E_w < 1 (here {self.nu * nu_fw:.3g})"
            )

    def compliance(self) -> Float[Array, "3 3"]:
        """`S`, strain = S · stress (module docstring)."""
        s12 = -self.nu / self.e_warp
        return jnp.array(
            [
                [1.0 / self.e_warp, s12, 0.0],
                [s12, 1.0 / self.e_weft, 0.0],
                [0.0, 0.0, 1.0 / self.g],
            ]
        )

    def stiffness(self) -> Float[Array, "3 3"]:
        """`Q = S⁻¹` in closed form: `Q₁₁ = E_w/D`, `Q₂₂ = E_f/D`,
        `Q₁₂ = ν E_f/D`, `Q₃₃ = G`, `D = 1 − ν² E_f/E_w`."""
        d = 1.0 - self.nu**2 * self.e_weft / self.e_warp
        q12 = self.nu * self.e_weft / d
        return jnp.array(
            [
                [self.e_warp / d, q12, 0.0],
                [q12, self.e_weft / d, 0.0],
                [0.0, 0.0, self.g],
            ]
        )


class Prestress(eqx.Module):
    """Design prestress of the membrane, warp and weft (kN/m), no shear."""

    warp: float
    weft: float

    def stress(self) -> Float[Array, "3"]:
        return jnp.array([self.warp, self.weft, 0.0])

    def strain(self, material: Material) -> Float[Array, "3"]:
        """The strain that carries this prestress: `S · (p_w, p_f, 0)`. A
        compensation equal to it (in %, ×100) makes the reassembled cloth carry
        exactly the design prestress on a developable surface."""
        return material.compliance() @ self.stress()


class BoundaryCompensation(eqx.Module):
    """Compensation `warp`, `weft` (%) on a boundary line (a 3-D polyline
    `(K, 3)`), blending linearly into the uniform value over `reach` (m)."""

    line: Float[np.ndarray, "K 3"] = eqx.field(converter=np.asarray)
    warp: float
    weft: float
    reach: float

    def __check_init__(self):
        if self.line.ndim != 2 or self.line.shape[1] != 3 or len(self.line) < 2:
            raise JaxgeoError(
                f"a boundary line is a (K >= 2, 3) polyline, got {self.line.shape}"
            )
        _positive("reach", float(self.reach))


class Compensation(eqx.Module):
    """Prestress compensation in percent: `warp`, `weft` everywhere, varied
    linearly towards the `boundaries` (module docstring)."""

    warp: float
    weft: float
    boundaries: tuple[BoundaryCompensation, ...] = ()

    def __check_init__(self):
        for v in (self.warp, self.weft):
            if not np.isfinite(v) or not -50.0 < v < 50.0:
                raise JaxgeoError(f"compensation must be in (-50, 50) %, got {v}")

    @property
    def uniform(self) -> bool:
        return len(self.boundaries) == 0

    def at(self, points: ArrayLike) -> Float[np.ndarray, "P 2"]:
        """Compensation strains (fractions, not %) `(c_w, c_f)` at 3-D `points`:
        `c = c₀ + Σ_b (c_b − c₀)·max(0, 1 − d_b/reach_b)`, `d_b` the distance to
        line `b` (numpy; the field is fixed data of a pattern)."""
        p = np.asarray(points, float).reshape(-1, 3)
        base = np.array([self.warp, self.weft]) / 100.0
        out = np.tile(base, (len(p), 1))
        for b in self.boundaries:
            t = np.clip(1.0 - _polyline_distance(p, b.line) / b.reach, 0.0, 1.0)
            out += t[:, None] * (np.array([b.warp, b.weft]) / 100.0 - base)
        return out


def _polyline_distance(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance from each point `(P, 3)` to the polyline `(K, 3)`."""
    a, b = line[:-1], line[1:]
    d = b - a
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    t = np.clip(np.einsum("pij,ij->pi", p[:, None] - a[None], d) / dd, 0.0, 1.0)
    q = a[None] + t[..., None] * d[None]
    return np.linalg.norm(p[:, None] - q, axis=-1).min(axis=1)
