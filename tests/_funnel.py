"""The funnel algorithm (Lee & Preparata; Mononen's "simple stupid funnel"), one
dependent step per portal: the reference that `jaxgeo._sleeve.pull`, the
engine's parallel string pull, is tested against (`tests/test_sleeve.py`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Int

from jaxgeo._sleeve import END, START, Sleeve, cross2d, lane_loop, portal_xy


def funnel(
    sleeves: Sleeve, active: Bool[Array, " B"] | None = None
) -> tuple[Int[Array, "B P"], Int[Array, " B"], Bool[Array, " B"]]:
    """The shortest path inside each sleeve of a lane batch (the funnel algorithm
    of Lee & Preparata, in the form of Mononen's "simple stupid funnel"): the
    instance ids of the points where it bends, `START` first and `END` last, their
    count, and False when the loop ran out of steps (it cannot for a valid sleeve:
    each restart moves on). Lanes where `active` is False take no step (their
    result is meaningless)."""
    cap = sleeves.left.shape[-1]
    # a guard, not a budget: each restart goes back to the portal after the new
    # apex, so a sleeve of n portals takes up to n·(bends + 1) steps (a corridor
    # of 182 faces needed more than 4·256 + 8 on the 20k catenoid)
    limit = cap * (cap + 2) + 8
    lxy, rxy = jax.vmap(portal_xy)(sleeves)

    def point(sl, lx, rx, i):
        at_end = i >= sl.n - 1
        j = jnp.minimum(i, cap - 1)
        return (
            jnp.where(at_end, sl.end_xy, lx[j]),
            jnp.where(at_end, END, sl.left_inst[j]),
            jnp.where(at_end, sl.end_xy, rx[j]),
            jnp.where(at_end, END, sl.right_inst[j]),
        )

    def cond(s):
        lane = s[0]
        return (s[1] <= lane.n - 1) & (s[13] < limit)

    def body(s, active):
        sl, i, ap, ai, a_i, lp, li, l_i, rp, ri, r_i, out, m, steps, lx, rx = s
        pl, il, pr, ir = point(sl, lx, rx, i)
        # A side at the apex bounds nothing (right after a restart, or while the
        # apex's vertex stays a portal end): any point narrows it, and the other
        # side cannot cross it. Mononen's version skips the crossing test when the
        # *moving* side is at the apex, which let a point beyond the other side
        # invert the funnel (5.8 % long on a flat grid). A point on the other
        # side's ray counts as crossing it (as in Mononen's): the funnel never has
        # zero width, where rounding could let the sides swap (seen on the
        # catenoid: a path 5e-4 shorter than the exact one, outside its corridor).
        r_apex = ir == ai  # the new right point is the apex's vertex itself
        r_tight = (ri == ai) | r_apex | (cross2d(rp - ap, pr - ap) >= 0)
        r_over = r_tight & ~r_apex & (li != ai) & (cross2d(lp - ap, pr - ap) >= 0)
        r_move = r_tight & ~r_over
        rp2 = jnp.where(r_move, pr, rp)
        ri2 = jnp.where(r_move, ir, ri)
        r_i2 = jnp.where(r_move, i, r_i)
        # the left side, unless the right restarted the funnel
        l_apex = il == ai
        l_tight = ~r_over & ((li == ai) | l_apex | (cross2d(lp - ap, pl - ap) <= 0))
        l_over = l_tight & ~l_apex & (ri2 != ai) & (cross2d(rp2 - ap, pl - ap) <= 0)
        l_move = l_tight & ~l_over
        lp2 = jnp.where(l_move, pl, lp)
        li2 = jnp.where(l_move, il, li)
        l_i2 = jnp.where(l_move, i, l_i)
        restart = r_over | l_over  # the other side becomes the apex
        np_ = jnp.where(r_over, lp2, rp2)
        ni = jnp.where(r_over, li2, ri2)
        n_i = jnp.where(r_over, l_i2, r_i2)
        bend = active & restart
        out = out.at[jnp.where(bend, m, out.shape[0])].set(ni, mode="drop")

        def upd(new, old):
            return jnp.where(active, new, old)

        return (
            sl,
            upd(jnp.where(restart, n_i + 1, i + 1), i),
            upd(jnp.where(restart, np_, ap), ap),
            upd(jnp.where(restart, ni, ai), ai),
            upd(jnp.where(restart, n_i, a_i), a_i),
            upd(jnp.where(restart, np_, lp2), lp),
            upd(jnp.where(restart, ni, li2), li),
            upd(jnp.where(restart, n_i, l_i2), l_i),
            upd(jnp.where(restart, np_, rp2), rp),
            upd(jnp.where(restart, ni, ri2), ri),
            upd(jnp.where(restart, n_i, r_i2), r_i),
            out,
            m + bend,
            steps + active,
            lx,
            rx,
        )

    lanes = sleeves.n.shape[0]
    sp = sleeves.start_xy
    i32 = jnp.zeros(lanes, jnp.int32)
    out = jnp.full((lanes, cap + 2), END, jnp.int32).at[:, 0].set(START)
    i0 = i32 if active is None else jnp.where(active, 0, sleeves.n).astype(jnp.int32)
    init = (
        sleeves, i0, sp, i32 + START, i32 - 1, sp, i32 + START, i32 - 1,
        sp, i32 + START, i32 - 1, out, i32 + 1, i32, lxy, rxy,
    )  # fmt: skip
    s = lane_loop(cond, body, init)
    out, m, steps = s[11], s[12], s[13]

    def close(out, m):
        ends_at_end = out[m - 1] == END
        out = jnp.where(ends_at_end, out, out.at[m].set(END))
        return out, jnp.where(ends_at_end, m, m + 1)

    out, m = jax.vmap(close)(out, m)
    return out, m.astype(jnp.int32), steps < limit
