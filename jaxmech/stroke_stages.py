"""The stages of a stroke's walk over its blocks, each a function of named state.

A stroke is cut into blocks of ``k`` points (``continuation``); one ``lax.scan`` step
(``walk_block``) solves one block for every design:

1. ``block_guesses``: each point's guess from the anchor (``StrokeCarry``) by the guarded
   predictor (``stroke_point.predict``);
2. ``checked_block``: checked Newton steps per point (``stroke_point.checked_step``: one
   in the robust program, up to ``CHECKED_STEPS`` or ``FRESH_STEPS`` in the straight-line
   one);
3. ``resolve_failures``: where any point failed, the robust kernel
   (``stroke_point.assemble``, several starts) re-solves the failed points, under one
   ``lax.cond`` per block;
4. ``block_derivatives``: every point's implicit derivatives (or the last point's), once,
   after the ``cond``: one copy of that program serves checked and re-solved points;
5. ``next_anchor``: the block's last point becomes the next anchor if it converged; a
   failed one never does (gap handling: the last trusted pose is kept, its derivatives
   dropped, so the points after a gap restart from that pose itself).

``track_walk`` records, along the forward walk, whether a design needs the reverse walk (a
failed point followed by a converged one) and its last converged pose, from which
``restart_walk`` starts the reverse walk (``continuation``).  Shapes: ``D`` designs,
``k`` points per block, ``m`` coordinates, ``dof`` inputs.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .implicit import input_derivatives
from .linalg import where
from .mechanism import Mechanism
from .options import SolverOptions
from .status import Status
from .stroke_point import CHECKED_STEPS, FRESH_STEPS, assemble, checked_step, predict

__all__ = [
    "StrokeSetup", "StrokeCarry", "WalkState", "PointResults", "BlockInput", "Derivatives",
    "block_guesses", "checked_block", "robust_block", "point_derivatives", "block_derivatives",
    "resolve_failures", "next_anchor", "track_walk", "restart_walk", "walk_block", "stroke_step",
]


@dataclasses.dataclass(frozen=True)
class StrokeSetup:
    """What every stage of one stroke program reads (closed over by the scan step).

    - `mech`, `options`, `derivs` (every point's derivatives wanted), `shared` (one stroke
      ``(N, dof)`` for every design, not ``(D, N, dof)``): static.
    - `p`: the designs' parameters, leaves ``(D,)``, finite (non-finite ones replaced).
    - `b0`: requested branch signs ``(D,)`` or ``(D, n_branches)``.
    - `scales`: coordinate scales ``(D, m)`` (``newton.coord_scales``).
    - `robust` (static): one checked step a point, and the points it did not accept
      re-solved by the robust kernel; without, up to ``CHECKED_STEPS`` (``FRESH_STEPS``
      from a guess) and the points those do not bring home stay failed (the straight-line
      program ``continuation`` tries first).
    """

    mech: Mechanism
    options: SolverOptions
    derivs: bool
    shared: bool
    p: dict
    b0: jax.Array
    scales: jax.Array
    robust: bool = True

    @property
    def ax(self):
        """The design axis of a block's inputs: None for a shared stroke."""
        return None if self.shared else 0


class WalkState(NamedTuple):
    """Along the forward walk, per design: a failed point seen (`failed`), a failed point
    followed by a converged one seen (`need`: the reverse walk is wanted), and the last
    converged pose (`q_last`, ``(D, m)``)."""

    failed: jax.Array
    need: jax.Array
    q_last: jax.Array


class StrokeCarry(NamedTuple):
    """The scan's state between blocks: the anchor (`q_anchor (D, m)`, its ``dq/du``
    `d1 (D, m, dof)` and ``d2q/du2`` `d2 (D, m, dof, dof)`, zero after a gap, and its input
    `u_anchor (D, dof)`) and the `walk`'s record."""

    q_anchor: jax.Array
    d1: jax.Array
    d2: jax.Array
    u_anchor: jax.Array
    walk: WalkState


class PointResults(NamedTuple):
    """Per point of a block, ``(D, k, ...)``: the root `q` (the last iterate where not
    converged), `status`, Newton `steps`, scaled `residual`, `cond`, `branch` value, and
    (with ``derivs``) ``dq/du`` `d1` and ``d2q/du2`` `d2` (None without)."""

    q: jax.Array
    status: jax.Array
    steps: jax.Array
    residual: jax.Array
    cond: jax.Array
    branch: jax.Array
    d1: jax.Array | None
    d2: jax.Array | None


class Derivatives(NamedTuple):
    """``dq/du`` `d1` and ``d2q/du2`` `d2` at every point of a block (None when not wanted)
    and at its last point (`end_d1`, `end_d2`: the next anchor's)."""

    d1: jax.Array | None
    d2: jax.Array | None
    end_d1: jax.Array
    end_d2: jax.Array


class BlockInput(NamedTuple):
    """One scan step's inputs: the block's inputs `u` (``([D,] k, dof)``), which of its
    entries are points of the stroke with finite inputs (`valid (D, k)`), whether it
    belongs to the reverse walk (`reverse`) and starts it (`restart`), and whether it starts
    a walk (`fresh`: its anchor has no series, so its checked steps may take
    ``FRESH_STEPS``)."""

    u: jax.Array
    valid: jax.Array
    reverse: jax.Array
    restart: jax.Array
    fresh: jax.Array


# --------------------------------------------------------------------------- mapping helpers
def per_block(setup: StrokeSetup, fn, u_blk, *args):
    """``fn(u, p, b0, *per-point args)`` over designs (outer) and the block's points
    (inner), ``(D, k, ...)`` in and out: what depends on the parameters alone is computed
    once per design (the checked step: 8% of the steady-state stroke, measured)."""
    inner = lambda u_d, p_, b_, *pts: jax.vmap(lambda u_, *pp: fn(u_, p_, b_, *pp))(u_d, *pts)  # noqa: E731
    return jax.vmap(inner, (setup.ax, 0, 0) + (0,) * len(args))(u_blk, setup.p, setup.b0, *args)


def per_point(setup: StrokeSetup, fn, u_blk, *args):
    """``per_block`` as one ``vmap`` over designs x points (the parameters repeated per
    point), for the robust kernel: JAX batches a ``while_loop`` (Newton's, ``assemble``'s)
    by re-tracing its body to a fixed point at every ``vmap`` level, and two nested levels
    were half the stroke's trace."""
    d = setup.b0.shape[0]
    kk, dof = u_blk.shape[-2:]
    flat = lambda x: x.reshape((d * kk,) + x.shape[2:])  # noqa: E731
    rep = lambda x: jnp.repeat(x, kk, axis=0)  # noqa: E731
    u_all = flat(jnp.broadcast_to(u_blk, (d, kk, dof)))
    out = jax.vmap(fn)(u_all, jax.tree_util.tree_map(rep, setup.p), rep(setup.b0), *map(flat, args))
    return jax.tree_util.tree_map(lambda x: x.reshape((d, kk) + x.shape[1:]), out)


# --------------------------------------------------------------------------- stages
def block_guesses(setup: StrokeSetup, carry: StrokeCarry, u_blk):
    """Each design's block of guesses ``(D, k, m)`` from its anchor by the guarded predictor
    (the series judged once per block, over its farthest point)."""
    max_step = setup.options.max_step
    one = lambda q_a, d1, d2, u_a, s, u_d: predict(q_a, d1, d2, u_d - u_a, s, max_step)  # noqa: E731
    return jax.vmap(one, (0, 0, 0, 0, 0, setup.ax))(carry.q_anchor, carry.d1, carry.d2, carry.u_anchor, setup.scales, u_blk)


def checked_block(setup: StrokeSetup, u_blk, guesses, fresh=False):
    """``stroke_point.checked_step`` for every point: a ``CheckedStep`` of ``(D, k, ...)``.
    The straight-line program takes up to ``CHECKED_STEPS`` Newton steps a point, or
    ``FRESH_STEPS`` in a block that starts a walk (``fresh``, may be traced); the robust
    program one (its fallback solves the points that need more)."""
    most = 1 if setup.robust else jnp.where(fresh, FRESH_STEPS, CHECKED_STEPS)
    step = lambda u, p_, b_, g_: checked_step(setup.mech, setup.options, u, p_, g_, b_, most)  # noqa: E731
    return per_block(setup, step, u_blk, guesses)


def robust_block(setup: StrokeSetup, u_blk, guesses, q_anchor, jac_guess):
    """``stroke_point.assemble`` for every point of a block (``q_anchor (D, m)``: the
    reference pose of its starts; ``jac_guess (D, k, m, m)``: the checked step's Jacobians
    at the guesses): a ``newton.NewtonResult`` of ``(D, k, ...)``."""
    one = lambda u, p_, b_, g_, ref, jg: assemble(setup.mech, setup.options, u, p_, g_, ref, b_, True, jg)  # noqa: E731
    return per_point(setup, one, u_blk, guesses, jnp.broadcast_to(q_anchor[:, None], guesses.shape), jac_guess)


# A nested jit: the straight-line and the robust program of a mechanism (same shapes)
# share its trace.
@functools.partial(jax.jit, static_argnums=(0, 1))
def point_derivatives(mech: Mechanism, shared: bool, q, u, p, ok):
    """``implicit.input_derivatives`` at ``q (D, k, m)``, ``u ([D,] k, dof)``: ``(d1, d2)``
    of ``(D, k, m, dof[, dof])``, zero where not ``ok``."""
    one = lambda q_, u_, p1, ok_: input_derivatives(mech, q_, u_, p1, ok_)  # noqa: E731
    return jax.vmap(jax.vmap(one, (0, 0, None, 0)), (0, None if shared else 0, 0, 0))(q, u, p, ok)


def block_derivatives(setup: StrokeSetup, q_eval, u_blk, good) -> Derivatives:
    """Every point's derivatives (None without ``derivs``) and the last point's (the next
    anchor's), at ``q_eval (D, k, m)`` where ``good`` (zero elsewhere)."""
    mech, shared = setup.mech, setup.shared
    if setup.derivs:  # every point's dq/du and d2q/du2 (the last one's also serve the next anchor)
        d1, d2 = point_derivatives(mech, shared, where(good[..., None], q_eval, 0.0), u_blk, setup.p, good)
        return Derivatives(d1, d2, d1[:, -1], d2[:, -1])
    e1, e2 = point_derivatives(mech, shared, where(good[:, -1:, None], q_eval[:, -1:], 0.0), u_blk[..., -1:, :], setup.p, good[:, -1:])
    return Derivatives(None, None, e1[:, 0], e2[:, 0])


def resolve_failures(setup: StrokeSetup, u_blk, guesses, q_anchor, jac_guess, points: PointResults) -> PointResults:
    """The points the checked step did not accept (``points``: its results, without
    derivatives), solved again by the robust kernel.  Accepted points keep every value the
    checked step gave, so a point's result never depends on which other designs share its
    block."""
    rob = robust_block(setup, u_blk, guesses, q_anchor, jac_guess)
    new = PointResults(rob.q, rob.status, rob.steps, rob.residual, rob.cond, rob.branch, None, None)
    keep = points.status == Status.CONVERGED

    def pick(x, y):
        return None if x is None else where(keep.reshape(keep.shape + (1,) * (x.ndim - keep.ndim)), x, y)

    return jax.tree_util.tree_map(pick, points, new, is_leaf=lambda x: x is None)


def next_anchor(carry: StrokeCarry, points: PointResults, ders: Derivatives, u_blk) -> StrokeCarry:
    """The anchor for the next block.  A failed block end is never an anchor: the last
    trusted pose is kept, and its derivatives dropped (``ders.end_*`` are zero where the
    point failed), so the next block restarts from that pose instead of a series
    extrapolated across the gap."""
    last_ok = points.status[:, -1] == Status.CONVERGED
    q_next = where(last_ok[:, None], points.q[:, -1], carry.q_anchor)
    u_next = where(last_ok[:, None], u_blk[..., -1, :], carry.u_anchor)
    return StrokeCarry(q_next, ders.end_d1, ders.end_d2, u_next, carry.walk)


def track_walk(walk: WalkState, points: PointResults, valid) -> WalkState:
    """``walk`` after a forward block: ``valid (D, k)`` marks the entries that are stroke
    points with finite inputs (the others say nothing about the stroke).  (Reductions and
    masks, no gathers: this runs in every block and the program stays small.)"""
    conv = valid & (points.status == Status.CONVERGED)
    fail = valid & ~conv
    k = conv.shape[1]
    any_conv, any_fail = jnp.any(conv, axis=1), jnp.any(fail, axis=1)
    last = k - 1 - jnp.argmax(conv[:, ::-1], axis=1)  # the last converged entry
    first_fail = jnp.argmax(fail, axis=1)
    need = walk.need | (any_conv & (walk.failed | (any_fail & (first_fail < last))))
    at_last = (jnp.arange(k)[None, :] == last[:, None])[..., None]
    q_conv = jnp.sum(where(at_last, points.q, 0.0), axis=1)
    return WalkState(walk.failed | any_fail, need, where(any_conv[:, None], q_conv, walk.q_last))


def restart_walk(carry: StrokeCarry, guess, u_first) -> StrokeCarry:
    """The reverse walk's first anchor: each design's last converged pose where it needs the
    walk (else its guess, ``(D, m)``), without derivatives, at ``u_first (D, dof)``."""
    q0 = where(carry.walk.need[:, None], carry.walk.q_last, guess)
    return StrokeCarry(q0, jnp.zeros_like(carry.d1), jnp.zeros_like(carry.d2), u_first, carry.walk)


def walk_block(setup: StrokeSetup, carry: StrokeCarry, xs: BlockInput):
    """One block for every design: guesses, checked steps, the robust kernel where any
    failed (one ``lax.cond``), the derivatives, the next anchor.  Returns
    ``(StrokeCarry, PointResults)``."""
    u_blk = xs.u
    g = block_guesses(setup, carry, u_blk)
    chk = checked_block(setup, u_blk, g, xs.fresh)
    status = where(chk.ok, Status.CONVERGED, Status.MAX_STEPS).astype(jnp.int32)
    points = PointResults(chk.q, status, chk.steps, chk.residual, chk.cond, chk.branch, None, None)
    if setup.robust:
        resolve = functools.partial(resolve_failures, setup, u_blk, g, carry.q_anchor, chk.jac_guess)
        points = jax.lax.cond(jnp.any(~chk.ok), resolve, lambda b: b, points)
    # Once, after the cond, at every reported root: one copy of the derivative program
    # serves both kinds of point (a copy in each branch was a third of the six-bar stroke's
    # compile time), and at the root itself, not one Newton step before it.
    ders = block_derivatives(setup, points.q, u_blk, points.status == Status.CONVERGED)
    points = points._replace(d1=ders.d1, d2=ders.d2)
    return next_anchor(carry, points, ders, u_blk), points


def empty_points(like: PointResults) -> PointResults:
    """Zeros shaped like ``like`` (a skipped block's output)."""
    return jax.tree_util.tree_map(jnp.zeros_like, like)


def stroke_step(setup: StrokeSetup, guess, u_first_reverse, empty: PointResults, carry: StrokeCarry, xs: BlockInput):
    """The scan step: a forward block (recorded by ``track_walk``), or a reverse one, run
    only while some design needs the reverse walk (``restart`` starts it from
    ``restart_walk(carry, guess, u_first_reverse)``); a skipped block outputs ``empty``."""
    carry = jax.tree_util.tree_map(lambda a, b: where(xs.restart, a, b), restart_walk(carry, guess, u_first_reverse), carry)
    active = ~xs.reverse | jnp.any(carry.walk.need)
    new, points = jax.lax.cond(active, functools.partial(walk_block, setup), lambda c, _: (c, empty), carry, xs)
    walk = track_walk(carry.walk, points, xs.valid)
    walk = jax.tree_util.tree_map(lambda a, b: where(xs.reverse, a, b), carry.walk, walk)
    return new._replace(walk=walk), points
