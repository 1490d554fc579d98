"""Flatten the cloths of a cut mesh into a cutting pattern.

1. **Flatten** (`flatten_cloth`): least-squares conformal map (LSCM, Lévy et al.
   2002) by sparse least squares, then the edge-length strain
   Σ w_e ((|x_i − x_j| − L_e)/L_e)² minimised (seam edges weighted 10×, so the
   two flattened copies of a seam keep its 3-D length and sew together), with
   a one-sided area term that keeps every face above 0.9 of its 3-D area
   (`_least_strain.AREA_FLOOR`: no crushed or mirrored slivers): 30
   trust-region evaluations of `scipy.optimize.least_squares`, then converged
   to a minimum by `_least_strain.converge` (Newton steps, off saddles), the
   flattening the stress objective (`cutting.objective`) starts from.
2. **Measures** (`make_pattern`): per cloth edge-length strain (max, RMS), area
   change, flattened seam lengths, and the roll width the cloth needs: the
   smallest width of a strip between two parallel lines containing it (rotating
   calipers on the convex hull, `strip_width`).

All of this is numpy/scipy: it runs once per layout, after the optimisation.

(Moved here from `jaxgeo.pattern`, which still re-exports the public names.)
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.optimize
import scipy.sparse as sp
from jaxtyping import Bool, Float, Int
from scipy.spatial import ConvexHull

from .._errors import JaxgeoError
from ._least_strain import area_params, area_residuals, converge
from .cut import CutMesh, edge_table

__all__ = [
    "SEAM_WEIGHT",
    "Cloth",
    "Pattern",
    "flatten_cloth",
    "make_pattern",
    "strip_width",
]

#: Weight of seam edges, relative to interior edges, in the strain least squares.
SEAM_WEIGHT = 10.0


# ----------------------------------------------------------------------- flattening


def _lscm(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Least-squares conformal map of a disk-like mesh, two far vertices pinned."""
    n = len(V)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1 = b - a
    e2 = c - a
    x1 = np.linalg.norm(e1, axis=1)
    ex = e1 / x1[:, None]
    nrm = np.cross(e1, e2)
    area2 = np.linalg.norm(nrm, axis=1)
    ey = np.cross(nrm / area2[:, None], ex)
    # local 2-D coordinates: a=(0,0), b=(x1,0), c=(x2,y2)
    x2 = np.einsum("ij,ij->i", e2, ex)
    y2 = np.einsum("ij,ij->i", e2, ey)
    # gradient operator rows (per face): grad phi = G @ [phi_a, phi_b, phi_c]
    gx = np.stack([-y2, y2, np.zeros_like(x1)], 1) / area2[:, None]
    gy = np.stack([x2 - x1, -x2, x1], 1) / area2[:, None]
    w = np.sqrt(area2 / 2)[:, None]
    m = len(F)
    rows = np.repeat(np.arange(m), 3)
    cols = F.ravel()
    Gx = sp.csr_matrix(((gx * w).ravel(), (rows, cols)), shape=(m, n))
    Gy = sp.csr_matrix(((gy * w).ravel(), (rows, cols)), shape=(m, n))
    # conformal: grad v = J grad u, J = rot90: (vx, vy) = (-uy, ux)
    A = sp.vstack([sp.hstack([Gy, Gx]), sp.hstack([-Gx, Gy])]).tocsc()
    bnd = np.unique(_boundary_edges(F))
    if len(bnd) == 0:
        raise JaxgeoError(
            "a closed cloth (no boundary edge) cannot be flattened: cut it open "
            "with a seam first"
        )
    far = bnd[np.argmax(np.linalg.norm(V[bnd] - V[bnd[0]], axis=1))]
    p0 = bnd[np.argmax(np.linalg.norm(V[bnd] - V[far], axis=1))]
    pins = np.array([p0, far])
    d = np.linalg.norm(V[far] - V[p0])
    pin_uv = np.array([[0.0, 0.0], [d, 0.0]])
    free = np.setdiff1d(np.arange(n), pins)
    fixed_cols = np.concatenate([pins, pins + n])
    free_cols = np.concatenate([free, free + n])
    rhs = -A[:, fixed_cols] @ np.concatenate([pin_uv[:, 0], pin_uv[:, 1]])
    Af = A[:, free_cols]
    sol = sp.linalg.spsolve((Af.T @ Af).tocsc(), Af.T @ rhs)
    uv = np.zeros((n, 2))
    uv[pins] = pin_uv
    uv[free, 0] = sol[: len(free)]
    uv[free, 1] = sol[len(free) :]
    return uv


def _boundary_edges(F: np.ndarray) -> np.ndarray:
    uniq, inv = edge_table(F)
    counts = np.bincount(inv, minlength=len(uniq))
    return uniq[counts == 1]


def _signed_areas(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    a, b, c = uv[F[:, 0]], uv[F[:, 1]], uv[F[:, 2]]
    return 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])


def flatten_cloth(
    V: Float[np.ndarray, "V 3"],
    F: Int[np.ndarray, "F 3"],
    seam_mask: Bool[np.ndarray, " E"] | None = None,
) -> tuple[Float[np.ndarray, "V 2"], Int[np.ndarray, "E 2"]]:
    """Flatten a disk-like cloth `(V, F)`: LSCM, then least edge-length strain
    with the one-sided area term (no face below 0.9 of its 3-D area, as a
    penalty: module docstring).

    **Arguments:** `seam_mask` marks, per unique edge (`edge_table(F)` order),
    the seam edges, weighted `SEAM_WEIGHT` in the strain fit.

    **Returns:** `(uv, edges)`: the 2-D positions `(V, 2)` (orientation
    preserved: positive signed areas) and the unique edges used.
    """
    uv, edges, _ = _flatten(V, F, seam_mask)
    return uv, edges


def _flatten(V, F, seam_mask):
    """`flatten_cloth`, and whether the strain fit converged to a minimum."""
    uv = _lscm(V, F)
    if np.sum(_signed_areas(uv, F)) < 0:
        uv[:, 1] *= -1
    edges, _ = edge_table(F)
    L = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    l2 = np.linalg.norm(uv[edges[:, 0]] - uv[edges[:, 1]], axis=1)
    uv *= np.sum(L * l2) / np.sum(l2 * l2)  # best uniform scale
    ew = np.ones(len(edges))
    if seam_mask is not None:
        ew[seam_mask] = SEAM_WEIGHT
    w = np.sqrt(ew) / L
    i, j = edges[:, 0], edges[:, 1]
    n, ne = len(V), len(edges)
    a3, sa = area_params(V, F)
    # Jacobian pattern: an edge's row has its ends' four dofs, a face's its
    # corners' six
    rows = np.concatenate(
        [np.repeat(np.arange(ne), 4), ne + np.repeat(np.arange(len(F)), 6)]
    )
    cols = np.concatenate(
        [
            np.stack([2 * i, 2 * i + 1, 2 * j, 2 * j + 1], 1).ravel(),
            (2 * F[:, :, None] + np.arange(2)).ravel(),
        ]
    )

    def res(x):
        p = x.reshape(n, 2)
        r_f, _ = area_residuals(p, F, a3, sa)
        return np.concatenate([w * (np.linalg.norm(p[i] - p[j], axis=1) - L), r_f])

    def jac(x):
        p = x.reshape(n, 2)
        d = p[i] - p[j]
        u = d / np.linalg.norm(d, axis=1)[:, None] * w[:, None]
        v = np.stack([u[:, 0], u[:, 1], -u[:, 0], -u[:, 1]], 1).ravel()
        _, jf = area_residuals(p, F, a3, sa)
        vals = np.concatenate([v, jf.ravel()])
        return sp.csr_matrix((vals, (rows, cols)), shape=(ne + len(F), 2 * n))

    sol = scipy.optimize.least_squares(
        res,
        uv.ravel(),
        jac=jac,
        method="trf",
        x_scale="jac",
        xtol=1e-10,
        ftol=1e-10,
        gtol=1e-10,
        max_nfev=30,
        tr_solver="lsmr",
    )
    uv, converged = converge(V, edges, ew, F, sol.x.reshape(n, 2))
    return uv, edges, bool(converged)


def strip_width(points: Float[np.ndarray, "N 2"]) -> tuple[float, float]:
    """The smallest width of a strip between two parallel lines containing
    `points`, and the angle (radians) of the strip's direction."""
    hull = points[ConvexHull(points).vertices]
    d = np.roll(hull, -1, axis=0) - hull
    d /= np.linalg.norm(d, axis=1)[:, None]
    normal = np.stack([-d[:, 1], d[:, 0]], 1)
    proj = np.einsum("kj,ij->ki", normal, hull)
    widths = proj.max(axis=1) - proj.min(axis=1)
    k = int(np.argmin(widths))
    return float(widths[k]), float(np.arctan2(d[k, 1], d[k, 0]))


# ----------------------------------------------------------------------- pattern


@dataclasses.dataclass
class Cloth:
    """One flattened cloth.

    - `vertices3d`, `faces`, `uv`: the cloth's own mesh and its flattening, rotated
      so the strip of least width runs along x (the roll), width along y, min at 0.
    - `outline`: vertex ids of its boundary loop (closed polygon, counter-clockwise).
    - `seams`: seam id → list of its edges in this cloth (vertex pairs).
    - `width`: the roll width it needs; `strain_max`, `strain_rms`: edge-length
      strain |l₂ − l₃|/l₃; `area_change`: A₂/A₃ − 1.
    - `inverted`: how many of its flat triangles are inverted (negative signed
      area): the flat cloth folds over itself there and cannot be cut as
      flattened. An edge-length strain has the same value on a triangle and
      its mirror image; the flattening's area term (`_least_strain.AREA_FLOOR`)
      keeps faces the right way round, so this is 0 on every cloth measured
      so far (a cap of a sphere reaching 0.95 below its equator included);
      should it not be, more seams through the cloth are the remedy.
    - `seam_lengths`: seam id → (3-D length, flattened length).
    """

    vertices3d: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    outline: np.ndarray
    seams: dict[int, np.ndarray]
    width: float
    strain_max: float
    strain_rms: float
    area_change: float
    seam_lengths: dict[int, tuple[float, float]]
    #: the cloth's vertices as ids of `CutMesh.vertices`
    vertex_ids: np.ndarray | None = None
    #: whether its flattening converged to a minimum of the strain energy
    #: (else it is the trust-region fit's, `flatten_cloth`)
    converged: bool = True
    #: its flat triangles with negative signed area (folds)
    inverted: int = 0

    def summary(self) -> dict:
        return {
            "width": self.width,
            "strain_max": self.strain_max,
            "strain_rms": self.strain_rms,
            "area_change": self.area_change,
            "converged": self.converged,
            "inverted_triangles": self.inverted,
            "seams": sorted(self.seams),
            "seam_lengths": {int(k): list(v) for k, v in self.seam_lengths.items()},
        }


@dataclasses.dataclass
class Pattern:
    cut: CutMesh
    cloths: list[Cloth]

    def seam_copy_difference(self) -> dict[int, float]:
        """Per seam, the relative difference of its flattened lengths in the
        cloths on either side: |a − b| / mean (seams with two copies)."""
        copies: dict[int, list[float]] = {}
        for c in self.cloths:
            for s, (_, l2) in c.seam_lengths.items():
                copies.setdefault(s, []).append(l2)
        return {
            s: abs(v[0] - v[1]) / (0.5 * (v[0] + v[1]))
            for s, v in copies.items()
            if len(v) == 2
        }

    @property
    def widths(self) -> np.ndarray:
        return np.array([c.width for c in self.cloths])


def _outline(F: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The longest boundary loop of a cloth, counter-clockwise in uv."""
    half = np.stack([F, np.roll(F, -1, axis=1)], -1).reshape(-1, 2)
    key = {(a, b) for a, b in half.tolist()}
    bnd = [(a, b) for a, b in half.tolist() if (b, a) not in key]
    nxt = dict(bnd)
    loops, seen = [], set()
    for s in nxt:
        if s in seen:
            continue
        lp, v = [], s
        while v not in seen:
            seen.add(v)
            lp.append(v)
            v = nxt[v]
        loops.append(np.asarray(lp))

    def perim(lp):
        q = uv[lp]
        return np.linalg.norm(np.roll(q, -1, 0) - q, axis=1).sum()

    return max(loops, key=perim)


def make_pattern(cut: CutMesh) -> Pattern:
    """Flatten every cloth of `cut` and measure it."""
    cloths = []
    seam_key = {}
    for (a, b), s in zip(cut.seam_edges.tolist(), cut.seam_of_edge.tolist()):
        seam_key[(min(a, b), max(a, b))] = s
    for c in range(cut.n_cloths):
        Fg = cut.faces[cut.cloth_of_face == c]
        used, Fl = np.unique(Fg, return_inverse=True)
        Fl = Fl.reshape(-1, 3)
        V = cut.vertices[used]
        edges, _ = edge_table(Fl)
        bnd = {tuple(e) for e in _boundary_edges(Fl).tolist()}
        gl = used[edges]
        sid = np.array(
            [
                seam_key.get((min(a, b), max(a, b)), -1) if tuple(e) in bnd else -1
                for (a, b), e in zip(gl.tolist(), edges.tolist())
            ]
        )
        uv, _, converged = _flatten(V, Fl, sid >= 0)
        L = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
        l2 = np.linalg.norm(uv[edges[:, 0]] - uv[edges[:, 1]], axis=1)
        strain = np.abs(l2 - L) / L
        a3 = 0.5 * np.linalg.norm(
            np.cross(V[Fl[:, 1]] - V[Fl[:, 0]], V[Fl[:, 2]] - V[Fl[:, 0]]), axis=1
        )
        signed = _signed_areas(uv, Fl)
        area_change = signed.sum() / a3.sum() - 1
        width, angle = strip_width(uv)
        rot = np.array(
            [[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]]
        )
        uv = uv @ rot.T
        uv -= uv.min(axis=0)
        seams = {int(s): edges[sid == s] for s in np.unique(sid[sid >= 0])}
        lengths = {
            s: (float(L[sid == s].sum()), float(l2[sid == s].sum())) for s in seams
        }
        cloths.append(
            Cloth(
                V,
                Fl,
                uv,
                _outline(Fl, uv),
                seams,
                width,
                float(strain.max()),
                float(np.sqrt(np.mean(strain**2))),
                float(area_change),
                lengths,
                used,
                converged,
                int(np.sum(signed < 0)),
            )
        )
    return Pattern(cut, cloths)
