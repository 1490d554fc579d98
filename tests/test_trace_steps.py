"""The laser trace's step functions (`jaxgeo.trace`), each on its own, on a flat
4 × 4 grid: vertex (a, b) is index 5a + b at (a, b, 0)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import surfaces, trace
from jaxgeo.locate import SurfacePoint
from jaxgeo.normals import vertex_normals
from jaxgeo.path import EDGE, FACE, VERTEX, Status

I32 = functools.partial(jnp.asarray, dtype=jnp.int32)


@functools.cache
def grid():
    a, b = np.meshgrid(np.arange(5.0), np.arange(5.0), indexing="ij")
    v = np.stack([a.ravel(), b.ravel(), np.zeros(25)], axis=1)
    return jg.Mesh(v, surfaces.grid_faces(4, 4))


@functools.cache
def context(candidates="local"):
    mesh = grid()
    normals = vertex_normals(mesh.vertices, mesh.faces)
    options = trace.TraceOptions(candidates=candidates, max_points=16)
    return trace._context(mesh, trace._frame(mesh), normals, options)


def in_frame(p):
    centre, scale, _ = context().frame
    return (jnp.asarray(p, float) - centre) / scale


def face_with(mesh, corners):
    """The face holding all of `corners`."""
    faces = np.asarray(mesh.faces)
    return int(np.flatnonzero(np.isin(faces, corners).sum(1) == len(corners))[0])


def test_mesh_angle_sums_the_fan_from_either_boundary_edge():
    """At vertex 10 = (2, 0), mid-way along a straight rim: π round to the other
    rim neighbour, from either side; towards a point q inside the fan the two
    sides' angles add up to π and each is the angle between the rim and q; 0
    when q is in no face of the fan; π/2 at the corner 0 = (0, 0)."""
    mesh = grid()
    angle = jax.jit(trace._mesh_angle)
    ctx = context()
    for out, other in ((5, 15), (15, 5)):  # vertex 5a + b is at (a, b, 0)
        q = in_frame([other // 5, 0.0, 0.0])
        got = angle(ctx, I32(10), I32(out), q, I32(VERTEX), I32(other))
        np.testing.assert_allclose(float(got), np.pi, rtol=1e-12)
    q = [2.3, 0.4, 0.0]
    f = next(g for g in fan_of(mesh, 10) if _inside(mesh, g, q))
    from_5 = float(angle(ctx, I32(10), I32(5), in_frame(q), I32(FACE), I32(f)))
    from_15 = float(angle(ctx, I32(10), I32(15), in_frame(q), I32(FACE), I32(f)))
    np.testing.assert_allclose(from_5 + from_15, np.pi, rtol=1e-12)
    np.testing.assert_allclose(from_15, np.arctan2(0.4, 0.3), rtol=1e-12)
    far = face_with(mesh, [18, 19])
    assert float(angle(ctx, I32(10), I32(5), in_frame(q), I32(FACE), I32(far))) == 0
    corner = angle(ctx, I32(0), I32(1), in_frame([1.0, 0, 0]), I32(VERTEX), I32(5))
    np.testing.assert_allclose(float(corner), np.pi / 2, rtol=1e-12)


def fan_of(mesh, v):
    faces = np.asarray(mesh.vertex_faces)[v]
    return faces[faces >= 0].tolist()


def _inside(mesh, f, q):
    """Whether the flat point q lies in face f."""
    a, b, c = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[f]][:, :2]
    m = np.stack([b - a, c - a], axis=1)
    s, t = np.linalg.solve(m, np.asarray(q[:2]) - a)
    return s >= 0 and t >= 0 and s + t <= 1


def test_boundary_slide_takes_the_rim_edge_towards_the_aim_or_keeps_its_way():
    """From vertex 10 on the rim, aiming left (−x) it slides to 5, aiming right to
    15, each with its way round the loop (+1 along `boundary_next`); a slide
    already under way keeps its way whatever the aim; it never goes back to the
    previous point, nor to an end behind the chord."""
    mesh = grid()
    slide = jax.jit(trace._boundary_slide)
    ctx = context()
    star = trace.star_faces(mesh, I32(VERTEX), I32(10))
    pos = in_frame([2.0, 0, 0])
    nxt = int(mesh.boundary_next[10])
    for aim, to in (([0.0, 0.5, 0], 5), ([4.0, 0.5, 0], 15)):
        ok, w, way = slide(ctx, pos, in_frame(aim), I32(VERTEX), I32(10), star,
                           I32(0), I32(-1))  # fmt: skip
        assert bool(ok) and int(w) == to and int(way) == (1 if to == nxt else -1)
        # under way the other way round: the aim no longer decides
        ok, w, way2 = slide(ctx, pos, in_frame(aim), I32(VERTEX), I32(10), star,
                            -way, I32(-1))  # fmt: skip
        assert bool(ok) and int(w) == 20 - to and int(way2) == -int(way)
    # the previous point is never slid back to, and the other end is behind
    ok, _, _ = slide(ctx, pos, in_frame([0.0, 0.5, 0]), I32(VERTEX), I32(10), star,
                     I32(0), I32(5))  # fmt: skip
    assert not bool(ok)


def ends_and_state(start, end, status=-1):
    ctx = context()
    ends = trace._ends(ctx, start, end)
    return ends, trace._initial_state(ctx, start, ends, status)


@pytest.mark.slow  # compiles System (16)'s solver: 16 s cold on 2 loaded cores
def test_look_ahead_finds_the_crossing_on_the_start_faces_edge():
    """From the centre of a face towards a point three faces on, the nearest
    crossing ahead is on an edge of the start face; towards a point of a
    neighbouring face the aim is reached at once."""
    mesh = grid()
    f0 = face_with(mesh, [0, 6])  # cell (0, 0): split along its diagonal 0–6
    third = jnp.full(3, 1 / 3)
    far = SurfacePoint(I32(face_with(mesh, [12, 18])), third)
    ends, state = ends_and_state(SurfacePoint(I32(f0), third), far)
    ahead = jax.jit(trace._look_ahead)(context(), ends, state)
    assert bool(ahead.crossed) and not bool(ahead.reached) and not bool(ahead.jumped)
    assert int(ahead.cross_kind) == EDGE
    assert int(ahead.cross_idx) in np.asarray(mesh.face_edges[f0]).tolist()
    near = SurfacePoint(I32(f0), jnp.asarray([0.2, 0.3, 0.5]))
    ends, state = ends_and_state(SurfacePoint(I32(f0), third), near)
    ahead = jax.jit(trace._look_ahead)(context(), ends, state)
    assert bool(ahead.reached) and bool(ahead.done)


@pytest.mark.slow  # compiles a step and a trace: 25 s cold on 2 loaded cores
def test_a_finished_lane_does_not_step_and_a_trace_is_its_steps():
    """`_step` leaves a state with a status alone; stepping a fresh state until it
    has one gives `trace`'s path."""
    mesh = grid()
    third = jnp.full(3, 1 / 3)
    start = SurfacePoint(I32(face_with(mesh, [0, 6])), third)
    end = SurfacePoint(I32(face_with(mesh, [18, 24])), third)
    step = jax.jit(trace._step)
    ends, done = ends_and_state(start, end, Status.NO_CROSSING)
    after = step(context(), ends, done)
    for a, b in zip(jax.tree.leaves(done), jax.tree.leaves(after)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    ends, state = ends_and_state(start, end)
    for _ in range(16):
        state = step(context(), ends, state)
        if int(state.status) >= 0:
            break
    assert int(state.status) == Status.SUCCESS
    ctx = context()
    path = trace.trace(mesh, ctx.normals, start, end, ctx.options)
    assert int(path.count) == int(state.count) > 3
    np.testing.assert_array_equal(path.elements, state.elems)
    np.testing.assert_array_equal(path.kinds, state.kinds)
