"""A corridor of faces unfolded into the plane (a *sleeve*), in JAX.

A corridor is a sequence of faces f_0 … f_{n−1} in which consecutive faces share an
edge, the *portal* k between f_k and f_{k+1}. Travelling from f_0 to f_{n−1}, each
portal has a left and a right vertex. The unfolding lays f_0 in the plane and every
next face across its portal, so that the shortest path inside the corridor is a
polyline of the plane (`pull`).

Every vertex *occurrence* gets an instance id: 0 and 1 for portal 0's left and
right vertex, k + 2 for the vertex of f_{k+1} opposite portal k. A vertex stays the
same instance over the consecutive portals it belongs to (`inst_first` …
`inst_last`), which is how the string pull and the flips tell a vertex the path wraps.

The unfolding is two prefix sums over the fixed capacity (masked past n), of the
turning angles and of the portals' origins, so that `jax.grad` goes through it:
it is also the differentiable length of the frozen combinatorics (envelope
theorem, see `jaxgeo.exact`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._numerics import dot, last_at_or_before, safe_norm


class Sleeve(eqx.Module):
    """The unfolded corridor. Portal arrays have the corridor's capacity C (entry
    k < n − 1 live); instance arrays have C + 1 entries (ids 0 … n live)."""

    n: Int[Array, ""]
    edge: Int[Array, " C"]
    left: Int[Array, " C"]
    right: Int[Array, " C"]
    left_inst: Int[Array, " C"]
    right_inst: Int[Array, " C"]
    inst_vertex: Int[Array, " C1"]
    inst_xy: Float[Array, "C1 2"]
    inst_first: Int[Array, " C1"]
    inst_last: Int[Array, " C1"]
    inst_is_left: Bool[Array, " C1"]
    start_xy: Float[Array, " 2"]
    end_xy: Float[Array, " 2"]
    valid: Bool[Array, ""]


def cross2d(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _cmul(a, b):
    """The product of complex numbers stored as (re, im) pairs."""
    return jnp.stack(
        [
            a[..., 0] * b[..., 0] - a[..., 1] * b[..., 1],
            a[..., 0] * b[..., 1] + a[..., 1] * b[..., 0],
        ],
        -1,
    )


def portals(faces: Int[Array, "F 3"], face_edges: Int[Array, "F 3"], corridor, n):
    """Edge, left and right vertex of every portal, the vertex opposite it in the
    next face, and whether consecutive corridor faces share an edge."""
    f, g = corridor[:-1], corridor[1:]
    fe, ge = face_edges[f], face_edges[g]  # (C-1, 3)
    match = fe[:, :, None] == ge[:, None, :]  # (C-1, 3, 3)
    shared = jnp.any(match, axis=(1, 2))
    cf = jnp.argmax(jnp.any(match, axis=2), axis=1)  # corner of f opposite it
    cg = jnp.argmax(jnp.any(match, axis=1), axis=1)
    rows = jnp.arange(f.shape[0])
    edge = fe[rows, cf]
    right = faces[f, :][rows, (cf + 1) % 3]
    left = faces[f, :][rows, (cf + 2) % 3]
    opposite = faces[g, :][rows, cg]
    live = jnp.arange(f.shape[0]) < n - 1
    valid = jnp.all(jnp.where(live, shared & (f != g), True))
    pad = jnp.zeros((1,), left.dtype)
    return (
        jnp.concatenate([edge, pad]),
        jnp.concatenate([left, pad]),
        jnp.concatenate([right, pad]),
        jnp.concatenate([opposite, pad]),
        valid,
    )


def unfold(
    vertices: Float[Array, "V 3"],
    faces: Int[Array, "F 3"],
    face_edges: Int[Array, "F 3"],
    corridor: Int[Array, " C"],
    n: Int[Array, ""],
    start_bary: Float[Array, " 3"],
    end_bary: Float[Array, " 3"],
) -> Sleeve:
    """Unfold `corridor[:n]` (n ≥ 2). `start_bary`/`end_bary` are the endpoints'
    barycentric coordinates in the corridor's first/last face."""
    cap = corridor.shape[0]
    dtype = vertices.dtype
    edge, left, right, opp, valid = portals(faces, face_edges, corridor, n)
    # 3-D frames of every portal: the opposite vertex in edge coordinates
    lv, rv, ov = vertices[left], vertices[right], vertices[opp]
    e = lv - rv
    el = safe_norm(e)
    el_ = jnp.where(el > 0, el, 1.0)
    q = ov - rv
    ox = dot(q, e) / el_
    oy = safe_norm(jnp.cross(e, q)) / el_
    # face 0's third vertex, behind portal 0
    f0 = faces[corridor[0]]
    apex0 = jnp.sum(jnp.where((f0 != left[0]) & (f0 != right[0]), f0, 0))
    qa = vertices[apex0] - rv[0]
    ax = jnp.sum(qa * e[0]) / el_[0]
    ay = safe_norm(jnp.cross(e[0], qa)) / el_[0]

    live = jnp.arange(cap) < n - 1
    # the next portal keeps its right end (the new vertex is its left one) or its
    # left end
    keep_right = live & jnp.concatenate([right[1:] == right[:-1], jnp.array([False])])
    keep_left = live & ~keep_right
    # Portal k's frame: origin at its right vertex, x towards its left one, y
    # backwards (the next face lies at y < 0). In it the next vertex is
    # w = (ox, −oy) and the next portal is (w, r) or (l, w): the frame of portal
    # k + 1 is z_k = t_k + c_k z_{k+1} with a unit complex c_k = e^{iφ_k}. Portal
    # k's frame in the plane is the composition of the maps of portals 0 … k − 1:
    # rotation by Φ_k = φ_0 + … + φ_{k−1} and origin T_k = Σ_{j<k} e^{iΦ_j} t_j, two
    # prefix sums (vector steps, no C dependent ones; as accurate as the product
    # of the unit complexes, ~k eps).
    wx, wy = ox, -oy
    keep_c = jnp.stack([wx, wy], -1)  # (l, r) → (w, r): x turns towards w
    move_c = jnp.stack([el - wx, -wy], -1)  # → (l, w): origin w, x towards l
    c = jnp.where(keep_right[:, None], keep_c, move_c)
    c_norm = safe_norm(c)
    # (a degenerate portal, or a dead one, turns by 0)
    phi = jnp.where(
        (c_norm > 0) & live,
        jnp.arctan2(c[:, 1], jnp.where(c_norm > 0, c[:, 0], 1.0)),
        0.0,
    )
    t = jnp.where((keep_right | ~live)[:, None], 0.0, jnp.stack([wx, wy], -1))
    turn = jnp.cumsum(phi) - phi  # Φ_k (exclusive)
    # (a barrier: else XLA's CPU backend computes the sines and cosines again in
    # each of the two products below, 2 × ~25 µs for 8 × 256 portals)
    C = jax.lax.optimization_barrier(jnp.stack([jnp.cos(turn), jnp.sin(turn)], -1))
    Ct = _cmul(C, t)
    T = jnp.cumsum(Ct, axis=0) - Ct  # T_k (exclusive)
    w2 = T + _cmul(C, jnp.stack([wx, wy], -1))

    # instances: 0, 1 = portal 0's ends; k + 2 = vertex opposite portal k. Portal
    # k's left (right) end is the last vertex that became a left (right) end.
    k = jnp.arange(cap, dtype=jnp.int32)
    li = jax.lax.cummax(jnp.where(keep_right, k + 2, 0))
    ri = jax.lax.cummax(jnp.where(keep_left, k + 2, 1))
    li = jnp.concatenate([jnp.zeros(1, jnp.int32), li[:-1]])
    ri = jnp.concatenate([jnp.ones(1, jnp.int32), ri[:-1]])
    inst_vertex = jnp.concatenate([jnp.stack([left[0], right[0]]), opp[:-1]])
    l0 = jnp.stack([el[0], jnp.zeros((), dtype)])
    inst_xy = jnp.concatenate([jnp.stack([l0, jnp.zeros(2, dtype)]), w2[:-1]])
    l2, r2 = inst_xy[li], inst_xy[ri]
    inst_first = jnp.concatenate([jnp.zeros(2, jnp.int32), k[:-1] + 1])
    big = jnp.where(live, k, -1)
    inst_last = (
        jnp.full(cap + 1, -1, jnp.int32)
        .at[jnp.where(live, li, cap)]
        .max(big, mode="drop")
        .at[jnp.where(live, ri, cap)]
        .max(big, mode="drop")
    )
    is_left = (
        jnp.zeros(cap + 1, bool).at[jnp.where(live, li, cap)].set(True, mode="drop")
    )

    # the endpoints, from the barycentric coordinates of the first/last face
    a2 = jnp.stack([ax, ay])  # portal 0 frame: forward is −y, f_0 behind
    corners0 = jnp.where(
        (f0 == left[0])[:, None],
        l2[0],
        jnp.where((f0 == right[0])[:, None], r2[0], a2),
    )
    last = jnp.maximum(n - 2, 0)
    fl = faces[corridor[jnp.maximum(n - 1, 0)]]
    corners1 = jnp.where(
        (fl == left[last])[:, None],
        l2[last],
        jnp.where((fl == right[last])[:, None], r2[last], w2[last]),
    )
    return Sleeve(
        n=n,
        edge=edge,
        left=left,
        right=right,
        left_inst=li,
        right_inst=ri,
        inst_vertex=inst_vertex,
        inst_xy=inst_xy,
        inst_first=inst_first,
        inst_last=inst_last,
        inst_is_left=is_left,
        start_xy=start_bary @ corners0,
        end_xy=end_bary @ corners1,
        valid=valid,
    )


def portal_xy(sleeve: Sleeve) -> tuple[Float[Array, "C 2"], Float[Array, "C 2"]]:
    """2-D positions of every portal's left and right vertex."""
    return sleeve.inst_xy[sleeve.left_inst], sleeve.inst_xy[sleeve.right_inst]


#: Instance ids of the endpoints in a pinned list.
START, END = -1, -2


def lane_loop(cond, body, state, unroll: int = 4):
    """`while any lane is active: state = vmap(body)(state, active)`, for a state
    whose leaves have a leading lane axis. Unlike `vmap(while_loop)` it never
    selects whole carried buffers between iterations, so `body` must leave an
    inactive lane unchanged itself (scatter with `mode="drop"` to an index out
    of range, `where` on scalars). That also lets one iteration take `unroll`
    steps (a lane that finishes at the first is left alone by the second): the
    loop's own operations, its test and the copies of the state, are then paid
    once per `unroll` steps (with 2, the funnel alone 5–15 % faster at 1 and 4
    lanes on the starts of 8 catenoid pairs than with 1; with 4, 108 -> 82 µs a
    round on a 103-face corridor of the 20k catenoid, one lane, and single paths
    6 % faster; 8 no better)."""
    active = jax.vmap(cond)

    def step(s):
        for _ in range(unroll):
            s = jax.vmap(body)(s, active(s))
        return s

    return jax.lax.while_loop(lambda s: jnp.any(active(s)), step, state)


def _funnel_stream(sl: Sleeve):
    """The points the funnel takes in order, one row per portal: x, y, instance
    id and 1 if the point joins the right chain (0: the left). Portal k ≥ 1 adds
    the end it does not share with portal k − 1; the end point comes last."""
    cap = sl.left.shape[0]
    lxy, rxy = portal_xy(sl)
    k = jnp.arange(cap)
    j = jnp.clip(k, 1, cap - 1)
    at_end = k >= sl.n - 1
    right = at_end | (sl.left_inst[j] == sl.left_inst[j - 1])
    xy = jnp.where(
        at_end[:, None], sl.end_xy, jnp.where(right[:, None], rxy[j], lxy[j])
    )
    inst = jnp.where(at_end, END, jnp.where(right, sl.right_inst[j], sl.left_inst[j]))
    dtype = xy.dtype
    return jnp.concatenate(
        [xy, inst.astype(dtype)[:, None], right.astype(dtype)[:, None]], axis=1
    )


def funnel(
    sleeves: Sleeve,
) -> tuple[Int[Array, "B P"], Int[Array, " B"], Bool[Array, " B"]]:
    """The shortest path inside each sleeve of a lane batch, by the funnel algorithm
    of Lee & Preparata (1984): the instance ids of the points where it bends,
    `START` first and `END` last, their count, and False when the loop ran out of
    steps (it cannot for a valid sleeve).

    The funnel is a deque: the left chain, the apex, the right chain, each chain the
    taut string from the apex to the portal end on its side (a left chain turns left
    at every point, a right chain right). Each portal adds one new vertex on one
    side (the end point comes last, on the right; `_funnel_stream`). One loop step
    either pops the chain end the new point does not turn correctly from, or, when
    its own chain is empty and the point is on or beyond the other chain's first
    segment, moves the apex one point along that chain (the old apex becomes a bend
    of the path), or pushes the point. Every point is pushed once and popped or
    passed by the apex at most once: at most 3 steps per portal (about 2 on random
    pairs), one cheap step for all lanes at a time.

    The loop's state is packed into few arrays (the counters in one vector, each
    deque slot as x, y and id in one row): every array the loop updates costs
    the CPU runtime an operation per step, and the steps are dependent, so the
    count of operations, not their arithmetic, sets the time (packed: 14
    operations a step instead of 32, 1.8–2.4× faster at 1–4 lanes). The ids
    (at most C + 1) ride in the float rows, exact in float32 below 2^24."""
    cap = sleeves.left.shape[-1]
    size = 2 * cap + 3  # a chain grows by at most one slot per point, either way
    mid = cap + 1  # the apex's first slot
    limit = 3 * cap + 8
    lanes = sleeves.n.shape[0]
    dtype = sleeves.inst_xy.dtype
    stream = jax.vmap(_funnel_stream)(sleeves)  # (B, C, 4)
    # the counters: the next point, the left chain's end, the apex, the right
    # chain's end, the path's bends so far, done, steps
    NEXT, LO, APEX, HI, M, DONE, STEPS = range(7)

    def cond(s):
        c = s[0]
        return (c[DONE] == 0) & (c[STEPS] < limit)

    def body(s, active):
        c, deque, out, stream = s
        i, lo, apex, hi = c[NEXT], c[LO], c[APEX], c[HI]
        row = stream[i]
        p, ip, right = row[:2], row[2], row[3] > 0
        at_end = ip == END
        sign = jnp.where(right, 1.0, -1.0)  # a right chain turns clockwise
        step = jnp.where(right, 1, -1)  # its slots grow upwards
        end = jnp.where(right, hi, lo)
        other = apex - step  # the other chain's first point
        near = deque[jnp.stack([end, end - step, other, apex])]  # (4, 3)
        e_xy, e2_xy, o_xy, a_xy = near[0, :2], near[1, :2], near[2, :2], near[3, :2]
        own = end != apex  # the point's own chain is not empty
        keep = sign * cross2d(e_xy - e2_xy, p - e_xy) < 0
        has_other = jnp.where(right, apex > lo, hi > apex)
        # a point on the other chain's first segment counts as beyond it (as in
        # Mononen's funnel): the funnel never has zero width, where rounding could
        # let its sides swap (a path 5e-4 short, outside its corridor, was seen)
        advance = ~own & has_other & (sign * cross2d(o_xy - a_xy, p - a_xy) >= 0)
        push = (own & keep) | (~own & ~advance)
        pop = own & ~keep
        new_end = jnp.where(push, end + step, jnp.where(pop, end - step, other))
        new = jnp.stack(
            [
                i + push,
                jnp.where(right, lo, new_end),
                jnp.where(advance, other, apex),
                jnp.where(right, new_end, hi),
                c[M] + advance,
                (push & at_end).astype(jnp.int32),
                c[STEPS] + 1,
            ]
        )
        slot = jnp.where(active & push, new_end, size)
        bend = jnp.where(active & advance, c[M], out.shape[0])
        # (an advance pushes nothing: the old apex's neighbour is read above)
        return (
            jnp.where(active, new, c),
            deque.at[slot].set(jnp.concatenate([p, ip[None]]), mode="drop"),
            out.at[bend].set(near[2, 2].astype(jnp.int32), mode="drop"),
            stream,
        )

    left0, right0 = sleeves.left_inst[:, 0], sleeves.right_inst[:, 0]

    def slot_row(xy, inst):
        return jnp.concatenate([xy, inst.astype(dtype)[:, None]], axis=1)

    def at(inst):  # the lanes' positions of one instance each
        return jnp.take_along_axis(sleeves.inst_xy, inst[:, None, None], axis=1)[:, 0]

    deque = jnp.zeros((lanes, size, 3), dtype).at[:, :, 2].set(END)
    deque = deque.at[:, mid - 1].set(slot_row(at(left0), left0))
    deque = deque.at[:, mid].set(slot_row(sleeves.start_xy, jnp.full(lanes, START)))
    deque = deque.at[:, mid + 1].set(slot_row(at(right0), right0))
    out = jnp.full((lanes, cap + 2), END, jnp.int32).at[:, 0].set(START)
    zero = jnp.zeros(lanes, jnp.int32)
    counters = jnp.stack(
        [
            zero + 1,  # portal 0's ends are in the deque, portal 1 is next
            zero + mid - 1,
            zero + mid,
            zero + mid + 1,
            zero + 1,  # START
            (sleeves.n < 2).astype(jnp.int32),  # one face: the straight segment
            zero,
        ],
        axis=1,
    )
    c, deque, out, _ = lane_loop(cond, body, (counters, deque, out, stream))
    ids = deque[..., 2].astype(jnp.int32)

    def close(ids, apex, hi, out, m, n):
        # the path: the bends so far, then the right chain (it ends at END)
        k = jnp.arange(size)
        to = jnp.where((k > apex) & (k <= hi) & (n >= 2), m + k - apex - 1, cap + 2)
        out = out.at[to].set(ids, mode="drop")
        return out, jnp.where(n >= 2, m + hi - apex, 2)

    out, m = jax.vmap(close)(ids, c[:, APEX], c[:, HI], out, c[:, M], sleeves.n)
    return out, m.astype(jnp.int32), c[:, DONE] == 1


def _pin_ranges(sl: Sleeve, pins):
    """Portal range [a, b] of every pinned point (START: −1, END: n − 1)."""
    inst = jnp.maximum(pins, 0)
    end = sl.n - 1

    def at(first_or_last):
        return jnp.where(pins == START, -1, jnp.where(pins == END, end, first_or_last))

    return at(sl.inst_first[inst]), at(sl.inst_last[inst])


def pins_xy(sl: Sleeve, pins):
    """2-D positions of pinned points (instance ids, `START`, `END`)."""
    inst = jnp.maximum(pins, 0)
    return jnp.where(
        (pins == START)[:, None],
        sl.start_xy,
        jnp.where((pins == END)[:, None], sl.end_xy, sl.inst_xy[inst]),
    )


def _pull_step(sl: Sleeve, pins, m, tol, angle_tol):
    """One step of the parallel string pull of one sleeve: in every segment
    between consecutive pins, pin the portal end that the segment misses by the
    most; unpin every point the string turns away from. Returns the new pins,
    their count, and whether anything changed."""
    cap = sl.left.shape[0]
    size = pins.shape[0]
    j_all = jnp.arange(size)
    live_pin = j_all < m
    a, b = _pin_ranges(sl, pins)
    xy = pins_xy(sl, pins)
    # segment j runs from pin j to pin j + 1; portal k lies in segment j(k), the
    # last pin whose range ends before k, unless it is in pin j(k)+1's range
    k = jnp.arange(cap)
    starts = jnp.where(live_pin & (j_all < m - 1), b + 1, cap)
    seg = jnp.clip(last_at_or_before(starts, cap), 0, size - 2)
    portal_live = (k < sl.n - 1) & (k > b[seg]) & (k < a[seg + 1])
    P, Q = xy[seg], xy[seg + 1]
    d = Q - P
    dn = safe_norm(d)
    dn_ = jnp.where(dn > 0, dn, 1.0)
    lxy, rxy = portal_xy(sl)
    # depth by which the segment's line misses each end (> 0: on the wrong side)
    miss_l = -cross2d(d, lxy - P) / dn_
    miss_r = cross2d(d, rxy - P) / dn_
    use_l = miss_l >= miss_r
    depth = jnp.where(portal_live & (dn > 0), jnp.maximum(miss_l, miss_r), -jnp.inf)
    cand = jnp.where(use_l, sl.left_inst, sl.right_inst)
    best = jax.ops.segment_max(depth, seg, num_segments=size)
    is_best = (depth == best[seg]) & (depth > tol)
    first_k = jax.ops.segment_min(jnp.where(is_best, k, cap), seg, num_segments=size)
    ins = (first_k < cap) & live_pin & (j_all < m - 1)
    ins_inst = cand[jnp.minimum(first_k, cap - 1)]
    # turns: a left pin must turn left (counter-clockwise), a right pin right
    prev = xy[jnp.maximum(j_all - 1, 0)]
    nxt = xy[jnp.minimum(j_all + 1, size - 1)]
    turn = cross2d(xy - prev, nxt - xy)
    inner = (j_all >= 1) & (j_all < m - 1)
    is_left = sl.inst_is_left[jnp.maximum(pins, 0)]
    scale = safe_norm(xy - prev) * safe_norm(nxt - xy)
    wrong = inner & jnp.where(
        is_left, turn < -angle_tol * scale, turn > angle_tol * scale
    )
    # a pin is dropped when it turns the wrong way, but not two neighbours at once
    # (each one's turn is measured against the other)
    prev_wrong = jnp.concatenate([jnp.array([False]), wrong[:-1]])
    drop = wrong & ~(prev_wrong & (jnp.arange(size) % 2 == 1))
    keep = live_pin & ~drop
    count = keep.astype(jnp.int32) + ins.astype(jnp.int32)
    start = jnp.cumsum(count) - count
    new = jnp.full(size, END, jnp.int32)
    new = new.at[jnp.where(keep, start, size)].set(pins, mode="drop")
    new = new.at[jnp.where(ins, start + keep, size)].set(ins_inst, mode="drop")
    new_m = jnp.sum(count)
    changed = jnp.any(ins) | jnp.any(drop)
    return new, new_m.astype(jnp.int32), changed, new_m <= size


def pull(
    sleeves: Sleeve, max_steps: int = 64
) -> tuple[Int[Array, "B P"], Int[Array, " B"], Bool[Array, " B"]]:
    """The shortest path inside each sleeve of a lane batch, pinned points as the funnel
    algorithm gives them, computed in parallel over the portals: starting from the
    straight segment, every step pins in each segment between consecutive pins the
    portal end its line misses by the most, and unpins the points the string turns away
    from. The result is the shortest path when no portal end is missed and every pin is
    wrapped the right way (a locally shortest path in a simply connected sleeve is the
    shortest), which is when a step changes nothing. That takes a few steps more than
    log₂ of the pins; a lane that has not converged in `max_steps` steps returns False
    (the exact engine then reports the lane as failed: another start may still succeed).
    It gives the same pins as the sequential `funnel` of Lee & Preparata
    (`tests/test_sleeve.py`) in a few dozen vector steps instead of ~2 dependent
    steps per portal. The engine uses the funnel: on this CPU it is faster at every
    lane count (0.57 against 0.82 ms for 4 sleeves of the 20k catenoid's starts, 4.7
    against 11.4 ms for 64); a GPU, where each loop step costs a kernel launch, may
    prefer the pull (not measured)."""
    lanes = sleeves.n.shape[0]
    cap = sleeves.left.shape[-1]
    size = cap + 2
    dtype = sleeves.inst_xy.dtype
    extent = jnp.max(jnp.abs(sleeves.inst_xy), axis=(1, 2)) + safe_norm(
        sleeves.start_xy - sleeves.end_xy
    )
    # rounding of the unfolding: in lengths (relative to the sleeve's extent) and
    # in the sine of a turn
    angle_tol = 64 * float(jnp.finfo(dtype).eps)
    tol = angle_tol * extent
    pins = jnp.full((lanes, size), END, jnp.int32).at[:, 0].set(START)
    m = jnp.full(lanes, 2, jnp.int32)

    def cond(s):
        _, _, changed, fits, step = s
        return (step < max_steps) & jnp.any(changed & fits)

    def body(s):
        pins, m, changed, fits, step = s
        go = changed & fits
        p2, m2, c2, f2 = jax.vmap(_pull_step, in_axes=(0, 0, 0, 0, None))(
            sleeves, pins, m, tol, angle_tol
        )
        return (
            jnp.where(go[:, None], p2, pins),
            jnp.where(go, m2, m),
            jnp.where(go, c2, changed),
            jnp.where(go, f2, fits),
            step + 1,
        )

    init = (pins, m, jnp.ones(lanes, bool), jnp.ones(lanes, bool), jnp.int32(0))
    pins, m, changed, fits, _ = jax.lax.while_loop(cond, body, init)
    return pins, m, ~changed & fits
