"""Least edge-length strain flattening of one cloth on the host (numpy, scipy).

The strain energy E = 1/2 |r|^2 with r_e = s_e (|u_i - u_j| - L_e) over the
cloth's edges (s_e = sqrt(w_e) / L_e, seam edges weighted more), the one-sided
area residuals r_f (`area_residuals`: zero unless a face's flat area falls
below `AREA_FLOOR` of its 3-D area), three linear gauge rows that fix the rigid
motions and r_p = u on padded vertices. Here: the system at a flattening
(`system`), its bordered sparse solve (`solve`), Gauss-Newton then Newton steps
to the optimum (`newton`), a converged flattening off saddles (`converge`,
`off_saddles`) and the strain energy (`strain_energy`).
`cutting.flatten.make_pattern` converges every cloth by `converge`;
`cutting.objective` starts its template there, and its "sparse" solver calls
`newton` and `hessian_solve` from `jax.pure_callback`; its default "banded"
solver is the same iteration in JAX (`objective._jax_newton`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

__all__ = [
    "AREA_FLOOR",
    "AREA_HESSIAN",
    "AREA_WEIGHT",
    "GN_ATOL",
    "GN_RTOL",
    "HOST_STEPS",
    "NEWTON_NEAR",
    "STALL_TOL",
    "area_params",
    "area_residuals",
    "converge",
    "hessian_solve",
    "newton",
    "off_saddles",
    "solve",
    "strain_energy",
    "system",
]

#: tolerances of the flattening's convergence (optimistix's Cauchy test, max
#: norm, as its Gauss-Newton "qr" solver; `newton` reads them per step)
GN_RTOL, GN_ATOL = 1e-10, 1e-12
#: steps of one `newton` call (cheap: one or two sparse LUs each)
HOST_STEPS = 100
#: its Newton steps start when a Gauss-Newton step is this small (relative)
NEWTON_NEAR = 1e-5
#: a step this small (relative) that lowers E nowhere ends the Newton loop as
#: converged; so does a Newton step this small that changes E by at most
#: GN_RTOL E: the point after it is within O(step^2) of the optimum, and the
#: Newton step's roundoff on an ill-conditioned cloth (1.9e-10 of the size on
#: a 111-vertex twin-peak cloth under `jax.vmap`) can stay above GN_RTOL for
#: ever (it looped 100 steps there, and the template was invalid)
STALL_TOL = 1e-8

#: The one-sided area term: r_f = a_f min(0, A2_f / A3_f - AREA_FLOOR), A2_f the
#: flat signed area of face f, A3_f its 3-D area, a_f = sqrt(AREA_WEIGHT A3_f /
#: mean A3) (`area_params`). It is zero on a face that keeps AREA_FLOOR of its
#: area, so it leaves a healthy flattening as it is (the four-point sail's
#: smallest A2/A3 is 0.977), and it keeps a sliver from being crushed to a
#: line or mirrored, which the edge lengths alone allow: an edge-length energy
#: barely sees a sliver's apex move and cannot tell a triangle from its mirror
#: image. Measured on the twin-peak tent's bridged layouts (three sets of seam
#: angles 1 degree apart): without it 45-48 inverted triangles and a uniform
#: RMS stress deviation of 343.5 / 47.6 / 147.1 kN/m carried by a few slivers;
#: with it 0 inverted and 7.9 / 7.2 / 7.6. A floor of 0.5 was too weak (slivers
#: held at half their area, RMS 15-19); the weight makes a face's residual
#: comparable to its edges' (edge residuals are relative strains).
AREA_FLOOR, AREA_WEIGHT = 0.9, 10.0
#: the Hessian of a triangle's signed area (bilinear in its corners), in the
#: dofs (x0, y0, x1, y1, x2, y2): d2 A / dx_k dy_(k+1) = 1/2, dx_k dy_(k-1) = -1/2
AREA_HESSIAN = 0.5 * np.array(
    [
        [0, 0, 0, 1, 0, -1],
        [0, 0, -1, 0, 1, 0],
        [0, -1, 0, 0, 0, 1],
        [1, 0, 0, 0, -1, 0],
        [0, 1, 0, -1, 0, 0],
        [-1, 0, 1, 0, 0, 0],
    ],
    dtype=np.float64,
)


def area_params(xc, faces):
    """Per face its 3-D area `A3` and the area residual's scale `sa = a_f / A3`
    (`AREA_FLOOR`'s comment), for the cloth's 3-D vertices `xc`."""
    p = xc[np.asarray(faces, np.int64).reshape(-1, 3)]
    a3 = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    if len(a3) == 0:  # no faces given: no area term
        return a3, a3
    return a3, np.sqrt(AREA_WEIGHT * a3 / np.mean(a3)) / a3


def area_residuals(u, faces, a3, sa):
    """The one-sided area residuals `r_f = sa (A2 - AREA_FLOOR A3)` where that
    is negative, else 0, and their gradients `(F, 3, 2)` in the corners."""
    p = u[faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    a2 = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    on = a2 < AREA_FLOOR * a3
    r = np.where(on, sa * (a2 - AREA_FLOOR * a3), 0.0)
    nxt, prv = p[:, [1, 2, 0]], p[:, [2, 0, 1]]
    grad = 0.5 * np.stack([nxt[..., 1] - prv[..., 1], prv[..., 0] - nxt[..., 0]], -1)
    return r, np.where(on, sa, 0.0)[:, None, None] * grad


# The flattening's least squares: r_e = s_e (|u_i - u_j| - L_e) over the edges,
# r_p = u on padded vertices, and three linear gauge rows B u - b. Its normal
# matrix J^T J (and its Hessian) couple only the two ends of an edge: sparse,
# ~8 nonzeros per row, but for B^T B (rank 3, dense). A step solves the bordered
# system [[A, B^T], [B, -I]] [du; y] = [g; 0] (A the sparse part; y = B du), so
# B^T B is never formed; `splu` factors it in O(ms) for a 1000-vertex cloth, where
# a dense QR of the Jacobian takes ~1e10 flops.


def system(u, L, sw, edges, vmask, uv0, area, full):
    """Residuals `r` (as `_residuals`, flattened), the matrix `A` of the sparse
    part (Gauss-Newton's J^T J, or with `full` the Hessian of 1/2 |r|^2) and the
    dense rows `B`, `J^T r`, for one cloth (numpy). `area`: `(faces, A3, sa)`
    of the area term (`area_params`; `sa` 0 on padded faces)."""
    u = np.asarray(u, np.float64)
    n = len(u)
    live = np.flatnonzero(np.asarray(sw) != 0)
    i, j = edges[live, 0], edges[live, 1]
    s, Le = np.asarray(sw)[live], np.asarray(L)[live]
    d = u[i] - u[j]
    dn = np.sqrt(np.sum(d * d, 1) + 1e-30)
    nrm = d / dn[:, None]
    r_e = s * (dn - Le)
    # per edge the 2x2 Hessian block of 1/2 r_e^2 in d (Gauss-Newton: s^2 n n^T)
    blk = (s * s)[:, None, None] * nrm[:, :, None] * nrm[:, None, :]
    if full:
        t = (s * s * (dn - Le) / dn)[:, None, None]
        blk = blk + t * (np.eye(2) - nrm[:, :, None] * nrm[:, None, :])
    ci, cj = 2 * i[:, None] + np.arange(2), 2 * j[:, None] + np.arange(2)
    rows, cols, vals = [], [], []
    for a, sa in ((ci, 1.0), (cj, -1.0)):
        for b, sb in ((ci, 1.0), (cj, -1.0)):
            rows.append(np.repeat(a, 2, 1).ravel())
            cols.append(np.tile(b, (1, 2)).ravel())
            vals.append((sa * sb * blk).ravel())
    # the area term: per face the 6x6 block J_f^T J_f (+ r_f d2 r_f with full)
    faces, a3, sa = (np.asarray(a) for a in area)
    r_f, jf = area_residuals(u, faces, a3, sa)
    jf = jf.reshape(-1, 6)
    fblk = jf[:, :, None] * jf[:, None, :]
    if full:  # (r_f is zero where the term is off)
        fblk = fblk + (r_f * sa)[:, None, None] * AREA_HESSIAN
    fd = (2 * faces[:, :, None] + np.arange(2)).reshape(-1, 6)
    rows.append(np.repeat(fd, 6, 1).ravel())
    cols.append(np.tile(fd, (1, 6)).ravel())
    vals.append(fblk.ravel())
    pad = np.flatnonzero(np.repeat(np.asarray(vmask) == 0, 2))
    rows.append(pad)
    cols.append(pad)
    vals.append(np.ones(len(pad)))
    A = sp.csc_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(2 * n, 2 * n),
    )
    # gauge rows: centroid (x, y) and mean rotation, as _residuals
    vm = np.asarray(vmask, np.float64)
    nv = vm.sum()
    c0 = (uv0 * vm[:, None]).sum(0) / nv
    r0 = (uv0 - c0) * vm[:, None]
    scale = np.sqrt(np.sum(r0 * r0))
    B = np.zeros((3, n, 2))
    B[0, :, 0] = B[1, :, 1] = vm / (nv * scale)
    B[2, :, 0], B[2, :, 1] = -r0[:, 1] / scale**2, r0[:, 0] / scale**2
    B = B.reshape(3, 2 * n)
    r_g = B @ u.ravel() - np.append(c0 / scale, 0.0)
    pins = (1.0 - vm)[:, None] * u
    g = np.zeros((n, 2))  # J^T r
    w = (s * r_e)[:, None] * nrm
    np.add.at(g, i, w)
    np.add.at(g, j, -w)
    np.add.at(g, faces, r_f[:, None, None] * jf.reshape(-1, 3, 2))
    g = g.ravel() + pins.ravel() + B.T @ r_g
    r = np.concatenate([r_e, r_f, pins.ravel(), r_g])
    return r, A, B, g


def solve(A, B, b):
    """Solve (A + B^T B) x = b by the bordered sparse system."""
    K = sp.bmat([[A, sp.csc_matrix(B.T)], [sp.csc_matrix(B), -sp.identity(3)]])
    return splu(K.tocsc()).solve(np.append(b, np.zeros(3)))[: A.shape[0]]


def _energy(r):
    return 0.5 * float(r @ r)


def newton(L, sw, edges, vmask, uv0, area, near=NEWTON_NEAR, steps=HOST_STEPS):
    """The flattening from the template's flat cloth `uv0` on the host:
    Gauss-Newton steps (one sparse LU each), with a backtracking (Armijo) line
    search; once a Gauss-Newton step is below `near` times the cloth's size,
    Newton steps (the Hessian of 1/2 |r|^2) where they descend. At most
    `steps` steps, converged when a full step is below the tolerance.

    Gauss-Newton first, as optimistix's (solver "qr"): it finds the same
    optimum. Newton from the start reached another local optimum on a
    four-point sail cloth at a line-search trial of the optimiser (J 4.23
    against 0.386) and so rejected the step that QR took. Newton near the end:
    Gauss-Newton converges only linearly where the residuals are not small (on
    the twin-peak tent 4 of 16 cloths took over 30 steps, and its two
    520-vertex cloths stalled at steps of 1.6e-3 without the line search).
    Returns (u, converged)."""
    edges, uv0 = np.asarray(edges), np.asarray(uv0, np.float64)
    u = uv0.copy()
    for _ in range(steps):
        r, A, B, g = system(u, L, sw, edges, vmask, uv0, area, False)
        e0 = _energy(r)
        if not np.isfinite(e0):
            break
        try:
            du = -solve(A, B, g)
        except RuntimeError:  # singular
            break
        is_newton = False
        if np.max(np.abs(du)) < near * (1.0 + np.max(np.abs(u))):
            _, A, B, _ = system(u, L, sw, edges, vmask, uv0, area, True)
            try:
                dn = -solve(A, B, g)
            except RuntimeError:  # singular Hessian
                dn = du
            if g @ dn < 0:  # a descent direction: Newton's step
                du, is_newton = dn, True
        du = du.reshape(u.shape)
        # converged: the full (Newton) step, the distance to the optimum, is
        # below GN_ATOL + GN_RTOL max|u| (the cloth's size), and E changes by
        # at most GN_RTOL E. (Not optimistix's test, per coordinate and on
        # every residual: the Newton step's roundoff, ~5e-12 on a twin-peak
        # cloth, exceeds 1e-12 + 1e-10 |u_i| near the origin, and with edge
        # weights 1/L ~ 100 it moves residuals of ~1e-3 by more than
        # 1e-12 + 1e-10 |r|: 3 of its 16 cloths never passed it.) A Newton
        # step passes below STALL_TOL (its definition).
        new = u + du
        r_new = system(new, L, sw, edges, vmask, uv0, area, False)[0]
        size = np.max(np.abs(new))
        tol = STALL_TOL * (1.0 + size) if is_newton else GN_ATOL + GN_RTOL * size
        if np.max(np.abs(du)) < tol and abs(_energy(r_new) - e0) <= GN_RTOL * e0:
            return new, np.bool_(True)
        slope, t = float(g @ du.ravel()), 1.0
        while _energy(r_new) > e0 + 1e-4 * t * slope:
            t *= 0.5
            if t < 1e-8:
                # no lower E along the step: at the optimum to roundoff if the
                # step is (an ill-conditioned Hessian's noise, ~1e-11 on one
                # twin-peak cloth), else stuck
                small = np.max(np.abs(du)) <= STALL_TOL * (1.0 + np.max(np.abs(u)))
                return u, np.bool_(small)
            new = u + t * du
            r_new = system(new, L, sw, edges, vmask, uv0, area, False)[0]
        u = new
    return u, np.bool_(False)


def hessian_solve(u, L, sw, edges, vmask, uv0, area, b):
    """The Hessian of 1/2 |r|^2 at `u` applied inversely to `b` (the adjoint)."""
    edges, uv0 = np.asarray(edges), np.asarray(uv0, np.float64)
    _, A, B, _ = system(u, L, sw, edges, vmask, uv0, area, True)
    return solve(A, B, np.asarray(b, np.float64).ravel()).reshape(b.shape)


def _lengths(x, edges):
    """Edge lengths of positions `x` (2-D or 3-D), safe at zero as `system`'s."""
    return np.sqrt(np.sum((x[edges[:, 0]] - x[edges[:, 1]]) ** 2, 1) + 1e-30)


def strain_energy(xc, edges, ew, faces, uv):
    """1/2 sum of the squared edge-length and area residuals of a flattening
    (`system`'s residuals but the gauge and pins)."""
    L, d = _lengths(xc, edges), _lengths(uv, edges)
    r_f, _ = area_residuals(uv, faces, *area_params(xc, faces))
    return 0.5 * float(np.sum(ew / L**2 * (d - L) ** 2) + r_f @ r_f)


def converge(xc, edges, ew, faces, uv):
    """The least-strain flattening of the cloth with 3-D vertices `xc`, edges
    `edges` weighted `ew`, converged from `uv`: by Newton steps from the start
    (Gauss-Newton did not converge in 100 steps on the twin-peak tent's large
    cloths; on one of them after an optimiser round Newton needed over 100),
    else by Gauss-Newton first, then moved off saddles (`off_saddles`); else
    `uv`. 500 steps at most (~10 ms each on a 500-vertex cloth). `faces`:
    the cloth's faces, for the area term.

    Why converged: `make_pattern` flattens by 30 trust-region evaluations
    first; on the twin-peak tent's two large cloths that is not converged and
    Newton from there reached other local optima at layouts 1e-6 apart (J
    jumped between 131, 157 and 323, central differences off by 30x), and the
    stress check moved with 1-ulp changes of the cut. Returns (uv, converged)."""
    L = _lengths(xc, edges)
    sw = np.sqrt(ew) / L
    area = (faces, *area_params(xc, faces))
    for near in (np.inf, NEWTON_NEAR):  # Newton, else Gauss-Newton first
        u, ok = newton(L, sw, edges, np.ones(len(uv)), uv, area, near, 5 * HOST_STEPS)
        if ok:
            return off_saddles(u, L, sw, edges, uv, area)
    return uv, False


#: `off_saddles`: escapes tried, the step along the direction of negative
#: curvature (a fraction of the cloth's size), and the largest cloth checked
#: (degrees of freedom: its Hessian is checked dense, 128 MB at this size; a
#: larger one's saddle is found by `evaluate`, whose flattening is then invalid)
SADDLE_ESCAPES, SADDLE_STEP, SADDLE_MAX_DOFS = 4, 1e-3, 4000


def off_saddles(u, L, sw, edges, uv0, area):
    """`u`, a converged flattening, if it is a minimum; else the minimum that
    Gauss-Newton reaches after a step off the saddle along the Hessian's most
    negative curvature (at most `SADDLE_ESCAPES` times). Newton converges to any
    stationary point: on a twin-peak cut it reached a saddle of a 519-vertex
    cloth (Hessian eigenvalue −14), where the implicit derivative's banded
    Cholesky has no factor and `evaluate` could not be differentiated.
    Returns (u, converged): False where the escapes ended on no minimum. A cloth
    above `SADDLE_MAX_DOFS` is not checked here (`evaluate` finds its saddle)."""
    ones = np.ones(len(u))
    if 2 * len(u) > SADDLE_MAX_DOFS:
        return u, True
    for _ in range(SADDLE_ESCAPES + 1):
        _, A, B, _ = system(u, L, sw, edges, ones, uv0, area, True)
        H = A.toarray() + B.T @ B
        try:
            np.linalg.cholesky(H)
            return u, True
        except np.linalg.LinAlgError:
            pass
        _, vec = np.linalg.eigh(H)
        step = SADDLE_STEP * (1.0 + np.max(np.abs(u)))
        down = u + step * vec[:, 0].reshape(u.shape) / np.max(np.abs(vec[:, 0]))
        u, ok = newton(L, sw, edges, ones, down, area, NEWTON_NEAR, 5 * HOST_STEPS)
        if not ok:
            return u, False
    return u, False
