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
    cut, paths = seams.cut(mesh, layout)
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
    # the JAX flattening re-solves the scipy one: equal within its tolerance
    numpy_rms = reassemble(cloths, MATERIAL, PRESTRESS).total_stats()["rms"]
    assert abs(float(aux["rms"]) - numpy_rms) <= 1e-4 * numpy_rms
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
