"""The differentiable stress objective (issue 15, item 4): its value agrees with
the numpy reassembly check, its gradient with central differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import seams, surfaces
from jaxgeo.cutting import (
    Compensation,
    Material,
    Prestress,
    compensate_pattern,
    reassemble,
)
from jaxgeo.cutting.objective import Settings, evaluate, make_template
from jaxgeo.pattern import make_pattern

# Heavy (compiles several solvers): in the slow set (`pytest -m slow`).
pytestmark = pytest.mark.slow

MATERIAL = Material(600.0, 400.0, 0.3, 30.0)
PRESTRESS = Prestress(2.0, 1.5)


@pytest.mark.slow  # one compile of trace + flattening + adjoint: ~60 s on 2 cores
def test_stress_objective_value_and_gradient():
    mesh = jg.Mesh(*surfaces.cone_tent(24, 6))
    layout = seams.radial_layout(mesh, 6, offset=0.1)
    cut, paths = seams.cut(mesh, layout, method="laser")  # Settings.method
    eps = np.asarray(PRESTRESS.strain(MATERIAL))[:2]
    cloths = compensate_pattern(make_pattern(cut), Compensation(*(100 * eps)))
    template, _ = make_template(mesh, layout, paths, cut, cloths)
    settings = Settings(MATERIAL, PRESTRESS, tuple(map(float, eps)), 1.0)
    f = eqx.filter_jit(
        lambda x: jax.value_and_grad(evaluate, has_aux=True)(
            x, mesh, template, settings
        )
    )
    x = jnp.asarray(layout.x)
    (j, aux), g = f(x)
    assert bool(aux["valid"])
    # the JAX flattening and make_pattern's converge to the same minimum, each
    # to GN_RTOL = 1e-10 of the cloth's size: divided by edges ~1/50 of it and
    # times E/RMS ~ 70 that is ~3.5e-7 of the RMS (measured 2.4e-7; before
    # make_pattern converged its flattening, up to 1e-4)
    numpy_rms = reassemble(cloths, MATERIAL, PRESTRESS).total_stats()["rms"]
    assert abs(float(aux["rms"]) - numpy_rms) <= 1e-6 * numpy_rms
    h = 1e-5  # of a unit arc-length parameter: truncation O(h²) ≪ 1e-4
    for k in (0, 3, 7):
        e = jnp.zeros_like(x).at[k].set(h)
        (jp, ap), _ = f(x + e)
        (jm, am), _ = f(x - e)
        assert bool(ap["valid"]) and bool(am["valid"])  # same cut topology
        fd = (jp - jm) / (2 * h)
        # the flattening's tolerance (1e-10 relative) divided by h bounds the
        # difference quotient's noise: 1e-3 relative is far above it
        assert abs(fd - g[k]) <= 1e-3 * abs(g[k])


def _cone_case():
    """The gradient test's case. The seams are turned off the mesh's radial
    lines (offset): a seam along mesh edges changes its edge sequence at any
    move of its ends, so no step would keep the template."""
    mesh = jg.Mesh(*surfaces.cone_tent(24, 6))
    layout = seams.radial_layout(mesh, 6, offset=0.1)
    eps = tuple(float(e) for e in np.asarray(PRESTRESS.strain(MATERIAL))[:2])
    return mesh, layout, eps


def _numpy_rms(mesh, layout, eps):
    from jaxgeo.trace import TraceOptions

    cut, _ = seams.cut(mesh, layout, TraceOptions("local", 160), "laser")
    cloths = compensate_pattern(make_pattern(cut), Compensation(*(100 * np.array(eps))))
    return reassemble(cloths, MATERIAL, PRESTRESS).total_stats()["rms"]


@pytest.mark.long  # by hand, `pytest -m long`: 60 s on 2 cores (over 10 min with QR)
@pytest.mark.slow  # compiles the BFGS loop round the objective: minutes on 2 cores
def test_stress_optimiser_lowers_the_objective_and_the_deviation():
    from jaxgeo.cutting import optimise_seams

    mesh, layout, eps = _cone_case()
    settings = Settings(MATERIAL, PRESTRESS, eps, 1.0)
    res = optimise_seams(mesh, layout, settings, steps=4, rounds=1)
    r = res.rounds[0]
    print(res.rounds)
    assert r["accepted"] >= 1  # BFGS took a step (Armijo: each one lowers J)
    assert res.j_end < res.j_start
    assert np.all(res.layout.x != layout.x)
    # independently of the template: the numpy check of a fresh cut at the new
    # layout carries less RMS deviation than the uniform seams' cut
    before, after = _numpy_rms(mesh, layout, eps), _numpy_rms(mesh, res.layout, eps)
    print(f"RMS deviation {before:.4g} -> {after:.4g} kN/m")
    assert after < before
    # no seam end left its box (its neighbours' half-gaps, at most max_move)
    from jaxgeo.cutting.optimise import move_radius

    moved = np.abs(np.mod(res.layout.x - layout.x + 0.5, 1.0) - 0.5)
    assert np.all(moved <= move_radius(layout, 0.02) * (1 + 1e-12))


def _small_cloth(amplitude=0.3):
    """A 5x5 grid bent into a saddle z = amplitude ((x - 1/2)^2 - (y - 1/2)^2):
    not developable, so the flattening has residuals of ~1e-2 (Newton and
    Gauss-Newton differ, the Hessian's second-order term matters), padded by 3
    vertices, 4 edges and 2 faces as templates are. At amplitude 2 two faces
    of its flattening are below the area term's floor (the term is active)."""
    from jaxgeo.pattern import edge_table

    n = 5
    s = np.linspace(0.0, 1.0, n)
    xx, yy = np.meshgrid(s, s)
    x3 = np.stack([xx.ravel(), yy.ravel(), amplitude * (xx - 0.5).ravel() ** 2], 1)
    x3[:, 2] -= amplitude * (yy - 0.5).ravel() ** 2
    q = np.arange(n * n).reshape(n, n)
    a, b, c, d = q[:-1, :-1], q[:-1, 1:], q[1:, :-1], q[1:, 1:]
    faces = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    edges = edge_table(faces)[0]
    ew = np.where(edges[:, 0] < n, 10.0, 1.0)  # one seam side weighted
    pad_v, pad_e, pad_f = 3, 4, 2
    x3 = np.concatenate([x3, np.zeros((pad_v, 3))])
    edges = np.concatenate([edges, np.zeros((pad_e, 2), np.int64)])
    ew = np.concatenate([ew, np.zeros(pad_e)])
    fmask = np.r_[np.ones(len(faces)), np.zeros(pad_f)]
    faces = np.concatenate([faces, np.zeros((pad_f, 3), np.int64)])
    vmask = np.r_[np.ones(n * n), np.zeros(pad_v)]
    uv0 = x3[:, :2] * vmask[:, None] + 0.01  # a start off the optimum
    return tuple(jnp.asarray(v) for v in (x3, edges, ew, faces, fmask, vmask, uv0))


def _band(edges, ew, vmask, uv0):
    """The banded solve's arrays of `_small_cloth` (as `make_template`)."""
    from jaxgeo.cutting.objective import _gauge_pins, _order

    n, ne = int(vmask.sum()), int((ew > 0).sum())
    pos = np.arange(len(vmask))
    pos[:n], band = _order(np.asarray(edges[:ne]), n)
    free = np.ones((len(vmask), 2))
    free[:n] = _gauge_pins(np.asarray(uv0[:n]))
    nb = 8 * int(np.ceil((2 * band + 2) / 8))
    shape = jnp.zeros((-(-2 * len(vmask) // nb), nb))
    assert shape.shape[0] >= 2  # more than one block: the scans run
    return jnp.asarray(pos), jnp.asarray(free), shape


def _assert_jvp_vjp(f, x3, dx, w, jvp):
    """`jvp` (of `f` at `x3` along `dx`) against central differences (step 1e-6:
    truncation ~1e-12 of the cloth's size 1, roundoff ~1e-10 / 1e-6; the bound
    1e-6 relative), and the VJP with `w` consistent with it to rounding."""
    h = 1e-6
    fd = (f(x3 + h * dx) - f(x3 - h * dx)) / (2 * h)
    assert float(jnp.max(jnp.abs(jvp - fd))) <= 1e-6 * float(jnp.max(jnp.abs(fd)))
    (vjp,) = jax.vjp(f, x3)[1](w)
    assert abs(float(jnp.sum(vjp * dx) - jnp.sum(w * jvp))) <= 1e-10 * float(
        jnp.sum(jnp.abs(w * jvp))
    )


def test_banded_flattening_matches_the_host_and_its_derivative():
    """The JAX flattening (solver "banded", the default) reaches the optimum
    of the host Newton flattening ("sparse") on a cloth where the area term
    is active; its implicit JVP and VJP agree with central differences, with
    the host's and with each other; and it holds no host callback (~30 s on
    the loaded 2-core machine, mostly compiling). (The host's agreement with
    optimistix's Gauss-Newton is the next test's.)"""
    from jaxgeo.cutting.objective import _area_params, _area_residuals, _flatten

    x3, edges, ew, faces, fmask, vmask, uv0 = _small_cloth(2.0)
    band = _band(edges, ew, vmask, uv0)

    def flat(x3, solver):
        return _flatten(x3, edges, ew, faces, fmask, vmask, uv0, solver, band)

    ub, okb = jax.jit(lambda x: flat(x, "banded"))(x3)
    us, oks = jax.jit(lambda x: flat(x, "sparse"))(x3)
    assert bool(okb) and bool(oks)
    # the area term acts at the optimum (on 2 faces, measured), and no face
    # is within 1e-3 of its floor, where the derivative has a kink
    r_f = _area_residuals(ub, faces, *_area_params(x3, faces, fmask))
    assert int(jnp.sum(r_f < 0)) >= 1
    # both Newton iterations stop a step below 1e-10 of the cloth's size (1)
    # from the optimum; quadratic convergence leaves ~1e-16 (measured 2e-16)
    assert float(jnp.max(jnp.abs(ub - us))) < 1e-12
    assert float(jnp.max(jnp.abs(ub[-3:]))) == 0.0  # padded vertices pinned

    rng = np.random.default_rng(0)
    dx = jnp.asarray(rng.normal(size=x3.shape)) * vmask[:, None]
    w = jnp.asarray(rng.normal(size=ub.shape))
    f = jax.jit(lambda x: flat(x, "banded")[0])
    fs = jax.jit(lambda x: flat(x, "sparse")[0])
    _, jvp = jax.jvp(f, (x3,), (dx,))
    _, jvp_host = jax.jvp(fs, (x3,), (dx,))
    # the same H^-1 b by two solvers: roundoff times H's condition (~1e3)
    assert float(jnp.max(jnp.abs(jvp - jvp_host))) <= 1e-10
    _assert_jvp_vjp(f, x3, dx, w, jvp)
    # JAX only: the reverse-mode program of a batch holds no host callback
    batch = jnp.stack([x3, x3 + 1e-3 * dx])
    prog = jax.make_jaxpr(jax.vmap(jax.grad(lambda x: jnp.sum(f(x) * w))))(batch)
    assert "callback" not in str(prog)


def test_sparse_flattening_matches_qr_and_its_derivative_the_differences():
    """The host Newton flattening (solver "sparse") reaches optimistix's
    Gauss-Newton optimum (solver "qr"), and its implicit JVP and VJP agree
    with central differences and with each other (~4 s)."""
    from jaxgeo.cutting.objective import _flatten

    x3, edges, ew, faces, fmask, vmask, uv0 = _small_cloth()

    def flat(x3, solver):  # no band: host, QR
        return _flatten(x3, edges, ew, faces, fmask, vmask, uv0, solver)

    us, oks = jax.jit(lambda x: flat(x, "sparse"))(x3)
    uq, okq = jax.jit(lambda x: flat(x, "qr"))(x3)
    assert bool(oks) and bool(okq)
    assert float(jnp.max(jnp.abs(us - uq))) < 1e-9
    assert float(jnp.max(jnp.abs(us[-3:]))) == 0.0  # padded vertices pinned

    rng = np.random.default_rng(0)
    dx = jnp.asarray(rng.normal(size=x3.shape)) * vmask[:, None]
    w = jnp.asarray(rng.normal(size=us.shape))
    f = jax.jit(lambda x: flat(x, "sparse")[0])
    _, jvp = jax.jvp(f, (x3,), (dx,))
    _assert_jvp_vjp(f, x3, dx, w, jvp)


def test_a_flattening_at_a_saddle_is_left_for_a_minimum_or_invalid():
    """A cloth of a twin-peak cut (`tests/data/saddle_cloth.npz`: 519 vertices,
    its design positions and the flattening Newton converged to) whose
    flattening is a saddle of the edge-strain energy: stationary, one Hessian
    eigenvalue of -14. It crashed the stress optimiser (the implicit derivative's
    banded Cholesky has no factor there: NaN, and lineax raised). At template
    time `_least_strain.converge` steps off the saddle to a minimum; in `evaluate` a
    flattening that converged to a saddle is not valid (J = +inf, rejected).
    The saddle is one of the edge energy alone (it crushes slivers to 0.004 of
    their area, which the area term would lift): the faces are not given (no
    area term); the saddle handling does not depend on the energy's terms."""
    from pathlib import Path

    from jaxgeo.cutting._least_strain import converge, system
    from jaxgeo.cutting.objective import _flatten

    d = np.load(Path(__file__).parent / "data" / "saddle_cloth.npz")
    xc, edges, ew, uv = d["xc"], d["edges"], d["ew"], d["uv"]
    L = np.linalg.norm(xc[edges[:, 0]] - xc[edges[:, 1]], axis=1)
    sw = np.sqrt(ew) / L
    ones = np.ones(len(uv))

    no_faces = np.zeros((0, 3), np.int64)
    no_area = (no_faces, np.zeros(0), np.zeros(0))

    def hessian_and_gradient(u):
        r, A, B, g = system(u, L, sw, edges, ones, uv, no_area, True)
        return A.toarray() + B.T @ B, g, 0.5 * float(r @ r)

    H, g, e_saddle = hessian_and_gradient(uv)
    # stationary (|grad| ~1e-9 against Hessian entries ~1e7) and not a minimum
    assert np.linalg.norm(g) < 1e-6 and np.linalg.eigvalsh(H)[0] < -1.0

    u, ok = converge(xc, edges, ew, no_faces, uv)
    H, g, e_min = hessian_and_gradient(u)
    assert ok and np.linalg.norm(g) < 1e-6
    assert np.linalg.eigvalsh(H)[0] > 0.0  # a minimum (gauge fixed by B)
    assert e_min < e_saddle

    # in JAX: the flattening from the saddle stays there and is not valid
    vmask = jnp.ones(len(uv))
    band = _band(jnp.asarray(edges), jnp.asarray(ew), vmask, jnp.asarray(uv))
    fmask = np.zeros(0)

    def flat(x, uv):
        return _flatten(x, edges, ew, no_faces, fmask, vmask, uv, "banded", band)

    _, ok_saddle = jax.jit(flat)(jnp.asarray(xc), uv)
    _, ok_min = jax.jit(flat)(jnp.asarray(xc), u)
    assert not bool(ok_saddle) and bool(ok_min)
