"""The parallel string pull (`jaxgeo._sleeve.pull`) against the sequential funnel
(`jaxgeo._sleeve.funnel`) on the engine's starting corridors: the same pinned points,
so the same shortest path in every sleeve.

Tolerance: none needed for the pins (integers). The pull decides a portal end is
missed when the segment's line misses it by more than 64 eps times the sleeve's
extent, the funnel by the sign of a cross product; they could differ only for an
end within that distance of the line, which random pairs on this mesh do not
produce (asserted: all equal).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import _sleeve, exact
from jaxgeo._numerics import corner_angles
from jaxgeo.locate import SurfacePoint

from .helpers import unit_icosphere

CAP = 64


def _starts(mesh: jg.Mesh, pairs: np.ndarray):
    """The cleaned starting corridors (one landmark start each) of vertex pairs,
    and their ends."""

    def one(a, b):
        s = exact._end(mesh, SurfacePoint.vertex(mesh, a))
        t = exact._end(mesh, SurfacePoint.vertex(mesh, b))
        vs = mesh.faces[s.face, jnp.argmax(s.bary)]
        vt = mesh.faces[t.face, jnp.argmax(t.bary)]
        slots, ok = exact.best_slots(mesh, vs, vt, 1)
        angles = corner_angles(mesh.vertices, mesh.faces)
        corridor, n, _ = exact._start(mesh, angles, slots[0], ok[0], vs, vt, s, t, CAP)
        return corridor, n, s, t

    corridor, n, s, t = jax.vmap(one)(pairs[:, 0], pairs[:, 1])
    corridor, n = exact._clean(mesh, corridor, n, s, t)
    return corridor, n, s, t


def _sleeves(mesh: jg.Mesh, pairs: np.ndarray) -> _sleeve.Sleeve:
    """Unfolded starting corridors (one landmark start each) of vertex pairs."""
    corridor, n, s, t = _starts(mesh, pairs)
    return jax.vmap(lambda c, m, s_, t_: exact._sleeve_of(mesh, c, m, s_, t_))(
        corridor, n, s, t
    )


@pytest.mark.slow  # > 5 s on 2 cores (README tests <= 5 min)
def test_pull_pins_what_the_funnel_pins():
    mesh = unit_icosphere(2)
    rng = np.random.default_rng(0)
    pairs = rng.integers(0, mesh.n_vertices, (48, 2))
    sl = jax.jit(_sleeves, static_argnums=())(mesh, jnp.asarray(pairs))
    valid = np.asarray(sl.valid)
    assert valid.all()  # every start is a corridor of faces that share edges
    usable = valid & (np.asarray(sl.n) >= 2)  # pairs on one face have no portal
    assert usable.mean() >= 0.8
    pins, m, ok = jax.jit(_sleeve.pull)(sl)
    ref, ref_m, ref_ok = jax.jit(_sleeve.funnel)(sl)
    assert np.all(np.asarray(ok)[usable]) and np.all(np.asarray(ref_ok)[usable])
    m, ref_m = np.asarray(m), np.asarray(ref_m)
    assert np.array_equal(m[usable], ref_m[usable])
    for i in np.flatnonzero(usable):
        assert np.array_equal(np.asarray(pins)[i, : m[i]], np.asarray(ref)[i, : m[i]])
    # coverage, not correctness: many of these strings bend (20 of 43 here, up
    # to 2 pins), so the test is not about straight segments only
    assert np.sum(m[usable] > 2) >= 15 and m.max() >= 4
