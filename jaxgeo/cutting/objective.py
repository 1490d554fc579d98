"""The stress objective as one JAX function of the seam-end parameters.

`x = (s_a, s_b)` (normalised arc lengths of the seam ends, `jaxgeo.seams.Layout`)
→ seam ends on the boundary (`boundary.packed_point`) → geodesics
(`jax.vmap` of `jaxgeo.shortest_path`, differentiable points) → cut vertices (a
fixed weighted sum of mesh vertices and seam points, `CutMesh.sources`: the cut
topology is held at a **template** built at some layout) → each cloth flattened
by least edge-length strain with the one-sided area term of
`_least_strain` (Gauss-Newton then Newton steps in JAX, each a
block-tridiagonal Cholesky of the system in reverse Cuthill-McKee order,
`_jax_newton`; fixed shapes, so it runs under jit, vmap and grad on CPU and
GPU; started from the template's converged flattening; differentiated
implicitly through the optimality condition, not through its iterations:
`jax.custom_jvp` with one banded solve of the Hessian per tangent or
cotangent, `jax.lax.custom_linear_solve`) → turned to its warp (the template's
angle) and shrunk by the uniform compensation → reassembly stress (`reassembly`) →

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
from functools import partial

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
from . import _least_strain as strain
from ._least_strain import (
    AREA_FLOOR,
    AREA_HESSIAN,
    AREA_WEIGHT,
    GN_ATOL,
    GN_RTOL,
    HOST_STEPS,
    NEWTON_NEAR,
    STALL_TOL,
)
from .compensate import CutCloth
from .material import Material, Prestress
from .reassembly import biot_strain, deviation

__all__ = ["Settings", "Template", "evaluate", "make_template", "trace_seams"]

INSET = 1e-6  # as jaxgeo.seams.INSET
#: Gauss-Newton steps of the flattening (solvers "qr", "lsmr"); the other
#: tolerances and step counts are `_least_strain`'s (`GN_RTOL`, ...)
GN_STEPS = 30


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
    #: linear solver of the flattening's Newton steps and its adjoint:
    #: "banded" (default; JAX only, fixed shapes: Gauss-Newton then Newton
    #: steps, each one block-tridiagonal Cholesky of the system reordered by
    #: reverse Cuthill-McKee, `_jax_newton`; the adjoint one more), "sparse"
    #: (the same iteration on the host, scipy `splu` inside `jax.pure_callback`:
    #: a reference, not jit-portable to GPU), "qr" (optimistix's Gauss-Newton,
    #: dense QR of the Jacobian: ~1e10 flops per step for a cloth of 1000
    #: faces; linear convergence, J = inf at the twin-peak tent's start layout)
    #: or "lsmr" (matrix-free: one JVP and one VJP per iteration; on the
    #: four-point sail its Gauss-Newton steps do not meet their tolerance in 30
    #: steps).
    solver: str = eqx.field(static=True, default="banded")


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
    #: each vertex's place in the cloth's reverse Cuthill-McKee order (padded
    #: vertices last), and 0 at the three coordinates that fix the gauge in a
    #: banded solve (`_gauge_pins`), else 1
    pos: Int[Array, "C Vc"]
    free: Float[Array, "C Vc 2"]
    #: shapes only: one block of the banded solve (block x blocks >= 2 Vc)
    blocks: Float[Array, "B b"]


@dataclasses.dataclass(frozen=True)
class Capacity:
    vertices: int  # cut-mesh vertices
    cloth_vertices: int
    cloth_edges: int
    cloth_faces: int
    block: int = 64  # block size of the banded solve (> its bandwidth in dofs)

    @staticmethod
    def of(cut, cloths, margin: float = 1.3) -> Capacity:
        def up(n, k=32):
            return int(k * np.ceil(margin * n / k))

        band = max(_order(_edges(c.faces), len(c.cloth.vertices3d))[1] for c in cloths)
        return Capacity(
            up(len(cut.vertices)),
            up(max(len(c.cloth.vertices3d) for c in cloths)),
            up(max(len(_edges(c.faces)) for c in cloths)),
            up(max(len(c.faces) for c in cloths)),
            up(2 * band + 2, 8),
        )


def _order(edges: np.ndarray, n: int) -> tuple[np.ndarray, int]:
    """Reverse Cuthill-McKee place of each of `n` vertices (scipy, at template
    time) and the largest place difference across an edge (the bandwidth)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    a = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), (n, n))
    perm = reverse_cuthill_mckee((a + a.T).tocsr(), symmetric_mode=True)
    pos = np.empty(n, np.int64)
    pos[perm] = np.arange(n)
    band = int(np.max(np.abs(pos[edges[:, 0]] - pos[edges[:, 1]]), initial=0))
    return pos, band


def _gauge_pins(uv: np.ndarray) -> np.ndarray:
    """Per vertex and coordinate 1, but 0 at the three coordinates a banded
    solve holds fixed to remove the rigid motions: both of the vertex `p`
    farthest from the centroid, and of the vertex `q` farthest from `p` the
    coordinate along which a rotation about `p` moves it most."""
    p = int(np.argmax(np.sum((uv - uv.mean(0)) ** 2, 1)))
    q = int(np.argmax(np.sum((uv - uv[p]) ** 2, 1)))
    dx, dy = uv[q] - uv[p]
    free = np.ones_like(uv)
    free[p] = 0.0
    free[q, int(abs(dx) > abs(dy))] = 0.0  # rotation moves q along (-dy, dx)
    return free


def _edges(faces: np.ndarray) -> np.ndarray:
    from .cut import edge_table

    return edge_table(faces)[0]


def make_template(
    mesh: Mesh,
    layout,
    paths,
    cut,
    cloths: list[CutCloth],
    capacity: Capacity | None = None,
    seam_weight: float = 10.0,
    starts: list | None = None,
    report: list | None = None,
) -> tuple[Template, Capacity]:
    """The template of `layout` from its traced `paths`, `cut` and compensated
    cloths (`compensate.compensate_pattern`, uniform compensation). The paths
    must be traced with the objective's method and capacity
    (`Settings.method`, `Settings.max_points`; `jaxgeo.seams.cut` defaults to
    the exact method), else `evaluate` finds the template broken (`valid`
    false).

    `starts`: per cloth `None` or a second start of its flattening (`(n, 2)`,
    the cloth's vertex order; e.g. the previous template's flattening carried
    over, `optimise`): where the flattening converges from it, the template
    continues that branch (its warp the principal axis of that flattening),
    else starts from the pattern's flattening. `report`, if given, gets per
    cloth `(edge-strain energy from the pattern's flattening, from the start
    or nan, start kept)`."""
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
    pos = np.tile(np.arange(cap.cloth_vertices), (C, 1))
    free = np.ones((C, cap.cloth_vertices, 2))
    # the cut vertices as `evaluate` makes them at this layout
    src = np.concatenate(
        [np.asarray(mesh.vertices), np.asarray(paths.points).reshape(-1, 3)]
    )
    x3 = np.sum(src[idx] * w[..., None], axis=1)
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
        pos[k, :n], band = _order(e, n)
        if 2 * band + 2 > cap.block:
            raise JaxgeoError("a cloth's bandwidth outgrew the template's block")
        xk, ek = x3[c.vertex_ids], ew[k, : len(e)]
        uv_k, _ = strain.converge(xk, e, ek, f, c.uv)
        a, e_fresh, e_start, kept = (
            cc.warp_angle,
            strain.strain_energy(xk, e, ek, f, uv_k),
            np.nan,
            False,
        )
        if starts is not None and starts[k] is not None:
            from .compensate import principal_angle

            uv_s, ok = strain.converge(xk, e, ek, f, np.asarray(starts[k], np.float64))
            e_start = strain.strain_energy(xk, e, ek, f, uv_s)
            if ok:  # continue the start's branch
                uv_k, a, kept = uv_s, principal_angle(uv_s, f), True
        if report is not None:
            report.append((e_fresh, e_start, kept))
        uv0[k, :n] = uv_k
        free[k, :n] = _gauge_pins(uv0[k, :n])
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
        pos=jnp.asarray(pos),
        free=jnp.asarray(free),
        blocks=jnp.zeros((-(-2 * cap.cloth_vertices // cap.block), cap.block)),
    )
    return t, cap


def _safe_norm(d):
    return jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-30)


def _gauss_newton(name: str, n_vertices: int) -> optx.GaussNewton:
    if name == "qr":
        return optx.GaussNewton(rtol=GN_RTOL, atol=GN_ATOL, linear_solver=lx.QR())
    if name == "lsmr":
        # an iterative solve's steps carry ~1e-10 of error: the Gauss-Newton
        # tolerance is set above it (a tighter one is never met)
        ls = lx.LSMR(rtol=1e-12, atol=1e-12, max_steps=4 * n_vertices)
        return optx.GaussNewton(rtol=1e-8, atol=1e-10, linear_solver=ls)
    raise JaxgeoError(
        f"unknown flattening solver {name!r}; use banded, sparse, qr or lsmr"
    )


def _gauge(uv0, vmask):
    """The template's flat centroid `c0`, centred positions `r0` and size."""
    nv = jnp.sum(vmask)
    c0 = jnp.sum(uv0 * vmask[:, None], 0) / nv
    r0 = (uv0 - c0) * vmask[:, None]
    return nv, c0, r0, jnp.sqrt(jnp.sum(r0 * r0))


def _area_params(x3, faces, fmask):
    """`_least_strain.area_params` of a padded cloth: `(A3, sa)` per face, 0 on
    padded faces."""
    p = x3[faces]
    a3 = 0.5 * _safe_norm(jnp.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])) * fmask
    mean = jnp.sum(a3) / jnp.maximum(jnp.sum(fmask), 1.0)
    live = fmask > 0
    a3_safe, mean = jnp.where(live, a3, 1.0), jnp.where(mean > 0, mean, 1.0)
    sa = jnp.where(live, jnp.sqrt(AREA_WEIGHT * a3_safe / mean) / a3_safe, 0.0)
    return a3, sa


def _face_area_residual(p, a3, sa):
    """`_least_strain.area_residuals`' residual of one face with flat corners
    `p` `(3, 2)` (one-sided: zero above `AREA_FLOOR` of its 3-D area)."""
    e1, e2 = p[1] - p[0], p[2] - p[0]
    a2 = 0.5 * (e1[0] * e2[1] - e1[1] * e2[0])
    return sa * jnp.minimum(a2 - AREA_FLOOR * a3, 0.0)


def _area_residuals(u, faces, a3, sa):
    """The area term's residuals of every face (`_face_area_residual`)."""
    return jax.vmap(_face_area_residual)(u[faces], a3, sa)


def _residuals(u, L, sw, edges, vmask, uv0, area):
    """Weighted edge-length residuals, the area term's residuals (`area` =
    `(faces, A3, sa)`, `_area_params`), pins of the padded vertices, and the
    gauge (centroid and mean rotation against the template's flat cloth, both
    zero at the optimum)."""
    i, j = edges[:, 0], edges[:, 1]
    nv, c0, r0, scale = _gauge(uv0, vmask)
    d = u[i] - u[j]
    r_e = sw * (_safe_norm(d) - L)
    r_f = _area_residuals(u, *area)
    pins = (1.0 - vmask)[:, None] * u
    c = jnp.sum(u * vmask[:, None], 0) / nv - c0
    rotn = jnp.sum(r0[:, 0] * u[:, 1] - r0[:, 1] * u[:, 0]) / scale
    return r_e, r_f, pins, c / scale, rotn / scale


def _flatten(x3, edges, ew, faces, fmask, vmask, uv0, solver="banded", band=None):
    """Least edge-length strain flattening (with the area term) of one padded
    cloth, differentiated implicitly in `x3` (through the optimality
    condition, not the iterations): by `_implicit` for solvers "banded" and
    "sparse", by optimistix's adjoint otherwise. `band`: `(pos, free, shape)`
    of the banded solve (`Template`)."""
    i, j = edges[:, 0], edges[:, 1]
    L = _safe_norm(x3[i] - x3[j])
    sw = jnp.sqrt(ew) / jnp.where(ew > 0, L, 1.0)
    a3, sa = _area_params(x3, faces, fmask)
    uv0 = jax.lax.stop_gradient(uv0)
    if solver == "banded":
        if band is None:
            raise JaxgeoError("the banded flattening needs the template's band")
        Ls, sws, a3s, sas = jax.lax.stop_gradient((L, sw, a3, sa))
        area_s = (faces, a3s, sas)
        u, ok = _jax_newton(Ls, sws, edges, vmask, uv0, area_s, *band)
        # the derivative solves with the Hessian at u by a banded Cholesky,
        # which has a factor only at a minimum: at a saddle (Newton converges
        # to any stationary point) the flattening is not valid
        pos, free, shape = band
        probe = _system_solve(
            u, Ls, sws, edges, vmask, uv0, area_s, pos, free, shape, True, uv0
        )
        ok = ok & jnp.all(jnp.isfinite(probe))
        area = (faces, a3, sa)
        return _implicit(solver, u, L, sw, area, edges, vmask, uv0, *band), ok
    if solver == "sparse":
        shapes = (
            jax.ShapeDtypeStruct(uv0.shape, uv0.dtype),
            jax.ShapeDtypeStruct((), jnp.bool_),
        )
        Ls, sws, a3s, sas = jax.lax.stop_gradient((L, sw, a3, sa))
        u, ok = jax.pure_callback(
            strain.newton,
            shapes,
            Ls,
            sws,
            edges,
            vmask,
            uv0,
            (faces, a3s, sas),
            vmap_method="sequential",
        )
        z = jnp.zeros(0)
        area = (faces, a3, sa)
        return _implicit(solver, u, L, sw, area, edges, vmask, uv0, z, z, z), ok

    def residuals(u, args):
        L, sw, a3, sa = args
        return _residuals(u, L, sw, edges, vmask, uv0, (faces, a3, sa))

    sol = optx.least_squares(
        residuals,
        _gauss_newton(solver, uv0.shape[0]),
        uv0,
        args=(L, sw, a3, sa),
        max_steps=GN_STEPS,
        throw=False,
    )
    return sol.value, sol.result == optx.RESULTS.successful


# ------------------------------------------- the banded flattening (JAX native)
# The same Newton iteration as `_least_strain.newton`, in JAX with fixed shapes (jit,
# vmap, grad; GPU as CPU). The edge part of the system (Gauss-Newton J^T J or
# the Hessian) couples the two ends of an edge only; in each cloth's reverse
# Cuthill-McKee order (`_order`) it is banded, so it is stored as block-
# tridiagonal (blocks of `Capacity.block` >= its bandwidth) and factored by a
# block Cholesky, one `lax.scan` over the blocks: O(n b^2) flops for n dofs
# and block b, where a dense Cholesky takes O(n^3) (1.7 s for the twin-peak
# tent's 16 cloths of 1408 dofs on 2 cores). The dense rank-3 gauge rows
# B^T B would fill the band, so the solve of (H + B^T B) y = b uses that H's
# null space is the rigid motions N (exactly for J^T J; for the Hessian at the
# optimum): z = (B N)^-T N^T b, H x = b - B^T z solved with three coordinates
# held at zero (`Template.free`: a particular solution, H's null space
# removed), then y = x + N (B N)^-1 (z - B x).


def _energy(u, L, sw, edges, vmask, uv0, area):
    r = _residuals(u, L, sw, edges, vmask, uv0, area)
    return 0.5 * sum(jnp.sum(x * x) for x in r)


def _rigid(u, vmask):
    """The rigid motions at `u` (x, y translation, rotation about the
    centroid), `(3, Vc, 2)`, zero on padded vertices."""
    nv = jnp.sum(vmask)
    c = jnp.sum(u * vmask[:, None], 0) / nv
    one, zero = vmask, jnp.zeros_like(vmask)
    rot = jnp.stack([-(u[:, 1] - c[1]), u[:, 0] - c[0]], 1) * vmask[:, None]
    return jnp.stack([jnp.stack([one, zero], 1), jnp.stack([zero, one], 1), rot])


def _gauge_rows(uv0, vmask):
    """The gauge residuals' rows B `(3, Vc, 2)` (linear in u, `_residuals`)."""
    nv, _, r0, scale = _gauge(uv0, vmask)
    zero = jnp.zeros_like(vmask)
    b0 = vmask / (nv * scale)
    return jnp.stack(
        [
            jnp.stack([b0, zero], 1),
            jnp.stack([zero, b0], 1),
            jnp.stack([-r0[:, 1], r0[:, 0]], 1) / scale**2,
        ]
    )


def _band_matrix(u, L, sw, edges, vmask, area, pos, free, nblk, nb, full):
    """The edge and area part of the system (Gauss-Newton, or with `full` the
    Hessian of those terms), pins of padded vertices and identity rows at the held
    coordinates, in block-tridiagonal form: diagonal blocks `(nblk, nb, nb)`
    and the blocks below them `(nblk - 1, nb, nb)`, in reordered dofs."""
    i, j = edges[:, 0], edges[:, 1]
    d = u[i] - u[j]
    dn = _safe_norm(d)
    nrm = d / dn[:, None]
    nn = nrm[:, :, None] * nrm[:, None, :]
    s2 = sw * sw
    blk = s2[:, None, None] * nn
    t = jnp.where(full, s2 * (dn - L) / dn, 0.0)
    blk = blk + t[:, None, None] * (jnp.eye(2) - nn)
    # the four node pairs of an edge, +blk on (i,i), (j,j), -blk on (i,j), (j,i)
    a = jnp.stack([i, j, i, j], 1)  # (E, 4)
    b = jnp.stack([i, j, j, i], 1)
    sign = jnp.array([1.0, 1.0, -1.0, -1.0])
    k2 = jnp.arange(2)
    shp = (len(i), 4, 2, 2)
    rows = jnp.broadcast_to(2 * pos[a][:, :, None, None] + k2[:, None], shp)
    cols = jnp.broadcast_to(2 * pos[b][:, :, None, None] + k2[None, :], shp)
    fr = free[a][:, :, :, None] * free[b][:, :, None, :]
    vals = sign[:, None, None] * blk[:, None] * fr
    # the area term: per face J_f^T J_f (+ r_f d2 r_f with full) on the six
    # dofs of its corners, which its edges already couple (the band holds it)
    # (r_f is zero where the term is off, so r_f sa AREA_HESSIAN is its d2 part)
    faces, a3, sa = area
    r_f, jf = jax.vmap(jax.value_and_grad(_face_area_residual))(u[faces], a3, sa)
    jf = jf.reshape(-1, 6)
    fblk = jf[:, :, None] * jf[:, None, :]
    fblk = fblk + jnp.where(full, r_f * sa, 0.0)[:, None, None] * AREA_HESSIAN
    fd = (2 * pos[faces][:, :, None] + k2).reshape(-1, 6)
    ffree = free[faces].reshape(-1, 6)
    fshape = fblk.shape
    rows = jnp.concatenate(
        [rows.ravel(), jnp.broadcast_to(fd[:, :, None], fshape).ravel()]
    )
    cols = jnp.concatenate(
        [cols.ravel(), jnp.broadcast_to(fd[:, None, :], fshape).ravel()]
    )
    vals = jnp.concatenate(
        [vals.ravel(), (fblk * ffree[:, :, None] * ffree[:, None, :]).ravel()]
    )
    # diagonal: pins of padded vertices, 1 at held coordinates and beyond 2 Vc
    n = pos.shape[0]
    dof = (2 * pos[:, None] + k2).ravel()
    dval = ((1.0 - vmask)[:, None] * free + (1.0 - free)).ravel()
    rows = jnp.concatenate([rows.ravel(), dof, jnp.arange(2 * n, nblk * nb)])
    cols = jnp.concatenate([cols.ravel(), dof, jnp.arange(2 * n, nblk * nb)])
    vals = jnp.concatenate([vals.ravel(), dval, jnp.ones(nblk * nb - 2 * n)])
    br, bc = rows // nb, cols // nb
    rr, cc = rows % nb, cols % nb
    diag = (
        jnp.zeros((nblk, nb, nb))
        .at[jnp.where(br == bc, br, nblk), rr, cc]
        .add(vals, mode="drop")
    )
    low = jnp.zeros((nblk - 1, nb, nb)).at[jnp.where(br == bc + 1, bc, nblk), rr, cc]
    low = low.add(vals, mode="drop")
    return diag, low


def _band_factor(diag, low):
    """Block Cholesky of a symmetric block-tridiagonal matrix: the inverses of
    the diagonal factors `Lk^-1` and `Wk = E_k Lk^-T` (NaN where it is not
    positive definite). The inverses make every solve matrix products: one
    triangular solve per block here and none in `_band_solve` (jaxlib's
    batched trsm calls, not their flops, dominated on the loaded 2-core CPU)."""
    tri = jax.scipy.linalg.solve_triangular
    eye = jnp.eye(diag.shape[-1])
    i0 = tri(jnp.linalg.cholesky(diag[0]), eye, lower=True)

    def step(ik, xs):
        e, dk1 = xs
        w = e @ ik.T
        ik1 = tri(jnp.linalg.cholesky(dk1 - w @ w.T), eye, lower=True)
        return ik1, (w, ik1)

    _, (w, inv) = jax.lax.scan(step, i0, (low, diag[1:]))
    return jnp.concatenate([i0[None], inv]), w


def _band_solve(fac, rhs):
    """Solve with `_band_factor`'s factors; `rhs` `(nblk, nb)`."""
    inv, w = fac
    y0 = inv[0] @ rhs[0]

    def fwd(y, xs):
        i1, wk, b1 = xs
        y1 = i1 @ (b1 - wk @ y)
        return y1, y1

    _, ys = jax.lax.scan(fwd, y0, (inv[1:], w, rhs[1:]))
    ys = jnp.concatenate([y0[None], ys])
    xl = inv[-1].T @ ys[-1]

    def bwd(x, xs):
        i0, wk, y0 = xs
        x0 = i0.T @ (y0 - wk.T @ x)
        return x0, x0

    _, xs = jax.lax.scan(bwd, xl, (inv[:-1], w, ys[:-1]), reverse=True)
    return jnp.concatenate([xs, xl[None]])


def _system_matvec(u, L, sw, edges, vmask, uv0, area, full, v):
    """The system's matrix times `v`: the Hessian of E (`full`) or J^T J."""

    def res(u):
        return jnp.concatenate(
            [x.ravel() for x in _residuals(u, L, sw, edges, vmask, uv0, area)]
        )

    hv = jax.jvp(
        lambda u: jax.grad(_energy)(u, L, sw, edges, vmask, uv0, area), (u,), (v,)
    )
    jv = jax.jvp(res, (u,), (v,))[1]
    (gn,) = jax.vjp(res, u)[1](jv)
    return jnp.where(full, hv[1], gn)


def _system_solve(u, L, sw, edges, vmask, uv0, area, pos, free, shape, full, b):
    """(H + B^T B + pins) y = b, H the edge part at `u` (module comment above
    `_energy`), and one step of iterative refinement with the exact product
    (`_system_matvec`): the held coordinates give the exact solve only where
    H's null space is the rigid motions (J^T J; the Hessian at the optimum),
    so a Newton step near it is exact to second order. `shape` `(nblk, nb)`
    carries the block sizes."""
    nblk, nb = shape.shape
    fac = _band_factor(
        *_band_matrix(u, L, sw, edges, vmask, area, pos, free, nblk, nb, full)
    )
    n = pos.shape[0]
    live = vmask[:, None]
    nmat = _rigid(u, vmask).reshape(3, -1)  # (3, 2n)
    bmat = _gauge_rows(uv0, vmask).reshape(3, -1)
    bn = bmat @ nmat.T  # (3, 3)
    order = (2 * pos[:, None] + jnp.arange(2)).ravel()

    def apply(b):
        bf = b.reshape(-1)
        z = jnp.linalg.solve(bn.T, nmat @ bf)
        rhs = ((bf - bmat.T @ z).reshape(n, 2) * free * live).ravel()
        # padded vertices: pins only, y = b there
        rhs = rhs + (b * (1.0 - live)).ravel()
        full_rhs = jnp.zeros(nblk * nb).at[order].set(rhs).reshape(nblk, nb)
        x = _band_solve(fac, full_rhs).reshape(-1)[order]
        c = jnp.linalg.solve(bn, z - bmat @ x)
        return (x + nmat.T @ c).reshape(n, 2)

    y = apply(b)
    return y + apply(b - _system_matvec(u, L, sw, edges, vmask, uv0, area, full, y))


def _jax_newton(L, sw, edges, vmask, uv0, area, pos, free, shape, newton=NEWTON_NEAR):
    """`_least_strain.newton` in JAX (`lax.while_loop`, fixed shapes): Gauss-Newton
    steps with a backtracking Armijo line search; Newton steps (the Hessian)
    once the last step was below `newton` times the cloth's size, where the
    Hessian is positive definite and its step descends (else that iteration
    falls back to Gauss-Newton, one step later). Same stopping tests as the
    host. Returns (u, converged)."""

    def energy(u):
        return _energy(u, L, sw, edges, vmask, uv0, area)

    def cond(st):
        return ~st["done"] & (st["k"] < HOST_STEPS)

    def body(st):
        u = st["u"]
        e0, g = jax.value_and_grad(energy)(u)
        size = 1.0 + jnp.max(jnp.abs(u))
        use_newton = (st["last"] < newton * size) & ~st["bad"]
        du = -_system_solve(
            u, L, sw, edges, vmask, uv0, area, pos, free, shape, use_newton, g
        )
        slope = jnp.sum(g * du)
        finite = jnp.all(jnp.isfinite(du))
        bad = use_newton & (~finite | ~(slope < 0))  # retry as Gauss-Newton
        fail = ~use_newton & ~finite  # singular Gauss-Newton matrix
        step = jnp.max(jnp.abs(du))
        du = jnp.where(finite, du, 0.0)
        new = u + du
        e1 = energy(new)
        # a Newton step passes below STALL_TOL (`_least_strain.STALL_TOL`)
        tol = jnp.where(
            use_newton & ~bad,
            STALL_TOL * (1.0 + jnp.max(jnp.abs(new))),
            GN_ATOL + GN_RTOL * jnp.max(jnp.abs(new)),
        )
        conv = ~bad & ~fail & (step < tol) & (jnp.abs(e1 - e0) <= GN_RTOL * e0)

        def ls_cond(c):
            t, e = c
            return (e > e0 + 1e-4 * t * slope) & (t >= 1e-8)

        def ls_body(c):
            t = 0.5 * c[0]
            return t, energy(u + t * du)

        t, _ = jax.lax.while_loop(ls_cond, ls_body, (jnp.asarray(1.0), e1))
        stuck = t < 1e-8
        small = step <= STALL_TOL * size
        move = ~bad & ~fail & (conv | ~stuck)
        u_next = jnp.where(conv, new, jnp.where(move, u + t * du, u))
        done = fail | (~bad & (conv | stuck)) | ~jnp.isfinite(e0)
        ok = ~fail & ~bad & (conv | (stuck & small)) & jnp.isfinite(e0)
        return {
            "u": u_next,
            "k": st["k"] + 1,
            "done": done,
            "ok": ok,
            "bad": bad,
            "last": jnp.where(bad, st["last"], step),
        }

    st = {
        "u": uv0,
        "k": jnp.asarray(0),
        "done": jnp.asarray(False),
        "ok": jnp.asarray(False),
        "bad": jnp.asarray(False),
        "last": jnp.asarray(jnp.inf),
    }
    st = jax.lax.while_loop(cond, body, st)
    return st["u"], st["ok"]


@partial(jax.custom_jvp, nondiff_argnums=(0,))
def _implicit(solver, u, L, sw, area, edges, vmask, uv0, pos, free, shape):
    """`u` (the flattening's optimum for `L`, `sw` and `area`'s `A3`, `sa`),
    with the tangent of the optimum: du = -H^-1 d(grad_u E)/d(L, sw, A3, sa)
    [dL, dsw, dA3, dsa], E = 1/2 |r|^2; the solve with H by `solver`
    ("banded": `_system_solve`; "sparse": the host)."""
    return u


def _energy_grad(u, L, sw, edges, vmask, uv0, area):
    return jax.grad(_energy)(u, L, sw, edges, vmask, uv0, area)


@_implicit.defjvp
def _implicit_jvp(solver, primals, tangents):
    u, L, sw, area, edges, vmask, uv0, pos, free, shape = primals
    _, dL, dsw, (_, da3, dsa), *_ = tangents
    faces = area[0]

    def grad_at(L, sw, a3, sa):
        return _energy_grad(u, L, sw, edges, vmask, uv0, (faces, a3, sa))

    _, rhs = jax.jvp(grad_at, (L, sw, *area[1:]), (dL, dsw, da3, dsa))

    def matvec(v):
        return jax.jvp(
            lambda u: _energy_grad(u, L, sw, edges, vmask, uv0, area), (u,), (v,)
        )[1]

    def solve(_, b):
        if solver == "banded":
            return _system_solve(
                u, L, sw, edges, vmask, uv0, area, pos, free, shape, True, b
            )
        return jax.pure_callback(
            strain.hessian_solve,
            jax.ShapeDtypeStruct(b.shape, b.dtype),
            u,
            L,
            sw,
            edges,
            vmask,
            uv0,
            area,
            b,
            vmap_method="sequential",
        )

    du = jax.lax.custom_linear_solve(
        matvec, rhs, solve, transpose_solve=solve, symmetric=True
    )
    return u, -du


def trace_seams(
    x: Float[Array, " P"], mesh: Mesh, template: Template, settings: Settings
):
    """The seams at `x` (`jax.vmap` of `shortest_path`, the method and
    capacity of `settings`) and per seam whether it keeps the template's
    sequence of mesh elements and was traced (`(N,)` bool)."""
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
    keep = (
        (paths.count == t.count)
        & jnp.all(jnp.where(m, paths.kinds == t.kinds, True), axis=1)
        & jnp.all(jnp.where(m, paths.elements == t.elements, True), axis=1)
        & (paths.status == Status.SUCCESS)
    )
    return paths, keep


def evaluate(
    x: Float[Array, " P"], mesh: Mesh, template: Template, settings: Settings
) -> tuple[Float[Array, ""], dict]:
    """`J(x)` (module docstring) and its parts: `rms`, `max` (stress deviation,
    kN/m), `waste`, `fit`, `widths` `(C,)`, `valid` (the template still holds
    and every solve succeeded)."""
    t, s = template, settings
    paths, keep = trace_seams(x, mesh, t, s)
    same = jnp.all(keep)
    src = jnp.concatenate([mesh.vertices, paths.points.reshape(-1, 3)])
    x3 = jnp.sum(src[t.src_idx] * t.src_w[..., None], axis=1)
    cw, cf = s.compensation
    shrink = jnp.array([1.0 / (1.0 + cw), 1.0 / (1.0 + cf)])

    def cloth(verts, vmask, edges, ew, faces, fmask, uv0, rot, pos, free):
        xc = x3[verts]
        band = (pos, free, t.blocks)
        u, ok = _flatten(xc, edges, ew, faces, fmask, vmask, uv0, s.solver, band)
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
        return d, area, width, length, ok, u

    d, area, width, length, ok, u_all = jax.vmap(cloth)(
        t.verts, t.vmask, t.edges, t.ew, t.faces, t.fmask, t.uv0, t.rot, t.pos, t.free
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
        # the cloths' design positions and flattenings (before the warp turn
        # and the compensation), to carry a flattening over to a new template
        "x3": x3[t.verts],
        "uv": u_all,
        "rms": rms,
        "max": dmax,
        "waste": waste,
        "fit": fit,
        "widths": width,
        "valid": valid,
    }
