"""Failures that cannot be mistaken for lengths: `throw=True` raises under
`jax.jit` and `jax.vmap` too (`equinox.branched_error_if`, as optimistix), stays
transparent to `jax.grad`; with `throw=False` a failed length is NaN and its
gradient zero."""

import re

import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo.geodesic import _error_if_failed

from .helpers import face_points, position, unit_icosphere

MESH = unit_icosphere(2)
FAR = jnp.array([0.0, 0.0, 5.0])  # 4 radii off the unit sphere
FAR_MESSAGE = "no path from p1 to p2: an endpoint is too far from the surface"


def _points(n: int, seed: int) -> jnp.ndarray:
    """`n` points strictly inside faces (away from vertices and edges, where the
    gradient of a length would be one-sided)."""
    f, b = face_points(MESH, n, seed)
    return jnp.asarray(np.stack([position(MESH, fi, bi) for fi, bi in zip(f, b)]))


def _length(a, b, **kw):
    return jg.path_length(MESH, a, b, **kw)


def _small_path(status, length=1.0) -> jg.Path:
    """A two-point `Path` with the given status (no solve: cheap to compile)."""
    return jg.Path(
        points=jnp.zeros((2, 3)),
        kinds=jnp.zeros(2, int),
        elements=jnp.zeros(2, int),
        params=jnp.zeros(2),
        branch=jnp.zeros(2, bool),
        count=jnp.asarray(2),
        length=jnp.asarray(length),
        status=jnp.asarray(status, jnp.int32),
    )


def test_the_error_branch_raises_the_status_message_under_jit_and_vmap():
    """The check `shortest_path(..., throw=True)` adds to a traced path, on small
    paths (the solver's own compile is in the slow tests below)."""
    check = jax.jit(lambda s, x: _error_if_failed(_small_path(s, x)).length)
    assert float(check(0, 2.5)) == 2.5  # a complete path passes unchanged
    # and so does its derivative (error_if is the identity for AD)
    assert float(jax.jit(jax.grad(check, argnums=1))(0, 2.5)) == 1.0
    for status in jg.Status:
        if status != jg.Status.SUCCESS:
            message = re.escape(f"no path from p1 to p2: {status.message}")
            with pytest.raises(Exception, match=message):
                check(int(status), 1.0)
    rows = jax.jit(jax.vmap(check))
    ok = rows(jnp.array([0, 0]), jnp.array([1.0, 2.0]))
    np.testing.assert_array_equal(ok, [1.0, 2.0])
    # one failed row fails the batch, with the message of the highest code
    far, refine = jg.Status.FAR_FROM_SURFACE, jg.Status.REFINE_FAILED
    with pytest.raises(Exception, match=re.escape(refine.message)):
        rows(jnp.array([0, far, refine]), jnp.ones(3))


@pytest.mark.slow  # compiles the solver under jax.jit
def test_throw_raises_under_jit_with_the_status_message():
    q = _points(2, 0)
    f = jax.jit(_length)  # throw=True, the default
    with pytest.raises(Exception, match=FAR_MESSAGE):
        f(FAR, q[1])
    # a complete path passes unchanged: the eager value, to the rounding of a
    # differently fused program (1e-12 of the unit sphere's size)
    assert float(f(q[0], q[1])) == pytest.approx(float(_length(q[0], q[1])), rel=1e-12)


@pytest.mark.slow  # compiles the solver with its gradient
def test_eager_grad_of_a_failed_path_raises_jaxgeo_error():
    # under an eager jax.grad the status is concrete: the eager error, with its
    # JaxgeoError type, not the compiled program's
    with pytest.raises(jg.JaxgeoError, match=FAR_MESSAGE):
        jax.grad(_length)(FAR, _points(1, 0)[0])


def _callbacks(jaxpr, in_cond: bool = False):
    """(callback primitive, whether inside a `cond`) for every equation of a
    jaxpr and its sub-jaxprs."""
    for eqn in jaxpr.eqns:
        if "callback" in eqn.primitive.name:
            yield eqn.primitive.name, in_cond
        for sub in jax.extend.core.jaxprs_in_params(eqn.params):
            yield from _callbacks(sub, in_cond or eqn.primitive.name == "cond")


def test_the_only_host_callback_is_the_error_branch():
    """No host callback on the path of a solve: with `throw=False` none at all;
    with `throw=True` only equinox's, inside the `cond` branch that runs when a
    path failed. Tracing only, no compile."""
    q = _points(2, 0)
    quiet = jax.make_jaxpr(lambda a, b: _length(a, b, throw=False))(q[0], q[1])
    assert not list(_callbacks(quiet.jaxpr))
    loud = jax.make_jaxpr(_length)(q[0], q[1])
    found = list(_callbacks(loud.jaxpr))
    assert found and all(in_cond for _, in_cond in found), found


@pytest.mark.slow  # compiles the batched solver with its gradient
def test_throw_under_vmap_of_jit_and_grad():
    p, q = _points(2, 1), _points(2, 2)
    f = jax.vmap(jax.jit(jax.value_and_grad(_length)))
    value, grad = f(p, q)
    with pytest.raises(Exception, match=FAR_MESSAGE):
        f(p.at[1].set(FAR), q)  # one row of two fails: the batch raises
    # error_if is transparent to differentiation: the values and gradients are
    # the eager ones (rounding of a differently fused program: 1e-12 relative)
    for k in range(2):
        v, g = jax.value_and_grad(_length)(p[k], q[k])
        assert float(value[k]) == pytest.approx(float(v), rel=1e-12)
        np.testing.assert_allclose(grad[k], g, rtol=1e-10, atol=1e-12)


@pytest.mark.slow  # compiles the solver with its gradient
def test_failed_length_is_nan_with_zero_gradient_under_jit():
    p, q = _points(2, 3), _points(2, 4)
    a = p.at[1].set(FAR)

    def lengths(a):
        return jax.vmap(lambda x, y: _length(x, y, throw=False))(a, q)

    value = jax.jit(lengths)(a)
    assert np.isfinite(value[0]) and np.isnan(value[1])  # never 0.0
    # a sum of lengths with a failure in it is NaN: no optimiser minimises it
    total, _ = jax.jit(jax.value_and_grad(lambda a: jnp.sum(lengths(a))))(a)
    assert np.isnan(total)
    # the failed row's gradient is zero, so masking failures with
    # jnp.where(ok, length, 0) gives the finite gradient of the others
    masked = jax.jit(
        jax.value_and_grad(
            lambda a: jnp.sum(jnp.where(jnp.isnan(lengths(a)), 0.0, lengths(a)))
        )
    )
    total, grad = masked(a)
    assert float(total) == pytest.approx(float(value[0]), rel=1e-12)
    assert np.all(grad[1] == 0) and np.all(np.isfinite(grad))
    assert np.linalg.norm(grad[0]) > 0.5  # |d length / d p1| = 1 tangentially


@pytest.mark.slow  # compiles the solver for integer endpoints
def test_traced_vertex_indices():
    def solve(i, j):
        path = jg.shortest_path(MESH, i, j, throw=False)
        return path.length, path.status

    f = jax.jit(solve)
    length, status = f(0, 100)
    assert status == jg.Status.SUCCESS
    assert float(length) == pytest.approx(float(_length(0, 100)), rel=1e-12)
    for bad in (-1, MESH.n_vertices):
        length, status = f(0, bad)
        assert status == jg.Status.INVALID_ENDPOINT and np.isnan(length)
    with pytest.raises(Exception, match="an endpoint is not a point of the mesh"):
        jax.jit(_length)(0, MESH.n_vertices)
