"""The seam-width optimiser's hand-written BFGS against `optimistix.BFGS` driven
step by step from Python (issue 16: "use optimistix's minimisers where they fit").

The layout is the twin-peak one of `tests/test_seams.py` (roll 0.75, 20 steps,
`max_move` 0.01). optimistix's `step` linearises the objective, so the host-side
evaluator (`seam_width._Evaluator`: re-trace, reject crossings and failed traces
as `inf`, replay for the gradient) sits behind `jax.custom_jvp` +
`jax.pure_callback`; the start is scaled as the loop's (`H0 = max_move/|g|_max`,
by the change of variable `z = c x`) and the Armijo slope is the loop's 1e-4.

    PYTHONPATH=. python benchmarks/seam_width_bfgs.py [jit|eager]

(The private `_Evaluator` is used on purpose: this compares the minimisers
around the same evaluations.)
"""

import math
import sys
import time

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

import jaxgeo as jg  # noqa: E402
from jaxgeo import surfaces  # noqa: E402
from jaxgeo.cutting import seam_width  # noqa: E402
from jaxgeo.cutting.cut import cut  # noqa: E402
from jaxgeo.cutting.layout import peaks_layout  # noqa: E402

STEPS, MAX_MOVE, ROLL = 20, 0.01, 0.75


def main(mode: str = "jit") -> None:
    mesh = jg.Mesh(*surfaces.twin_peak_tent(n_side=8, n_radial=10))
    layout = peaks_layout(mesh, 7, 3, 0.4, sector=172)
    cs = cut(mesh, layout)[0].cloth_seams()
    ev = seam_width._Evaluator(
        mesh, layout, cs, ROLL, seam_width.Weights(), np.ones(len(cs))
    )
    x0 = layout.x.copy()
    t = time.perf_counter()
    f0, g0, _ = ev(x0)
    print(f"first evaluation (compiles) {time.perf_counter() - t:.1f} s, J0 {f0:.6g}")
    t = time.perf_counter()
    ev(x0)
    print(f"one evaluation {time.perf_counter() - t:.2f} s")

    t = time.perf_counter()
    res = seam_width.optimise(mesh, layout, ROLL, cs, steps=STEPS, max_move=MAX_MOVE)
    print(
        f"hand-written BFGS: {len(res.history) - 1} steps, "
        f"J {res.j_start:.6g} -> {res.j_end:.6g}, {time.perf_counter() - t:.1f} s"
    )

    assert g0 is not None
    c = math.sqrt(max(np.abs(g0).max(), 1e-12) / MAX_MOVE)
    n_evals = [0]

    def host(z):
        n_evals[0] += 1
        f, g, _ = ev(np.asarray(z) / c)
        if not math.isfinite(f):
            return np.float64(np.inf), np.zeros_like(x0)
        return np.float64(f), np.asarray(g / c, np.float64)

    shape = (
        jax.ShapeDtypeStruct((), jnp.float64),
        jax.ShapeDtypeStruct(x0.shape, jnp.float64),
    )

    @jax.custom_jvp
    def objective(z):
        return jax.pure_callback(host, shape, z)[0]

    @objective.defjvp
    def objective_jvp(primals, tangents):
        f, g = jax.pure_callback(host, shape, primals[0])
        return f, g @ tangents[0]

    solver = optx.BFGS(rtol=1e-12, atol=1e-12)
    solver = eqx.tree_at(
        lambda s: s.search, solver, optx.BacktrackingArmijo(0.5, slope=1e-4)
    )

    def run():
        def fn(y, args):  # a new closure per call, as an optimise() would make
            return objective(y), None

        n_evals[0] = 0
        z = jnp.asarray(x0 * c)
        t = time.perf_counter()
        state = solver.init(
            fn, z, None, {}, jax.ShapeDtypeStruct((), jnp.float64), None, frozenset()
        )
        step = eqx.filter_jit(solver.step) if mode == "jit" else solver.step
        t_first = None
        for _ in range(STEPS * 11 + 1):
            z, state, _ = step(fn, z, None, {}, state, frozenset())
            t_first = t_first or time.perf_counter() - t
            if int(state.num_accepted_steps) > STEPS:
                break
            if bool(solver.terminate(fn, z, None, {}, state, frozenset())[0]):
                break
        print(
            f"optimistix BFGS ({mode} step): {int(state.num_accepted_steps) - 1} "
            f"steps, {n_evals[0]} evaluations, J -> {float(state.f_info.f):.6g}, "
            f"{time.perf_counter() - t:.1f} s (first step {t_first:.1f} s)"
        )

    run()
    run()


if __name__ == "__main__":
    main(*sys.argv[1:])
