"""The robust half of a stroke: the points the straight-line walk did not solve, solved
again with bounded work, batched over every failed point of every design at once.

The straight-line walk (``stages.walk_block``) solves a stroke forward by checked
Newton steps from a predicted guess; a point those steps do not bring home stays failed,
and so do the points after it (the anchor stays at the last trusted pose, without its
series).  ``repair`` takes those failures in phases of one loop; every Newton solve of a
phase is one call of one kernel (``solve_points``: ``point.multistart`` over the
points to solve, gathered in groups of ``GROUP`` points per design, as many groups as there
are points), so no loop's trip count is set by one design for a whole batch, and the
program holds one copy of the Newton kernel:

1. **Fresh assemblies** (``FRESH``: from the nearest converged pose before the point, else
   the design's guess; the same pose with a tenth of the step cap; then
   ``point.STARTS`` fixed offsets around it), at each failed end of the stroke
   (point 0, the last point) and, later, at every point where the loop closes only on
   another branch (``BRANCH``: an assemblable stretch the walk never reached).
2. **Fill steps** (``CONTINUE``): the failed points next to a point the last phase
   converged, from a secant prediction along the stroke, one Newton solve of at most
   ``FILL_ITERATIONS`` each, step after step until no fill goes on.  This re-enters a gap
   from its far side, where the requested branch's poses are easy to reach (a stroke
   re-enters the assemblable range at a toggle, which the walk's side cannot cross).
3. **Two-sided solves** (``TWO_SIDED``): every point still failed whose nearest converged
   neighbours changed, from the nearest converged pose before it, and from the nearest
   after it where that is at most ``RIGHT_REACH`` points away, each at the full step cap
   and, where that one did not stall (``INFEASIBLE``), at a tenth of it.  A point they
   converge next to failed ones (a stretch between two gaps) starts fill steps again.

Every phase's starts end with one from across the fold next to a root the phase found only
on another branch (``point.across_fold``, run only then): a stretch a point or two
long between two gaps sits next to a loop's toggle, where Newton from every pose nearby can
land on the loop's other assembly mode.

A point solved before keeps the better answer (``point.score``).  At most
``ROUNDS`` two-sided phases run.  Angles stay continuous as numbers (``unwrap``): each
repaired pose is moved by whole turns, in stroke order, to within half a turn of the
converged pose before it (else of the guess), so a stretch re-entered after a gap starts
within half a turn of the last pose before the gap.
Every reported pose passed the kernel's tests on the requested branch.  Shapes: ``D``
designs, ``nb`` (bucketed) stroke points, the first ``n`` of them the stroke, ``m``
coordinates, ``dof`` inputs.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.linalg import where
from ..solver.solution import Solution
from ..solver.status import Status
from .point import STARTS, fresh_starts, multistart, score, whole_turns
from .stages import PointResults, StrokeSetup, point_derivatives

__all__ = ["repair", "failed_points", "GROUP"]

#: Points solved at once, per design of the batch: a design whose whole stroke failed
#: takes many groups, a batch with few failures one.  One: a fill step (most of the
#: repair's phases) has at most one point per design, so a wider group left half its lanes
#: idle under ``vmap`` (2 -> 1: the gapped four-bar sweep of ``benchmarks/gaps.py`` 0.36 ->
#: 0.27 s warm, the six-bar's 0.72 -> 0.76 s, within its noise; no status moved).
GROUP = 1
#: Two-sided phases at most (the first, and those after stretches found between gaps).
ROUNDS = 3
#: A two-sided solve starts from the converged pose after the point only where that pose is
#: at most this many points away.
RIGHT_REACH = 3
#: A failed point every this many points of a stroke is assembled afresh after its two-sided
#: solves fail (``repair``'s probes), so that a stretch between two gaps is found.
PROBE = 8
#: A fill step's Newton iterations at most: a continued guess that needs more is left to
#: the two-sided solves.
FILL_ITERATIONS = 8
#: The kinds of solve (``solve_points``'s `mode`).
FRESH, TWO_SIDED, CONTINUE = 0, 1, 2
_FIELDS = ("q", "status", "steps", "residual", "cond", "branch")


class Context(NamedTuple):
    """What the stages read: the stroke's inputs ``us`` (sanitised, ``(nb, dof)`` shared or
    ``(D, nb, dof)``), the failed points `fail` ``(D, nb)``, the stroke's length `n`
    (traced) and the guesses `g0` ``(D, m)``."""

    us: jax.Array
    fail: jax.Array
    n: jax.Array
    g0: jax.Array


def failed_points(points: PointResults, valid, n):
    """``(D, nb)``: the stroke points (the first ``n``) with finite inputs (``valid``) that
    are not ``CONVERGED``: what ``repair`` solves again."""
    return valid & (points.status != Status.CONVERGED) & (jnp.arange(valid.shape[1]) < n)


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
    return x.at[rows, jnp.where(mask, j, nb)].set(v.astype(x.dtype), mode="drop")


def _nearest(conv, n):
    """``(left, right)`` ``(D, nb)``: the nearest converged point at or before each point
    (-1: none) and at or after it within the stroke (``nb``: none)."""
    nb = conv.shape[1]
    i = jnp.arange(nb)
    left = jax.lax.cummax(where(conv, i, -1), axis=1)
    right = jax.lax.cummin(where(conv & (i < n), i, nb), axis=1, reverse=True)
    return left, right


# --------------------------------------------------------------------------- the solves
def solve_points(setup: StrokeSetup, ctx: Context, pts: PointResults, todo, mode, tried, guess, near) -> PointResults:
    """The points ``todo (D, nb)`` solved on their own by ``point.multistart``: a
    fresh assembly around the nearest converged pose before the point (else the guess)
    where ``mode`` is ``FRESH``, the two-sided starts where ``TWO_SIDED``, one start from
    ``guess (D, nb, m)`` where ``CONTINUE`` (the same `mode` for every point).  In groups of
    ``GROUP`` points per design, only as many groups as there are points.  A point solved
    before (``tried (D, nb)``) takes the new answer only where it is better
    (``point.score``).  ``near (D, nb, 2)``: ``_nearest`` of ``pts``'s converged
    points (the caller has it)."""
    mech, opts = setup.mech, setup.options
    d, nb = ctx.fail.shape
    m = pts.q.shape[-1]
    left, right = near[..., 0], near[..., 1]
    size = d * nb
    group = min(size, GROUP * d)
    order = jnp.nonzero(todo.reshape(-1), size=size, fill_value=0)[0]
    count = jnp.sum(todo)
    u_all = jnp.broadcast_to(ctx.us, (d,) + ctx.us.shape[-2:]).reshape((size,) + ctx.us.shape[-1:])
    flat = lambda x: x.reshape((size,) + x.shape[2:])  # noqa: E731
    q_flat, design = flat(pts.q), jnp.repeat(jnp.arange(d), nb)
    dtype = pts.q.dtype
    cap = jnp.asarray(opts.max_step, dtype)
    # the two-sided table: left, left at a tenth of the cap (after a left start that did not
    # stall), right, likewise, where the right is near; then, in every table, a start from
    # the other side of the fold next to a root on another branch (``across_fold``, run only
    # where one was found: a stretch between two gaps lies next to a toggle, where Newton
    # from every nearby pose can land on the other mode).  Padded to STARTS + 3 rows.
    pad = STARTS - 2
    two_caps = jnp.concatenate([jnp.stack([cap, 0.1 * cap, cap, 0.1 * cap, cap]), jnp.full((pad,), cap)])
    two_after = jnp.asarray([False, True, False, True, False] + [False] * pad)
    fresh_fold = jnp.asarray([False] * (STARTS + 2) + [True])

    fresh, cont = mode == FRESH, mode == CONTINUE

    def one(u_, p_, b_, q_l, q_r, has_r, g_, live):
        f_starts, f_caps = fresh_starts(mech, opts, q_l, p_)
        f_starts, f_caps = jnp.concatenate([f_starts, q_l[None]]), jnp.concatenate([f_caps, cap[None]])
        both = jnp.stack([where(cont, g_, q_l), q_l, q_r, q_r, q_l])
        left = jnp.stack([where(cont, g_, q_l), q_l, q_l, q_l, q_l])  # its third row the fold's
        t_starts = jnp.concatenate([where(has_r, both, left), jnp.broadcast_to(q_l, (pad, m))])
        t_fold = jnp.concatenate([where(has_r, jnp.asarray([False, False, False, False, True]), jnp.asarray([False, False, True, False, False])),
                                  jnp.zeros((pad,), bool)])  # fmt: skip
        starts = where(fresh, f_starts, t_starts)
        caps = where(fresh, f_caps, two_caps)
        after = two_after & ~fresh
        fold = where(fresh, fresh_fold, t_fold & ~cont)
        count_ = where(fresh, STARTS + 3, where(cont, 1, where(has_r, 5, 3)))
        budget = where(cont, FILL_ITERATIONS, opts.max_iterations)
        return multistart(mech, opts, u_, p_, starts, caps, count_, b_, True, skip=~live, after_stall=after, budget=budget, fold=fold)[0]

    def solve(k, pts_):
        idx = jax.lax.dynamic_slice_in_dim(order, k * group, group)
        live = k * group + jnp.arange(group) < count
        dsg = design[idx]
        l_i, r_i = flat(left)[idx], flat(right)[idx]
        q_l = where((l_i >= 0)[:, None], q_flat[dsg * nb + jnp.clip(l_i, 0, nb - 1)], ctx.g0[dsg])
        q_r = q_flat[dsg * nb + jnp.clip(r_i, 0, nb - 1)]
        p_ = jax.tree_util.tree_map(lambda x: x[dsg], setup.p)
        # the pose after a point serves where it is near (a stretch re-entered at a toggle);
        # deeper in a gap the start before the point says as much, at half the cost
        near_r = (r_i < nb) & (r_i - idx % nb <= RIGHT_REACH)
        res: Solution = jax.vmap(one)(u_all[idx], p_, setup.b0[dsg], q_l, q_r, near_r, flat(guess)[idx], live)
        take = live & (~flat(tried)[idx] | (score(res.status) > score(flat(pts_.status)[idx])))
        put = lambda x, v: flat(x).at[jnp.where(take, idx, size)].set(v.astype(x.dtype), mode="drop").reshape(x.shape)  # noqa: E731
        return pts_._replace(**{f: put(getattr(pts_, f), getattr(res, f)) for f in _FIELDS})

    return jax.lax.fori_loop(0, (count + group - 1) // group, solve, pts)


# --------------------------------------------------------------------------- fills
def _shift(x, k: int, fill):
    """``x (D, nb, ...)`` moved by ``k`` points along the stroke (``x[:, j - k]`` at ``j``)."""
    pad = jnp.full_like(x[:, : abs(k)], fill)
    return jnp.concatenate([pad, x[:, :-k]], axis=1) if k > 0 else jnp.concatenate([x[:, -k:], pad], axis=1)


def _secant(q1, q2, u0, u1, u2, have2, s, max_step):
    """A point's guess from its neighbours' roots along a fill (``q1`` at ``u1``, the nearer;
    ``q2`` at ``u2`` where ``have2``), ``(..., m)``: linear extrapolation, dropped where its
    step is larger than ``max_step`` (scaled, as Newton's)."""
    step_u = jnp.linalg.norm(u0 - u1, axis=-1)
    prev_u = jnp.linalg.norm(u1 - u2, axis=-1)
    ratio = jnp.clip(step_u / jnp.where(prev_u > 0, prev_u, 1.0), 0.0, 2.0)
    step = (q1 - q2) * ratio[..., None]
    keep = have2 & (prev_u > 0) & (jnp.max(jnp.abs(step) / s[..., None, :], axis=-1) <= max_step)
    return q1 + where(keep[..., None], step, 0.0)


def frontier(setup: StrokeSetup, ctx: Context, pts: PointResults, newly):
    """``(todo, guess)``: the failed points next to a point converged by the last phase
    (``newly (D, nb)``), and each one's guess continued from it (``_secant``, through the
    converged point beyond where there is one): one step of a fill."""
    conv = pts.status == Status.CONVERGED
    u = jnp.broadcast_to(ctx.us, ctx.fail.shape + ctx.us.shape[-1:])
    sides = []
    for k in (1, -1):  # from the point before (a forward fill), from the point after
        near = _shift(newly, k, False)
        guess = _secant(_shift(pts.q, k, 0.0), _shift(pts.q, 2 * k, 0.0), u, _shift(u, k, 0.0), _shift(u, 2 * k, 0.0),
                        _shift(conv, 2 * k, False), setup.scales, setup.options.max_step)  # fmt: skip
        sides.append((near, guess))
    (fwd, g_f), (bwd, g_b) = sides
    todo = ctx.fail & ~conv & (fwd | bwd)
    return todo, where(fwd[..., None], g_f, g_b)


# --------------------------------------------------------------------------- angles
def unwrap(setup: StrokeSetup, ctx: Context, pts: PointResults, moved) -> PointResults:
    """The points ``moved (D, nb)`` (those the repair solved, and any the walk solved after
    its first failure) moved by whole turns, in stroke order, to within half a turn of the
    converged point before each (else the guess), where the equations allow it: a stretch
    re-entered after a gap starts within half a turn of the last pose before the gap (what
    a walk gives), and no two neighbours differ by a turn."""
    mech, opts = setup.mech, setup.options
    ok = pts.status == Status.CONVERGED
    u_all = jnp.broadcast_to(ctx.us, ctx.fail.shape + ctx.us.shape[-1:])

    def one(q_, g_, u_, p_, ok_, r_):
        return whole_turns(mech, opts, q_, g_, u_, p_, ok_, r_)

    def step(prev, x):
        q, u, ok_, move, res = x
        q = where(move[:, None], jax.vmap(one)(q, prev, u, setup.p, move & ok_, res), q)
        return where(ok_[:, None], q, prev), q

    xs = tuple(jnp.moveaxis(a, 1, 0) for a in (pts.q, u_all, ok, moved & ok, pts.residual))
    _, q = jax.lax.scan(step, ctx.g0, xs)
    return pts._replace(q=jnp.moveaxis(q, 0, 1))


# --------------------------------------------------------------------------- phases
DONE = -1


class Phase(NamedTuple):
    """The repair's loop state: round `r`, the phase's `kind` (``FRESH``, ``CONTINUE``: a
    fill step, ``TWO_SIDED``, or ``DONE``), the points `pts`, the points the last phase
    converged (`newly`), the points a fill tried (`filled`), the converged neighbours each
    failed point was last solved two-sided from (`ends`, ``(D, nb, 2)``; -2: never), and the
    points assembled afresh (`fresh`)."""

    r: jax.Array
    kind: jax.Array
    pts: PointResults
    newly: jax.Array
    filled: jax.Array
    ends: jax.Array
    fresh: jax.Array


def repair(setup: StrokeSetup, us, pts: PointResults, valid, n, g0) -> PointResults:
    """The straight-line walk's points ``pts`` (``(D, nb, ...)``, derivatives included where
    ``setup.derivs``) with its failed points (``valid`` inputs, not ``CONVERGED``, within
    the first ``n``) solved again by this module's phases, one ``solve_points`` each.  The
    points the walk solved keep every value it gave (after its first failure, up to whole
    turns: ``unwrap``)."""
    d, nb = valid.shape
    i = jnp.arange(nb)
    fail = failed_points(pts, valid, n)
    ctx = Context(us, fail, n, g0)
    walked = pts
    ends_of_stroke = fail & ((i == 0) | (i == n - 1))[None, :]

    # probes: every PROBE-th point of the stroke, assembled afresh once its two-sided solves
    # failed (an island between two gaps, farther than RIGHT_REACH from any converged point,
    # is reached by no fill and its two-sided solves from across the gaps stall)
    probe = (i % PROBE == 0)[None, :]

    def waiting(st: Phase):
        tried_two = st.ends[..., 0] > -2
        return fail & ~st.fresh & ((st.pts.status == Status.BRANCH) | (probe & tried_two & (st.pts.status != Status.CONVERGED)))

    def body(st: Phase) -> Phase:
        conv = st.pts.status == Status.CONVERGED
        near = jnp.stack(_nearest(conv, n), axis=-1)
        solved = (st.ends[..., 0] > -2) | st.fresh
        step, guess = frontier(setup, ctx, st.pts, st.newly)
        todo_fresh = where(st.r == 0, ends_of_stroke, waiting(st))
        todo_two = fail & ~conv & jnp.any(near != st.ends, axis=-1)
        kind = st.kind
        todo = where(kind == FRESH, todo_fresh, where(kind == CONTINUE, step & ~st.filled, todo_two))
        # a fill writes only what it converges (a better answer than any failure)
        tried = where(kind == CONTINUE, True, solved)
        pts = solve_points(setup, ctx, st.pts, todo, kind, tried, guess, near)
        # a fresh phase after a two-sided one keeps that one's new points for the fills
        newly = (todo & (pts.status == Status.CONVERGED)) | ((kind == FRESH) & st.newly)
        filled = st.filled | (todo & (kind == CONTINUE))
        ends = where((todo & (kind == TWO_SIDED))[..., None], near, st.ends).astype(st.ends.dtype)
        fresh = st.fresh | (todo & (kind == FRESH))
        nxt = Phase(st.r, kind, pts, newly, filled, ends, fresh)
        more_fill = jnp.any(ctx.fail & (pts.status != Status.CONVERGED) & (_shift(newly, 1, False) | _shift(newly, -1, False)) & ~filled)
        again = (st.r + 1 < ROUNDS) & jnp.any(waiting(nxt))
        # a two-sided solve that converged a point next to failed ones (a stretch between
        # gaps) starts a fill too, while rounds are left
        # the probes first: fills from the two-sided solves' points go on after them (with
        # the fills first, a stroke whose every round starts fills never ran its probes)
        after_two = where(again, FRESH, where(more_fill & (st.r + 1 < ROUNDS), CONTINUE, DONE))
        kind_next = where(kind == TWO_SIDED, after_two, where(more_fill, CONTINUE, TWO_SIDED))
        return nxt._replace(r=st.r + (kind == TWO_SIDED).astype(st.r.dtype), kind=kind_next.astype(st.kind.dtype))

    no = jnp.zeros((d, nb), bool)
    init = Phase(jnp.zeros((), jnp.int32), jnp.asarray(FRESH, jnp.int32), pts._replace(d1=None, d2=None), no, no,
                 jnp.full((d, nb, 2), -2, i.dtype), no)  # fmt: skip
    done = jax.lax.while_loop(lambda st: st.kind != DONE, body, init)
    # the walk's points after its first failure too: one it solved there from a stale
    # anchor (the pose before a gap) counts its turns from that anchor
    after = jnp.cumsum(fail, axis=1) > 0
    pts = unwrap(setup, ctx, done.pts, after)
    if not setup.derivs:
        return pts._replace(d1=walked.d1, d2=walked.d2)
    new = fail & (pts.status == Status.CONVERGED)
    d1, d2 = point_derivatives(setup.mech, setup.shared, where(new[..., None], pts.q, 0.0), us, setup.p, new)
    keep = lambda a, b: where(_expand(new, a), a, b)  # noqa: E731
    return pts._replace(d1=keep(d1, walked.d1), d2=keep(d2, walked.d2))
