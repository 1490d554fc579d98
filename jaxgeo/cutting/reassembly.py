"""Reassembly check: the cut cloths forced back onto the design surface.

Each triangle of a cut cloth (flat, compensated, warp along +x) is mapped onto
its triangle of the design surface, which is held fixed (the model assumes the
installed shape equals the design shape; docs/cutting.md). Per triangle
(constant-strain triangle, CST):

- deformation gradient `F = [x₁−x₀, x₂−x₀] · [X₁−X₀, X₂−X₀]⁻¹` (3×2, flat → 3-D);
- right stretch `U = √(FᵀF)` in the warp frame, closed form for 2×2 SPD
  `C = FᵀF`: `U = (C + √det C · I) / √(tr C + 2√det C)`;
- engineering (Biot) strain `ε = (U₁₁ − 1, U₂₂ − 1, 2U₁₂)` — a cloth shrunk by
  1/(1 + c) and stretched back has ε = c exactly;
- stress `σ = Q ε` (`Material.stiffness`, warp frame, kN/m);
- deviation from the design prestress `Δ = σ − (p_w, p_f, 0)`, magnitude
  `d = √(Δσ_w² + Δσ_f² + 2τ²)` (the Frobenius norm of the stress difference).

Statistics: max |d|, RMS weighted by the design triangle areas
`√(Σ A d² / Σ A)`, and the area-weighted mean.
All functions are jax.numpy (differentiable, vmappable).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .compensate import CutCloth
from .material import Material, Prestress

__all__ = [
    "Reassembly",
    "biot_strain",
    "deviation",
    "reassemble",
    "stats",
    "triangle_stress",
]


def biot_strain(
    flat: Float[Array, "F 3 2"], design: Float[Array, "F 3 3"]
) -> Float[Array, "F 3"]:
    """Engineering strain `(ε_w, ε_f, γ)` of each flat triangle mapped onto its
    design triangle (module docstring; flat x = warp)."""
    e2 = jnp.stack([flat[:, 1] - flat[:, 0], flat[:, 2] - flat[:, 0]], -1)  # (F,2,2)
    e3 = jnp.stack([design[:, 1] - design[:, 0], design[:, 2] - design[:, 0]], -1)
    # C = e2⁻ᵀ (e3ᵀ e3) e2⁻¹
    g = jnp.einsum("fki,fkj->fij", e3, e3)
    inv = jnp.linalg.inv(e2)
    c = jnp.einsum("fki,fkl,flj->fij", inv, g, inv)
    s = jnp.sqrt(jnp.linalg.det(c))
    t = jnp.sqrt(c[:, 0, 0] + c[:, 1, 1] + 2.0 * s)
    u = (c + s[:, None, None] * jnp.eye(2)) / t[:, None, None]
    return jnp.stack([u[:, 0, 0] - 1.0, u[:, 1, 1] - 1.0, 2.0 * u[:, 0, 1]], -1)


def triangle_stress(
    flat: Float[Array, "F 3 2"], design: Float[Array, "F 3 3"], material: Material
) -> Float[Array, "F 3"]:
    """Stress `(σ_w, σ_f, τ)` (kN/m) of each reassembled triangle."""
    return biot_strain(flat, design) @ material.stiffness().T


def deviation(stress: Float[Array, "F 3"], prestress: Prestress) -> Float[Array, " F"]:
    """`d = √(Δσ_w² + Δσ_f² + 2τ²)` per triangle (kN/m)."""
    dv = stress - prestress.stress()
    return jnp.sqrt(dv[:, 0] ** 2 + dv[:, 1] ** 2 + 2.0 * dv[:, 2] ** 2)


def design_areas(design: Float[Array, "F 3 3"]) -> Float[Array, " F"]:
    n = jnp.cross(design[:, 1] - design[:, 0], design[:, 2] - design[:, 0])
    return 0.5 * jnp.linalg.norm(n, axis=-1)


def stats(d: Float[Array, " F"], area: Float[Array, " F"]) -> dict[str, Array]:
    """`max`, `rms` (area-weighted) and area-weighted `mean` of deviations."""
    w = area / jnp.sum(area)
    return {
        "max": jnp.max(d),
        "rms": jnp.sqrt(jnp.sum(w * d**2)),
        "mean": jnp.sum(w * d),
    }


@dataclasses.dataclass
class Reassembly:
    """Per cloth: `stress` `(F, 3)` (warp frame, kN/m), `deviation` `(F,)` and
    the design triangle `area` `(F,)`; `summary()` for reports."""

    stress: list[np.ndarray]
    deviation: list[np.ndarray]
    area: list[np.ndarray]

    def cloth_stats(self, k: int) -> dict[str, float]:
        s = stats(jnp.asarray(self.deviation[k]), jnp.asarray(self.area[k]))
        return {key: float(v) for key, v in s.items()}

    def total_stats(self) -> dict[str, float]:
        s = stats(
            jnp.asarray(np.concatenate(self.deviation)),
            jnp.asarray(np.concatenate(self.area)),
        )
        return {key: float(v) for key, v in s.items()}


def reassemble(
    cloths: list[CutCloth], material: Material, prestress: Prestress
) -> Reassembly:
    """Stress and deviation of every cut cloth stretched onto the design."""
    stress, dev, area = [], [], []
    for c in cloths:
        design = jnp.asarray(c.cloth.vertices3d[c.faces])
        s = triangle_stress(jnp.asarray(c.uv[c.faces]), design, material)
        stress.append(np.asarray(s))
        dev.append(np.asarray(deviation(s, prestress)))
        area.append(np.asarray(design_areas(design)))
    return Reassembly(stress, dev, area)
