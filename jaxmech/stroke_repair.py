"""The robust half of a stroke: the points the straight-line walk did not solve, solved
again with bounded work, batched over every failed point of every design at once.

The straight-line walk (``stroke_stages.walk_block``) solves a stroke forward by checked
Newton steps from a predicted guess; a point those steps do not bring home stays failed,
and so do the points after it (the anchor stays at the last trusted pose, without its
series).  ``repair`` takes those failures in rounds of three stages, none of whose loops
is set by one design for a whole batch:

1. **Probes** (``probe``): a fresh assembly (``stroke_point.assemble``: the guess, the
   guess with a tenth of the step cap, then ``STARTS`` fixed offsets around it) at up to
   two points a design, from the nearest converged pose before the point (else the
   design's guess).  The first round probes each failed end of the stroke (point 0, the
   last point); later rounds the middle of a run of points where the loop closes only on
   another branch (``BRANCH``: an assemblable stretch the walk never reached, between two
   gaps).
2. **Fills** (``fill``): from each converged probe, continuation in both directions along
   the failed points, one checked step a point (up to ``FRESH_STEPS`` plain Newton steps
   from a secant prediction), each fill stopping at its first failure.  This re-enters a
   gap from its far side, where the requested branch's poses are easy to reach (a stroke
   re-enters the assemblable range at a toggle, which the walk's side cannot cross).
3. **Two-sided solves** (``two_sided``): every point still failed whose nearest converged
   neighbours changed, solved on its own by ``stroke_point.multistart`` from the nearest
   converged pose before it and the nearest after it, each at the full and a tenth of the
   step cap: at most four Newton solves a point, for all such points of all designs in
   groups of ``GROUP`` points per design, so a gap's points cost a few solves each and
   never hold the batch for more.

Rounds go on (at most ``ROUNDS``) while some design has a ``BRANCH`` run not probed yet.
Angles stay continuous as numbers (``unwrap``): each repaired pose is moved by whole turns,
in stroke order, to within half a turn of the converged pose before it (else of the
guess), so a stretch re-entered after a gap starts within half a turn of the last pose
before the gap, as a walk would give.  Every reported pose passed the kernel's tests on
the requested branch.  Shapes: ``D`` designs, ``nb`` (bucketed) stroke
points, the first ``n`` of them the stroke, ``m`` coordinates, ``dof`` inputs.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .linalg import where
from .newton import NewtonResult
from .status import Status
from .stroke_point import FRESH_STEPS, assemble, checked_step, multistart, score, whole_turns
from .stroke_stages import PointResults, StrokeSetup, point_derivatives

__all__ = ["repair", "GROUP", "ROUNDS", "PROBES"]

#: Two-sided solves run in groups of ``GROUP`` points per design of the batch: a design
#: whose whole stroke failed takes a few groups, a batch with few failures one.
GROUP = 8
#: Rounds of probes, fills and two-sided solves at most (the first, and two for stretches
#: between gaps).
ROUNDS = 3
#: Probes a design per round.
PROBES = 2


class Context(NamedTuple):
    """What the stages read: the stroke's inputs ``us`` (sanitised, ``(nb, dof)`` shared or
    ``(D, nb, dof)``), the failed points `fail` ``(D, nb)``, the stroke's length `n`
    (traced) and the guesses `g0` ``(D, m)``."""

    us: jax.Array
    fail: jax.Array
    n: jax.Array
    g0: jax.Array


def _expand(mask, like):
    return mask.reshape(mask.shape + (1,) * (like.ndim - mask.ndim))


def _gather(x, j):
    """``x[d, j[d, l]]`` for ``x (D, nb, ...)`` and lane indices ``j (D, L)`` (clipped)."""
    nb = x.shape[1]
    jj = jnp.clip(j, 0, nb - 1)
    return jnp.take_along_axis(x, jj.reshape(jj.shape + (1,) * (x.ndim - 2)), axis=1)


def _inputs(ctx: Context, j):
    """The inputs at lane indices ``j (D, L)``: ``(D, L, dof)``."""
    d = ctx.fail.shape[0]
    return _gather(jnp.broadcast_to(ctx.us, (d,) + ctx.us.shape[-2:]), j)


def _scatter(x, j, mask, v):
    """``x`` with ``x[d, j[d, l]] = v[d, l]`` where ``mask (D, L)`` (other lanes dropped)."""
    d, nb = x.shape[:2]
    rows = jnp.broadcast_to(jnp.arange(d)[:, None], j.shape)
    cols = jnp.where(mask, j, nb)  # out of range: dropped
    return x.at[rows, cols].set(v, mode="drop")


def _record(pts: PointResults, j, mask, res) -> PointResults:
    """``pts`` with the points ``j (D, L)`` where ``mask`` set from ``res`` (fields ``(D, L, ...)``
    named as ``PointResults``'s)."""
    fields = ("q", "status", "steps", "residual", "cond", "branch")
    return pts._replace(**{f: _scatter(getattr(pts, f), j, mask, getattr(res, f).astype(getattr(pts, f).dtype)) for f in fields})


def _nearest(conv, n):
    """``(left, right)`` ``(D, nb)``: the nearest converged point at or before each point
    (-1: none) and at or after it within the stroke (``nb``: none)."""
    nb = conv.shape[1]
    i = jnp.arange(nb)
    left = jax.lax.cummax(where(conv, i, -1), axis=1)
    right = jax.lax.cummin(where(conv & (i < n), i, nb), axis=1, reverse=True)
    return left, right


def _per_lane(setup: StrokeSetup, fn, *args):
    """``fn(p, b0, *lane args)`` over designs x lanes (``(D, L, ...)`` args)."""
    d, lanes = args[0].shape[:2]
    flat = lambda x: x.reshape((d * lanes,) + x.shape[2:])  # noqa: E731
    rep = lambda x: jnp.repeat(x, lanes, axis=0)  # noqa: E731
    out = jax.vmap(fn)(jax.tree_util.tree_map(rep, setup.p), rep(setup.b0), *map(flat, args))
    return jax.tree_util.tree_map(lambda x: x.reshape((d, lanes) + x.shape[1:]), out)


# --------------------------------------------------------------------------- 1. probes
def probe(setup: StrokeSetup, ctx: Context, pts: PointResults, at, want):
    """A fresh assembly at the points ``at (D, PROBES)`` where ``want``, from the nearest
    converged pose before each (else the guess).  Returns ``(pts, ok)``: the points with
    the probes' answers where they converged (a failed probe leaves the point as it was:
    the two-sided solves take it), and which probes did."""
    conv = pts.status == Status.CONVERGED
    left, _ = _nearest(conv, ctx.n)
    start = _gather(left, at)
    guess = where(_expand(start >= 0, pts.q[:, :1]), _gather(pts.q, start), ctx.g0[:, None])

    def one(p_, b_, u_, g_, want_):
        return assemble(setup.mech, setup.options, u_, p_, g_, g_, b_, True, skip=~want_)

    res = _per_lane(setup, one, _inputs(ctx, at), guess, want)
    ok = want & (res.status == Status.CONVERGED)
    return _record(pts, at, ok, res), ok


# --------------------------------------------------------------------------- 2. fills
class FillState(NamedTuple):
    """The fills' loop state: step `t`, the points so far (`pts`), and which lanes are
    still going (`go`, ``(D, 2 PROBES)``: each probe's forward and backward fill)."""

    t: jax.Array
    pts: PointResults
    go: jax.Array


def _secant(q1, q2, u0, u1, u2, have2, s, max_step):
    """A point's guess from its fill neighbours' roots (``q1`` at ``u1``, the nearer; ``q2``
    at ``u2`` where ``have2``), ``(..., m)``: linear extrapolation, dropped where its step is
    larger than ``max_step`` (scaled, as Newton's)."""
    step_u = jnp.linalg.norm(u0 - u1, axis=-1)
    prev_u = jnp.linalg.norm(u1 - u2, axis=-1)
    ratio = jnp.clip(step_u / jnp.where(prev_u > 0, prev_u, 1.0), 0.0, 2.0)
    step = (q1 - q2) * ratio[..., None]
    keep = have2 & (prev_u > 0) & (jnp.max(jnp.abs(step) / s, axis=-1) <= max_step)
    return q1 + where(keep[..., None], step, 0.0)


def fill(setup: StrokeSetup, ctx: Context, pts: PointResults, at, ok) -> PointResults:
    """From each converged probe (``at``, ``ok``: ``(D, PROBES)``), continuation forward and
    backward along the failed points, one point a step for every lane, until every fill
    stopped (at a point it could not solve, or one solved already)."""
    mech, opts = setup.mech, setup.options
    seed = jnp.concatenate([at, at], axis=1)
    step = jnp.concatenate([jnp.ones_like(at), -jnp.ones_like(at)], axis=1)
    scales = jnp.repeat(setup.scales[:, None], seed.shape[1], axis=1)

    def lane(p_, b_, u_, g_, go_):
        return checked_step(mech, opts, u_, p_, g_, b_, where(go_, FRESH_STEPS, 0))

    def body(st: FillState) -> FillState:
        j = seed + step * st.t
        near, far = j - step, j - 2 * step
        inside = (j >= 0) & (j < ctx.n)
        conv = st.pts.status == Status.CONVERGED
        go = st.go & inside & _gather(ctx.fail, j) & ~_gather(conv, j)
        have2 = (far >= 0) & (far < ctx.n) & _gather(conv, far)
        u0, u1, u2 = _inputs(ctx, j), _inputs(ctx, near), _inputs(ctx, far)
        guess = _secant(_gather(st.pts.q, near), _gather(st.pts.q, far), u0, u1, u2, have2, scales, opts.max_step)
        chk = _per_lane(setup, lane, u0, guess, go)
        solved = go & chk.ok
        res = PointResults(chk.q, jnp.full(j.shape, Status.CONVERGED, jnp.int32), chk.steps, chk.residual, chk.cond, chk.branch, None, None)
        pts = _record(st.pts, j, solved, res)
        return FillState(st.t + 1, pts, solved)

    def more(st: FillState):
        return (st.t < ctx.n) & jnp.any(st.go)

    return jax.lax.while_loop(more, body, FillState(jnp.ones((), jnp.int32), pts, jnp.concatenate([ok, ok], axis=1))).pts


def unwrap(setup: StrokeSetup, ctx: Context, pts: PointResults, moved) -> PointResults:
    """The points ``moved (D, nb)`` (those the repair solved, and any the walk solved after
    its first failure) moved by whole turns, in stroke
    order, to within half a turn of the converged point before each (else the guess),
    where the equations allow it: a run re-entered after a gap starts within half a turn
    of the last pose before the gap (what a walk gives), and no two neighbours differ by
    a turn."""
    mech, opts = setup.mech, setup.options
    ok = pts.status == Status.CONVERGED
    u_all = jnp.broadcast_to(ctx.us, ctx.fail.shape + ctx.us.shape[-1:])

    def one(q_, g_, u_, p_, ok_, r_):
        return whole_turns(mech, opts, q_, g_, u_, p_, ok_, r_)

    def step(carry, x):
        prev = carry
        q, u, ok_, move, res = x
        q = where(move[:, None], jax.vmap(one)(q, prev, u, setup.p, move & ok_, res), q)
        return where(ok_[:, None], q, prev), q

    xs = tuple(jnp.moveaxis(a, 1, 0) for a in (pts.q, u_all, ok, moved & ok, pts.residual))
    _, q = jax.lax.scan(step, ctx.g0, xs)
    return pts._replace(q=jnp.moveaxis(q, 0, 1))


# --------------------------------------------------------------------------- 3. point by point
def solve_points(setup: StrokeSetup, ctx: Context, pts: PointResults, todo, one, tried) -> PointResults:
    """The points ``todo (D, nb)`` solved on their own by ``one(u, p, b0, q_left, q_right,
    has_right, live) -> NewtonResult`` (``q_left``: the nearest converged pose before the
    point, else the guess; ``q_right``: the nearest after it, where ``has_right``), in
    groups of ``GROUP`` points per design, as many groups as there are such points.  A
    point solved before (``tried (D, nb)``) takes the new answer only where it is better
    (``stroke_point.score``: on the branch, then on another branch)."""
    d, nb = ctx.fail.shape
    left, right = _nearest(pts.status == Status.CONVERGED, ctx.n)
    size = d * nb
    group = min(size, GROUP * d)
    order = jnp.nonzero(todo.reshape(-1), size=size, fill_value=0)[0]
    count = jnp.sum(todo)
    u_all = jnp.broadcast_to(ctx.us, (d,) + ctx.us.shape[-2:]).reshape((size,) + ctx.us.shape[-1:])
    q_flat = pts.q.reshape((size, -1))
    design = jnp.repeat(jnp.arange(d), nb)
    flat = lambda x: x.reshape((size,) + x.shape[2:])  # noqa: E731

    def solve(k, pts_):
        idx = jax.lax.dynamic_slice_in_dim(order, k * group, group)
        live = k * group + jnp.arange(group) < count
        dsg = design[idx]
        l_i, r_i = flat(left)[idx], flat(right)[idx]
        q_l = where((l_i >= 0)[:, None], q_flat[dsg * nb + jnp.clip(l_i, 0, nb - 1)], ctx.g0[dsg])
        q_r = q_flat[dsg * nb + jnp.clip(r_i, 0, nb - 1)]
        p_ = jax.tree_util.tree_map(lambda x: x[dsg], setup.p)
        res: NewtonResult = jax.vmap(one)(u_all[idx], p_, setup.b0[dsg], q_l, q_r, r_i < nb, live)
        take = live & (~flat(tried)[idx] | (score(res.status) > score(flat(pts_.status)[idx])))
        put = lambda x, v: flat(x).at[jnp.where(take, idx, size)].set(v.astype(x.dtype), mode="drop").reshape(x.shape)  # noqa: E731
        return pts_._replace(**{f: put(getattr(pts_, f), getattr(res, f)) for f in ("q", "status", "steps", "residual", "cond", "branch")})

    return jax.lax.fori_loop(0, (count + group - 1) // group, solve, pts)


def two_sided(setup: StrokeSetup, ctx: Context, pts: PointResults, tried):
    """Every point still failed whose nearest converged neighbours are not the ones it was
    last ``tried`` from (``(D, nb, 2)``), solved on its own (``solve_points``) from the
    nearest converged pose before it and the nearest after it, each at the full and a
    tenth of the step cap: at most four Newton solves.  Returns ``(pts, tried)``."""
    mech, opts = setup.mech, setup.options
    nb = ctx.fail.shape[1]
    conv = pts.status == Status.CONVERGED
    ends = jnp.stack(_nearest(conv, ctx.n), axis=-1)
    todo = ctx.fail & ~conv & (jnp.arange(nb) < ctx.n) & jnp.any(ends != tried, axis=-1)
    caps = jnp.asarray([opts.max_step, 0.1 * opts.max_step] * 2, pts.q.dtype)

    def one(u_, p_, b_, q_l, q_r, has_r, live):
        starts = jnp.stack([q_l, q_l, q_r, q_r])
        return multistart(mech, opts, u_, p_, starts, caps, where(has_r, 4, 2), b_, True, skip=~live)[0]

    return solve_points(setup, ctx, pts, todo, one, tried[..., 0] > -2), where(todo[..., None], ends, tried).astype(tried.dtype)


def branch_probes(setup: StrokeSetup, ctx: Context, pts: PointResults, probed, tried):
    """A fresh assembly (``stroke_point.assemble``, from the nearest converged pose before
    the point) at every failed point where the loop closes only on another branch
    (``BRANCH``) not ``probed`` yet: an assemblable stretch the walk never reached, between
    two gaps.  Returns ``(pts, probed)``."""
    todo = ctx.fail & (pts.status == Status.BRANCH) & ~probed & (jnp.arange(ctx.fail.shape[1]) < ctx.n)

    def one(u_, p_, b_, q_l, q_r, has_r, live):
        return assemble(setup.mech, setup.options, u_, p_, q_l, q_l, b_, True, skip=~live)

    return solve_points(setup, ctx, pts, todo, one, tried), probed | todo


# --------------------------------------------------------------------------- rounds
class Round(NamedTuple):
    """The rounds' loop state: round `r`, the points `pts`, the neighbours each failed point
    was `tried` from (``(D, nb, 2)``), and the `BRANCH` points `probed` already."""

    r: jax.Array
    pts: PointResults
    tried: jax.Array
    probed: jax.Array


def repair(setup: StrokeSetup, us, pts: PointResults, valid, n, g0) -> PointResults:
    """The straight-line walk's points ``pts`` (``(D, nb, ...)``, derivatives included where
    ``setup.derivs``) with its failed points (``valid`` inputs, not ``CONVERGED``, within
    the first ``n``) solved again by rounds of this module's three stages.  The points the
    walk solved keep every value it gave (after its first failure, up to whole turns:
    ``unwrap``)."""
    d, nb = valid.shape
    fail = valid & (pts.status != Status.CONVERGED) & (jnp.arange(nb) < n)
    ctx = Context(us, fail, n, g0)
    walked = pts
    e = n - 1

    def round_(st: Round) -> Round:
        # the first round: a fresh assembly at each failed end of the stroke and fills
        # from there; later ones: every BRANCH point not probed yet
        at = jnp.broadcast_to(jnp.stack([jnp.zeros((), jnp.int32), e.astype(jnp.int32)]), (d, PROBES))
        want = jnp.stack([fail[:, 0], _gather(fail, at[:, 1:])[:, 0] & (e > 0)], axis=1) & (st.r == 0)
        pts, ok = probe(setup, ctx, st.pts, at, want)
        pts = fill(setup, ctx, pts, at, ok)
        pts, probed = branch_probes(setup, ctx, pts, st.probed | (st.r == 0), st.tried[..., 0] > -2)
        pts, tried = two_sided(setup, ctx, pts, st.tried)
        return Round(st.r + 1, pts, tried, where(st.r == 0, st.probed, probed))

    def more(st: Round):
        left = ctx.fail & (st.pts.status == Status.BRANCH) & ~st.probed
        return (st.r == 0) | ((st.r < ROUNDS) & jnp.any(left))

    init = Round(jnp.zeros((), jnp.int32), pts._replace(d1=None, d2=None), jnp.full((d, nb, 2), -2, jnp.arange(nb).dtype), jnp.zeros((d, nb), bool))
    # the walk's points after its first failure too: one it solved there from a stale
    # anchor (the pose before a gap) counts its turns from that anchor, not from the
    # stretch the repair found before it
    after = jnp.cumsum(fail, axis=1) > 0
    pts = unwrap(setup, ctx, jax.lax.while_loop(more, round_, init).pts, after)
    if not setup.derivs:
        return pts._replace(d1=walked.d1, d2=walked.d2)
    new = fail & (pts.status == Status.CONVERGED)
    d1, d2 = point_derivatives(setup.mech, setup.shared, where(new[..., None], pts.q, 0.0), us, setup.p, new)
    keep = lambda a, b: where(_expand(new, a), a, b)  # noqa: E731
    return pts._replace(d1=keep(d1, walked.d1), d2=keep(d2, walked.d2))
