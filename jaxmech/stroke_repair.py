"""The robust half of a stroke: the points the straight-line walk did not solve, solved
again with bounded work, batched over every failed point of every design at once.

The straight-line walk (``stroke_stages.walk_block``) solves a stroke forward by checked
Newton steps from a predicted guess; a point those steps do not bring home stays failed,
and so do the points after it (the anchor stays at the last trusted pose, without its
series).  ``repair`` takes those failures in three stages, none of whose loops is set by
one design for a whole batch:

1. **Probes** (``probe``): one fresh assembly (``stroke_point.assemble``: the guess, the
   guess with a tenth of the step cap, then ``STARTS`` fixed offsets) per design at each
   failed end of its stroke: point 0 from the design's guess, the last point from the last
   converged pose.  Two lanes a design, whatever its number of failed points.
2. **Fills** (``fill``): from each converged probe, continuation along the failed points
   towards the converged ones (forward from point 0, backward from the last point), one
   checked step a point (up to ``FRESH_STEPS`` plain Newton steps from a secant
   prediction); a fill stops at its first failure.  The backward fill re-enters a gap from
   the well-conditioned side, where the requested branch's poses are easy to reach (a
   stroke re-enters the assemblable range at a toggle, which the walk's side cannot cross).
3. **Two-sided solves** (``two_sided``): every point still failed, solved on its own by
   ``stroke_point.multistart`` from the nearest converged pose before it (the anchor the
   walk stopped at) and the nearest after it, each at the full and a tenth of the step cap:
   at most four Newton solves a point, for all such points of all designs in groups of a
   fixed size (``GROUP`` per design), so a gap's points cost a few solves each and never
   hold the batch for more.

Angles stay continuous as numbers: a fill continues from its probe, the backward fill's
run is moved by the whole turns that bring its first point within half a turn of the last
converged pose before it (where the run starts a stroke, of the guess), and a two-sided
solve's pose within half a turn of the start it came from.  Every reported pose passed the
kernel's tests on the requested branch.  Shapes: ``D`` designs, ``nb`` (bucketed) stroke
points, the first ``n`` of them the stroke, ``m`` coordinates, ``dof`` inputs.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .linalg import small_max, where
from .newton import NewtonResult
from .status import Status
from .stroke_point import FRESH_STEPS, assemble, checked_step, multistart, whole_turns
from .stroke_stages import PointResults, StrokeSetup, point_derivatives

__all__ = ["repair", "GROUP"]

#: Two-sided solves run in groups of ``GROUP`` points per design of the batch: a design
#: whose whole stroke failed takes a few groups, a batch with few failures one.
GROUP = 8


def _at(x, j):
    """``x[:, j]`` for a traced scalar index ``j`` (points on axis 1)."""
    return jax.lax.dynamic_index_in_dim(x, j, axis=1, keepdims=False)


def _set(x, j, v, mask):
    """``x`` with ``x[:, j]`` replaced by ``v`` where ``mask (D,)``."""
    old = _at(x, j)
    new = where(mask.reshape(mask.shape + (1,) * (old.ndim - 1)), v, old)
    return jax.lax.dynamic_update_index_in_dim(x, new, j, axis=1)


def _inputs(setup: StrokeSetup, us, j):
    """Every design's input at point ``j`` (traced), ``(D, dof)``."""
    d = setup.b0.shape[0]
    u = jax.lax.dynamic_index_in_dim(us, j, axis=us.ndim - 2, keepdims=False)
    return jnp.broadcast_to(u, (d, us.shape[-1]))


def _take(x, idx, fill):
    """``x[d, idx[d]]`` per design (``x (D, nb, ...)``, ``idx (D,)``), ``fill (D, ...)`` where
    ``idx`` is out of range."""
    nb = x.shape[1]
    got = jnp.take_along_axis(x, jnp.clip(idx, 0, nb - 1).reshape(idx.shape + (1,) * (x.ndim - 1)), axis=1)[:, 0]
    inside = (idx >= 0) & (idx < nb)
    return where(inside.reshape(inside.shape + (1,) * (got.ndim - 1)), got, fill)


def _record(pts: PointResults, j, mask, q, status, steps, residual, cond, branch) -> PointResults:
    """``pts`` with point ``j`` of the designs in ``mask`` replaced."""
    return pts._replace(q=_set(pts.q, j, q, mask), status=_set(pts.status, j, status, mask), steps=_set(pts.steps, j, steps, mask),
                        residual=_set(pts.residual, j, residual, mask), cond=_set(pts.cond, j, cond, mask),
                        branch=_set(pts.branch, j, branch, mask))  # fmt: skip


class FillState(NamedTuple):
    """The fills' loop state: step `t`, the points so far (`pts`), which designs' forward
    and backward fills are still going (`fwd`, `bwd`, ``(D,)``), and which points the
    backward fill solved (`by_bwd`, ``(D, nb)``)."""

    t: jax.Array
    pts: PointResults
    fwd: jax.Array
    bwd: jax.Array
    by_bwd: jax.Array


def probe(setup: StrokeSetup, us, pts: PointResults, fail, n, g0) -> tuple[PointResults, jax.Array, jax.Array]:
    """Stage 1: a fresh assembly at point 0 where it failed (from the design's guess) and at
    the stroke's last point ``n - 1`` where it failed (from the last converged pose before
    it, else the guess).  Returns ``(pts, fwd, bwd)``: the points with the probes' answers
    where they converged, and which designs' forward and backward fills start."""
    mech, opts = setup.mech, setup.options
    d, nb = fail.shape
    e = n - 1
    i = jnp.arange(nb)
    conv = pts.status == Status.CONVERGED
    last = jnp.max(where(conv & (i < e), i, -1), axis=1)
    q_last = _take(pts.q, last, g0)
    need = jnp.stack([fail[:, 0], _at(fail, e)], axis=1)  # (D, 2)
    starts = jnp.stack([g0, q_last], axis=1)
    u = jnp.stack([_inputs(setup, us, 0), _inputs(setup, us, e)], axis=1)
    flat = lambda x: x.reshape((2 * d,) + x.shape[2:])  # noqa: E731
    rep = lambda x: jnp.repeat(x, 2, axis=0)  # noqa: E731

    def one(u_, p_, b_, g_, need_):
        return assemble(mech, opts, u_, p_, g_, g_, b_, True, skip=~need_)

    res = jax.vmap(one)(flat(u), jax.tree_util.tree_map(rep, setup.p), rep(setup.b0), flat(starts), flat(need))
    res = jax.tree_util.tree_map(lambda x: x.reshape((d, 2) + x.shape[1:]), res)
    ok = need & (res.status == Status.CONVERGED)
    # a failed probe keeps the walk's own answer there: the two-sided solves try it again
    for j, col in ((0, 0), (e, 1)):
        r = jax.tree_util.tree_map(lambda x: x[:, col], res)
        pts = _record(pts, j, ok[:, col], r.q, r.status, r.steps, r.residual, r.cond, r.branch)
    return pts, ok[:, 0], ok[:, 1] & (e > 0)


def _secant(q1, q2, u0, u1, u2, have2, s, max_step):
    """A point's guess from its two neighbours' roots along the fill (``q1`` at ``u1``, the
    nearer; ``q2`` at ``u2`` where ``have2``): linear extrapolation, dropped where its step
    is larger than ``max_step`` (scaled, as Newton's)."""
    step_u = jnp.linalg.norm(u0 - u1, axis=-1)
    prev_u = jnp.linalg.norm(u1 - u2, axis=-1)
    ratio = jnp.clip(step_u / jnp.where(prev_u > 0, prev_u, 1.0), 0.0, 2.0)
    step = (q1 - q2) * ratio[:, None]
    keep = have2 & (prev_u > 0) & (jnp.max(jnp.abs(step) / s, axis=-1) <= max_step)
    return q1 + where(keep[:, None], step, 0.0)


def fill(setup: StrokeSetup, us, pts: PointResults, fail, n, fwd, bwd) -> tuple[PointResults, jax.Array]:
    """Stage 2: the fills, one point a step in each direction for every design, until
    every fill stopped (at a point it could not solve, or one the walk had solved).
    Returns ``(pts, by_bwd)``."""
    mech, opts = setup.mech, setup.options
    d, nb = fail.shape
    e = n - 1

    def lane(u, p_, b_, g_, go):
        return checked_step(mech, opts, u, p_, g_, b_, where(go, FRESH_STEPS, 0))

    def direction(st: FillState, pts: PointResults, active, j, near, far):
        go = active & _at(fail, j) & (j >= 0) & (j < n)
        have2 = (far >= 0) & (far < n)
        u0, u1, u2 = (_inputs(setup, us, jnp.clip(x, 0, nb - 1)) for x in (j, near, far))
        q1, q2 = _at(pts.q, jnp.clip(near, 0, nb - 1)), _at(pts.q, jnp.clip(far, 0, nb - 1))
        guess = _secant(q1, q2, u0, u1, u2, have2 & (_at(pts.status, jnp.clip(far, 0, nb - 1)) == Status.CONVERGED),
                        setup.scales, opts.max_step)  # fmt: skip
        chk = jax.vmap(lane)(u0, setup.p, setup.b0, guess, go)
        ok = go & chk.ok
        status = jnp.full((d,), Status.CONVERGED, jnp.int32)
        jc = jnp.clip(j, 0, nb - 1)
        return _record(pts, jc, ok, chk.q, status, chk.steps, chk.residual, chk.cond, chk.branch), go & chk.ok, ok

    def body(st: FillState) -> FillState:
        pts, fwd_ok, _ = direction(st, st.pts, st.fwd, st.t, st.t - 1, st.t - 2)
        pts, bwd_ok, solved = direction(st, pts, st.bwd, e - st.t, e - st.t + 1, e - st.t + 2)
        by_bwd = _set(st.by_bwd, jnp.clip(e - st.t, 0, nb - 1), solved, solved)
        return FillState(st.t + 1, pts, fwd_ok, bwd_ok, by_bwd)

    def more(st: FillState):
        return (st.t < n) & jnp.any(st.fwd | st.bwd)

    by_bwd = jnp.zeros((d, nb), bool).at[:, jnp.clip(e, 0, nb - 1)].set(bwd)
    st = jax.lax.while_loop(more, body, FillState(jnp.ones((), jnp.int32), pts, fwd, bwd, by_bwd))
    return st.pts, st.by_bwd


def align_backward_fill(setup: StrokeSetup, us, pts: PointResults, by_bwd, g0) -> PointResults:
    """The backward fill's run moved by the whole turns that bring its first point within
    half a turn of the last converged pose before it (else the guess), where the equations
    allow it: the angles across the gap are then what a forward walk would give."""
    mech, opts = setup.mech, setup.options
    nb = by_bwd.shape[1]
    i = jnp.arange(nb)
    first = jnp.min(where(by_bwd, i, nb), axis=1)
    conv = pts.status == Status.CONVERGED
    before = jnp.max(where(conv & ~by_bwd & (i < first[:, None]), i, -1), axis=1)
    ref = _take(pts.q, before, g0)
    q_r = _take(pts.q, first, g0)
    res_r = _take(pts.residual, first, jnp.zeros_like(first, pts.residual.dtype))
    u_all = jnp.broadcast_to(us, (by_bwd.shape[0],) + us.shape[-2:])
    u_r = _take(u_all, first, u_all[:, 0])
    have = first < nb
    moved = jax.vmap(lambda q_, g_, u_, p_, ok_, r_: whole_turns(mech, opts, q_, g_, u_, p_, ok_, r_))(q_r, ref, u_r, setup.p, have, res_r)
    shift = moved - q_r
    return pts._replace(q=where(by_bwd[..., None], pts.q + shift[:, None, :], pts.q))


def two_sided(setup: StrokeSetup, us, pts: PointResults, fail, n, g0) -> PointResults:
    """Stage 3: every point still failed, solved on its own from the nearest converged pose
    before it (else the guess) and the nearest after it (where there is one), each at the
    full and a tenth of the step cap; in groups of ``GROUP`` points per design, only as many
    groups as there are failed points."""
    mech, opts = setup.mech, setup.options
    d, nb = fail.shape
    i = jnp.arange(nb)
    conv = pts.status == Status.CONVERGED
    left = jax.lax.cummax(where(conv, i, -1), axis=1)
    right = jax.lax.cummin(where(conv & (i < n), i, nb), axis=1, reverse=True)
    todo = (fail & ~conv & (i < n)).reshape(-1)
    size = d * nb
    group = min(size, GROUP * d)
    order = jnp.nonzero(todo, size=size, fill_value=0)[0]
    count = jnp.sum(todo)
    u_all = jnp.broadcast_to(us, (d,) + us.shape[-2:]).reshape((size,) + us.shape[-1:])
    q_flat = pts.q.reshape((size, -1))
    design = jnp.repeat(jnp.arange(d), nb)
    dtype = pts.q.dtype
    cap, small = opts.max_step, 0.1 * opts.max_step
    caps = jnp.asarray([cap, small, cap, small], dtype)

    def solve(k, pts_):
        idx = jax.lax.dynamic_slice_in_dim(order, k * group, group)
        live = k * group + jnp.arange(group) < count
        dsg = design[idx]
        l_i, r_i = left.reshape(-1)[idx], right.reshape(-1)[idx]
        base = dsg * nb
        q_l = where((l_i >= 0)[:, None], q_flat[base + jnp.clip(l_i, 0, nb - 1)], g0[dsg])
        q_r = q_flat[base + jnp.clip(r_i, 0, nb - 1)]
        has_r = r_i < nb
        starts = jnp.stack([q_l, q_l, q_r, q_r], axis=1)
        p_ = jax.tree_util.tree_map(lambda x: x[dsg], setup.p)

        def one(u_, p1, b_, s_, n_, live_):
            res, j = multistart(mech, opts, u_, p1, s_, caps, n_, b_, True, skip=~live_)
            q = whole_turns(mech, opts, res.q, s_[j], u_, p1, res.status == Status.CONVERGED, res.residual)
            return res._replace(q=q)

        res: NewtonResult = jax.vmap(one)(u_all[idx], p_, setup.b0[dsg], starts, where(has_r, 4, 2), live)
        flat = lambda x: x.reshape((size,) + x.shape[2:])  # noqa: E731
        put = lambda x, v: flat(x).at[jnp.where(live, idx, size)].set(v, mode="drop").reshape(x.shape)  # noqa: E731
        return pts_._replace(q=put(pts_.q, res.q), status=put(pts_.status, res.status), steps=put(pts_.steps, res.steps),
                             residual=put(pts_.residual, res.residual), cond=put(pts_.cond, res.cond),
                             branch=put(pts_.branch, res.branch))  # fmt: skip

    groups = (count + group - 1) // group
    return jax.lax.fori_loop(0, groups, solve, pts)


def repair(setup: StrokeSetup, us, pts: PointResults, valid, n, g0) -> PointResults:
    """The straight-line walk's points ``pts`` (``(D, nb, ...)``, derivatives included where
    ``setup.derivs``) with its failed points (``valid`` inputs, not ``CONVERGED``, within
    the first ``n``) solved again by the three stages of this module.  The points the walk
    solved keep every value it gave."""
    nb = valid.shape[1]
    fail = valid & (pts.status != Status.CONVERGED) & (jnp.arange(nb) < n)
    walked = pts
    pts = pts._replace(d1=None, d2=None)
    pts, fwd, bwd = probe(setup, us, pts, fail, n, g0)
    pts, by_bwd = fill(setup, us, pts, fail, n, fwd, bwd)
    pts = align_backward_fill(setup, us, pts, by_bwd, g0)
    pts = two_sided(setup, us, pts, fail, n, g0)
    if not setup.derivs:
        return pts._replace(d1=walked.d1, d2=walked.d2)
    new = fail & (pts.status == Status.CONVERGED)
    d1, d2 = point_derivatives(setup.mech, setup.shared, where(new[..., None], pts.q, 0.0), us, setup.p, new)
    keep = lambda a, b: where(new.reshape(new.shape + (1,) * (a.ndim - 2)), a, b)  # noqa: E731
    return pts._replace(d1=keep(d1, walked.d1), d2=keep(d2, walked.d2))
