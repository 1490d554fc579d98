"""The stress objective as one JAX function of the seam-end parameters.

`x = (s_a, s_b)` (normalised arc lengths of the seam ends, `jaxgeo.seams.Layout`)
→ seam ends on the boundary (`boundary.packed_point`) → geodesics
(`jax.vmap` of `jaxgeo.shortest_path`, differentiable points) → cut vertices (a
fixed weighted sum of mesh vertices and seam points, `CutMesh.sources`: the cut
topology is held at a **template** built at some layout) → each cloth flattened
by least edge-length strain (Gauss–Newton, `optimistix.least_squares`,
differentiated implicitly through the optimality condition, not through its
iterations) → turned to its warp (the template's angle) and shrunk by the
uniform compensation → reassembly stress (`reassembly`) →

    J = rms_dev / |p|  +  λ_waste · waste  +  λ_fit · Σ_c relu(w_c/W − 1)²,

`rms_dev` the area-weighted RMS stress deviation, `|p|` the norm of the design
prestress, `waste = Σ_c (W − w_c)·ℓ_c / Σ_c A_c` the roll left beside each
cloth (width `w_c` across the warp, length `ℓ_c` along it, area `A_c`), `W` the
roll width. The flattening's rigid motions are fixed by three gauge residuals
(centroid and mean rotation against the template's flat cloth) that vanish at
the optimum, so they do not bias it; padded vertices (cloths are padded to one
size so that they vmap) are pinned.

The template is valid while every geodesic keeps the template's sequence of
mesh elements; `evaluate` then returns `valid = True`. Away from it the cut
changes and a new template is needed (`optimise`).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, Int

from .._errors import JaxgeoError
from ..boundary import PackedLoops, packed_point
from ..geodesic import shortest_path
from ..mesh import Mesh
from ..methods import Method
from ..path import Status
from .compensate import CutCloth
from .material import Material, Prestress
from .reassembly import biot_strain, deviation

__all__ = ["Settings", "Template", "evaluate", "make_template"]

INSET = 1e-6  # as jaxgeo.seams.INSET
#: largest cloth capacity (vertices) flattened with a dense QR by solver="auto"
QR_LIMIT = 256


class Settings(eqx.Module):
    """Fixed data of the objective: material, prestress, uniform compensation
    strains `(c_w, c_f)`, roll width, weights, geodesic method and capacity."""

    material: Material
    prestress: Prestress
    compensation: tuple[float, float]
    roll_width: float
    waste: float = 0.1
    fit: float = 10.0
    method: Method = eqx.field(static=True, default="laser")
    max_points: int = eqx.field(static=True, default=160)
    #: linear solver of the flattening's Gauss-Newton steps and its adjoint:
    #: "qr" (dense: ~1e10 flops per step for a cloth of 1000 faces), "lsmr"
    #: (matrix-free: one JVP and one VJP per iteration), or "auto": QR up to
    #: `QR_LIMIT` cloth vertices (the template's capacity), LSMR above. On the
    #: 6-cloth cone of tests/test_cutting_objective.py both give J within 1e-9
    #: relative, LSMR 4x faster; but on the four-point sail the Gauss-Newton
    #: steps with LSMR do not meet their tolerance in 30 steps (the result is
    #: right to 1e-10, yet reported unconverged, so J = inf).
    solver: str = eqx.field(static=True, default="auto")


class Template(eqx.Module):
    """The cut topology at one layout, padded to fixed capacities (arrays only,
    so a new template of the same capacities does not recompile)."""

    packed: PackedLoops
    loop_a: Int[Array, " N"]
    loop_b: Int[Array, " N"]
    kinds: Int[Array, "N M"]
    elements: Int[Array, "N M"]
    count: Int[Array, " N"]
    src_idx: Int[Array, "V K"]
    src_w: Float[Array, "V K"]
    verts: Int[Array, "C Vc"]
    vmask: Float[Array, "C Vc"]
    edges: Int[Array, "C E 2"]
    ew: Float[Array, "C E"]
    faces: Int[Array, "C Fc 3"]
    fmask: Float[Array, "C Fc"]
    uv0: Float[Array, "C Vc 2"]
    rot: Float[Array, "C 2 2"]


@dataclasses.dataclass(frozen=True)
class Capacity:
    vertices: int  # cut-mesh vertices
    cloth_vertices: int
    cloth_edges: int
    cloth_faces: int

    @staticmethod
    def of(cut, cloths, margin: float = 1.3) -> Capacity:
        def up(n):
            return int(32 * np.ceil(margin * n / 32))

        return Capacity(
            up(len(cut.vertices)),
            up(max(len(c.cloth.vertices3d) for c in cloths)),
            up(max(len(_edges(c.faces)) for c in cloths)),
            up(max(len(c.faces) for c in cloths)),
        )


def _edges(faces: np.ndarray) -> np.ndarray:
    from ..pattern import edge_table

    return edge_table(faces)[0]


def make_template(
    mesh: Mesh,
    layout,
    paths,
    cut,
    cloths: list[CutCloth],
    capacity: Capacity | None = None,
    seam_weight: float = 10.0,
) -> tuple[Template, Capacity]:
    """The template of `layout` from its traced `paths`, `cut` and compensated
    cloths (`compensate.compensate_pattern`, uniform compensation). The paths
    must be traced with the objective's method and capacity
    (`Settings.method`, `Settings.max_points`; `jaxgeo.seams.cut` defaults to
    the exact method), else `evaluate` finds the template broken (`valid`
    false)."""
    cap = capacity or Capacity.of(cut, cloths)
    m = int(paths.points.shape[1])
    idx, w = cut.sources(mesh.n_vertices, m)
    nv = len(idx)
    if nv > cap.vertices:
        raise JaxgeoError(f"{nv} cut vertices exceed the template's {cap.vertices}")
    pad = cap.vertices - nv
    idx = np.concatenate([idx, np.zeros((pad, idx.shape[1]), np.int64)])
    w = np.concatenate([w, np.zeros((pad, w.shape[1]))])
    w[nv:, 0] = 1.0
    C = len(cloths)
    verts = np.zeros((C, cap.cloth_vertices), np.int64)
    vmask = np.zeros((C, cap.cloth_vertices))
    edges = np.zeros((C, cap.cloth_edges, 2), np.int64)
    ew = np.zeros((C, cap.cloth_edges))
    faces = np.zeros((C, cap.cloth_faces, 3), np.int64)
    fmask = np.zeros((C, cap.cloth_faces))
    uv0 = np.zeros((C, cap.cloth_vertices, 2))
    rot = np.zeros((C, 2, 2))
    for k, cc in enumerate(cloths):
        c = cc.cloth
        assert c.vertex_ids is not None  # (make_pattern sets it)
        n, f = len(c.vertex_ids), c.faces
        e = _edges(f)
        if n > cap.cloth_vertices or len(e) > cap.cloth_edges:
            raise JaxgeoError("a cloth outgrew the template's capacity")
        if len(f) > cap.cloth_faces:
            raise JaxgeoError("a cloth outgrew the template's capacity")
        seam = {frozenset(p) for s in c.seams.values() for p in np.asarray(s).tolist()}
        verts[k, :n] = c.vertex_ids
        vmask[k, :n] = 1.0
        edges[k, : len(e)] = e
        ew[k, : len(e)] = [
            seam_weight if frozenset(p) in seam else 1.0 for p in e.tolist()
        ]
        faces[k, : len(f)] = f
        fmask[k, : len(f)] = 1.0
        uv0[k, :n] = c.uv
        a = cc.warp_angle
        rot[k] = [[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]
    t = Template(
        layout.packed,
        jnp.asarray(layout.loop_a),
        jnp.asarray(layout.loop_b),
        jnp.asarray(paths.kinds),
        jnp.asarray(paths.elements),
        jnp.asarray(paths.count),
        *(
            jnp.asarray(a)
            for a in (idx, w, verts, vmask, edges, ew, faces, fmask, uv0, rot)
        ),
    )
    return t, cap


def _safe_norm(d):
    return jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-30)


def _gauss_newton(name: str, n_vertices: int) -> optx.GaussNewton:
    if name == "auto":
        name = "qr" if n_vertices <= QR_LIMIT else "lsmr"
    if name == "qr":
        return optx.GaussNewton(rtol=1e-10, atol=1e-12, linear_solver=lx.QR())
    if name == "lsmr":
        # an iterative solve's steps carry ~1e-10 of error: the Gauss-Newton
        # tolerance is set above it (a tighter one is never met)
        ls = lx.LSMR(rtol=1e-12, atol=1e-12, max_steps=4 * n_vertices)
        return optx.GaussNewton(rtol=1e-8, atol=1e-10, linear_solver=ls)
    raise JaxgeoError(f"unknown flattening solver {name!r}; use auto, qr or lsmr")


def _flatten(x3, edges, ew, vmask, uv0, solver="auto"):
    """Least edge-length strain flattening of one padded cloth (implicit
    differentiation in `x3` through optimistix's adjoint)."""
    i, j = edges[:, 0], edges[:, 1]
    L = _safe_norm(x3[i] - x3[j])
    sw = jnp.sqrt(ew) / jnp.where(ew > 0, L, 1.0)
    nv = jnp.sum(vmask)
    c0 = jnp.sum(uv0 * vmask[:, None], 0) / nv
    r0 = (uv0 - c0) * vmask[:, None]
    scale = jnp.sqrt(jnp.sum(r0 * r0))

    def residuals(u, args):
        L, sw = args
        d = u[i] - u[j]
        r_e = sw * (_safe_norm(d) - L)
        pins = (1.0 - vmask)[:, None] * u
        c = jnp.sum(u * vmask[:, None], 0) / nv - c0
        rotn = jnp.sum(r0[:, 0] * u[:, 1] - r0[:, 1] * u[:, 0]) / scale
        return r_e, pins, c / scale, rotn / scale

    solver = _gauss_newton(solver, uv0.shape[0])
    sol = optx.least_squares(
        residuals,
        solver,
        jax.lax.stop_gradient(uv0),
        args=(L, sw),
        max_steps=30,
        throw=False,
    )
    return sol.value, sol.result == optx.RESULTS.successful


def evaluate(
    x: Float[Array, " 2N"], mesh: Mesh, template: Template, settings: Settings
) -> tuple[Float[Array, ""], dict]:
    """`J(x)` (module docstring) and its parts: `rms`, `max` (stress deviation,
    kN/m), `waste`, `fit`, `widths` `(C,)`, `valid` (the template still holds
    and every solve succeeded)."""
    t, s = template, settings
    n = t.loop_a.shape[0]

    def seam(la, lb, a, b):
        p1 = packed_point(mesh, t.packed, la, a, INSET)
        p2 = packed_point(mesh, t.packed, lb, b, INSET)
        return shortest_path(
            mesh, p1, p2, method=s.method, max_points=s.max_points, throw=False
        )

    paths = jax.vmap(seam)(t.loop_a, t.loop_b, x[:n], x[n:])
    m = jnp.arange(paths.kinds.shape[1])[None] < t.count[:, None]
    same = (
        jnp.all(paths.count == t.count)
        & jnp.all(jnp.where(m, paths.kinds == t.kinds, True))
        & jnp.all(jnp.where(m, paths.elements == t.elements, True))
        & jnp.all(paths.status == Status.SUCCESS)
    )
    src = jnp.concatenate([mesh.vertices, paths.points.reshape(-1, 3)])
    x3 = jnp.sum(src[t.src_idx] * t.src_w[..., None], axis=1)
    cw, cf = s.compensation
    shrink = jnp.array([1.0 / (1.0 + cw), 1.0 / (1.0 + cf)])

    def cloth(verts, vmask, edges, ew, faces, fmask, uv0, rot):
        xc = x3[verts]
        u, ok = _flatten(xc, edges, ew, vmask, uv0, s.solver)
        cutuv = (u @ rot.T) * shrink
        # padded faces get a unit right triangle on both sides (zero strain)
        unit2 = jnp.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        unit3 = jnp.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        live = fmask[:, None, None] > 0
        flat = jnp.where(live, cutuv[faces], unit2)
        design = jnp.where(live, xc[faces], unit3)
        stress = biot_strain(flat, design) @ s.material.stiffness().T
        d = deviation(stress, s.prestress)
        nrm = jnp.cross(design[:, 1] - design[:, 0], design[:, 2] - design[:, 0])
        area = 0.5 * _safe_norm(nrm) * fmask
        y = cutuv[:, 1]
        big = jnp.max(jnp.abs(cutuv)) + 1.0
        width = jnp.max(jnp.where(vmask > 0, y, -big)) - jnp.min(
            jnp.where(vmask > 0, y, big)
        )
        xs = cutuv[:, 0]
        length = jnp.max(jnp.where(vmask > 0, xs, -big)) - jnp.min(
            jnp.where(vmask > 0, xs, big)
        )
        return d, area, width, length, ok

    d, area, width, length, ok = jax.vmap(cloth)(
        t.verts, t.vmask, t.edges, t.ew, t.faces, t.fmask, t.uv0, t.rot
    )
    total = jnp.sum(area)
    rms = jnp.sqrt(jnp.sum(area * d**2) / total)
    dmax = jnp.max(jnp.where(t.fmask > 0, d, 0.0))
    p = jnp.linalg.norm(s.prestress.stress())
    waste = jnp.sum((s.roll_width - width) * length) / total
    fit = jnp.sum(jax.nn.relu(width / s.roll_width - 1.0) ** 2)
    j = rms / p + s.waste * waste + s.fit * fit
    valid = same & jnp.all(ok)
    return j, {
        "rms": rms,
        "max": dmax,
        "waste": waste,
        "fit": fit,
        "widths": width,
        "valid": valid,
    }
