"""One stroke point: the guarded predictor, the checked Newton step, and fresh assembly.

These act on one sample (one design, one input); ``stages`` maps them over a block
of points and designs, and ``continuation`` walks the blocks.  ``predict`` gives a point's
guess from the last anchor's root and implicit derivatives; ``checked_step`` takes one
plain Newton step from it and runs the kernel's tests; a point that fails them is solved
by ``assemble``: the Newton kernel (``newton.newton``) from several starts.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanism.branches import branch_value, has_branch, on_branch
from ..solver.linalg import cond1, inv_small, small_max, small_norm, solve_blocks, where
from ..mechanism.mechanism import Mechanism
from ..solver.newton import coord_scales, evaluator, newton, per_lane
from ..solver.solution import Solution
from ..solver.options import SolverOptions, tolerances
from ..solver.status import Status
from ..mechanism.structure import blocks
from ..solver.xla import unfused

__all__ = ["predict", "checked_step", "CheckedStep", "towards", "whole_turns", "multistart", "fresh_starts", "across_fold", "score", "STARTS", "CHECKED_STEPS", "FRESH_STEPS"]


# --------------------------------------------------------------------------- predictor
def series_terms(d1, d2, du):
    """``(q' du, q'' du du / 2)`` as elementwise products and sums over the (few) inputs: a
    ``dot`` under ``vmap`` is lowered by XLA according to the batch size, with a rounding
    that depends on it, and a stroke's result must not depend on its batch."""
    first = jnp.sum(d1 * du, axis=-1)
    second = 0.5 * jnp.sum(d2 * du[:, None] * du[None, :], axis=(-2, -1))
    return first, second


def trusted_terms(d1, d2, du, s, max_step):
    """``(d1, d2)`` with the terms the Taylor series cannot be trusted with over ``du`` zeroed.

    Near a singular position the series diverges (there ``q''`` is huge: a flap design
    that starts near a toggle had its second-order term predict 2000 rad, and Newton then
    converged to the same pose 319 turns away, where angle-dependent loads are wrong).  So
    the second-order term is kept only while it is under a quarter of the first-order one
    (scaled max norms: the series is then converging), and a step of more than ``max_step``
    (scaled, as Newton's) is not predicted at all: the anchor itself is the guess.
    """
    first, second = series_terms(d1, d2, du)
    size = lambda x: small_max(jnp.abs(x) / s)  # noqa: E731
    keep2 = size(second) <= 0.25 * size(first)
    step = where(keep2, first + second, first)
    keep1 = size(step) <= max_step
    return where(keep1, d1, 0.0), where(keep1 & keep2, d2, 0.0)


def predict(q, d1, d2, du, s, max_step):
    """Guarded second-order predictor ``q + q' du + q'' du du / 2`` from a solved anchor
    (``q (m,)``, ``d1 (m, dof)``, ``d2 (m, dof, dof)``), with the terms its series cannot be
    trusted with dropped (``trusted_terms``).  ``s``: coordinate scales
    (``newton.coord_scales``); ``max_step``: the largest scaled step predicted.

    ``du``: one input step ``(dof,)`` -> ``(m,)``, or the steps to a block of points
    ``(k, dof)`` -> ``(k, m)``: the series is then judged once, over the last (farthest)
    step, and the same terms serve every point (what a stroke's block does).
    """
    one = du.ndim == 1
    du = du.reshape((-1, du.shape[-1]))
    d1_t, d2_t = trusted_terms(d1, d2, du[-1], s, max_step)

    def point(du_):
        first, second = series_terms(d1_t, d2_t, du_)
        return q + first + second

    out = jax.vmap(point)(du)
    return out[0] if one else out


# --------------------------------------------------------------------------- one checked step
class CheckedStep(NamedTuple):
    """``checked_step``'s result for one sample.

    - `q_eval`: the iterate the tests are evaluated at, always finite.
    - `q`: ``q_eval`` plus the next Newton step where ``ok`` (the reported root).
    - `ok`: every test passed (converged, conditioned, finite, on the branch).
    - `residual`, `cond`, `branch`: at ``q_eval``, as the root record's (``newton``'s ``Solution``).
    - `steps`: Newton steps taken (int32).
    - `jac_guess`: the scaled Jacobian at the guess (what ``assemble`` reads the guess's
      assembly modes from, without evaluating it again).
    """

    q_eval: jax.Array
    q: jax.Array
    ok: jax.Array
    residual: jax.Array
    cond: jax.Array
    branch: jax.Array
    steps: jax.Array
    jac_guess: jax.Array


def lean_xtol(opts: SolverOptions, dtype):
    """Step test of ``checked_step``: the reported root is the last iterate plus a step ``dz``
    of at most ``1e4 eps`` (scaled), whose own error is of order ``|dz|^2`` (quadratic
    convergence): round-off, up to a condition number of ~1e3 (beyond which the robust
    kernel re-solves the point anyway).  The stroke's derivatives are taken at that root."""
    return min(tolerances(opts, dtype)[0], 1e4 * float(jnp.finfo(dtype).eps))


#: Most plain Newton steps ``checked_step`` takes from a predicted guess: one from a good
#: prediction; a coarse stroke's (a four-bar at 2 degrees a point: 1e-5 off) needs two to
#: pass the lean step test.
CHECKED_STEPS = 3
#: ... and from a pose without a series (a stroke's guess at its first point, the reverse
#: walk's start).  Every step is capped at ``max_step`` and its angles are moved by whole
#: turns to within half a turn of the guess (the convention of ``assemble``).
FRESH_STEPS = 6


class _StepCarry(NamedTuple):
    """``checked_step``'s loop state: steps taken `i`, the iterate `q`, its residual `r`
    and Jacobian `js`, the next (block-solved) step `dz`, whether `q` is finite."""

    i: jax.Array
    q: jax.Array
    r: jax.Array
    js: jax.Array
    dz: jax.Array
    finite: jax.Array


def checked_step(mech: Mechanism, opts: SolverOptions, u, p, guess, b0, most=CHECKED_STEPS) -> CheckedStep:
    """Plain Newton steps from a close (predicted) guess (one, or up to `most` (may be
    traced) while the next one is not yet within the lean step test; each capped at
    ``opts.max_step``, scaled), then the convergence, conditioning, finiteness and branch
    (``b0``: the requested signs) tests of ``newton.newton``: the common case of a stroke
    point; the points that fail it go to ``assemble``.  ``most=1`` (a Python int): one
    step in straight-line code, no loop (the robust stroke program's: a loop there cost 8%
    more compile for the scenes, and its fallback solves the rest)."""
    dtype = guess.dtype
    _, ftol, cond_max = tolerances(opts, dtype)
    xtol = lean_xtol(opts, dtype)
    evaluate, s = evaluator(mech, u, p, dtype)
    order = blocks(mech)  # block-triangular solves (structure.py)
    r, js = evaluate(guess)
    tiny = float(jnp.finfo(dtype).tiny)

    def more(c: _StepCarry):
        close = (small_max(jnp.abs(c.dz)) <= xtol) & (small_norm(c.r) <= ftol)
        return (c.i < most) & c.finite & ((c.i == 0) | ~close)

    one = isinstance(most, int) and most == 1

    def step(c: _StepCarry) -> _StepCarry:
        q_, dz_ = c.q, c.dz
        q_ = q_ - dz_ * jnp.minimum(1.0, opts.max_step / jnp.maximum(small_max(jnp.abs(dz_)), tiny)) * s
        if not one:  # angles within half a turn of the guess (as assemble's); the tests see it
            q_ = towards(mech, q_, guess)
        finite_ = jnp.all(jnp.isfinite(q_))
        q_ = where(finite_, q_, jnp.zeros_like(q_))
        r_, js_ = evaluate(q_)
        return _StepCarry(c.i + 1, q_, r_, js_, solve_blocks(js_, r_, order), finite_)

    init = _StepCarry(jnp.zeros((), jnp.int32), guess, r, js, solve_blocks(js, r, order), jnp.asarray(True))
    if one:  # straight-line code: the robust program's (it re-solves the rest)
        steps, q, r, js, dz, finite_q = step(init)
    else:
        steps, q, r, js, dz, finite_q = jax.lax.while_loop(more, step, per_lane(init, jnp.all(jnp.isfinite(guess))))
    rn = small_norm(r)
    cond = cond1(js, order)
    br = branch_value(mech, q, u, p, js)
    ok = (small_max(jnp.abs(dz)) <= xtol) & (rn <= ftol) & (cond <= cond_max)
    ok = ok & finite_q & jnp.all(jnp.isfinite(dz)) & on_branch(b0, br)
    qf = where(ok, q - dz * s, q)
    # ok feeds every output: computed once (finite here), it saves ~20% of this step on CPU
    packed = unfused(jnp.concatenate([qf, ok.astype(dtype)[None]]))
    return CheckedStep(q, packed[:-1], packed[-1] > 0.5, rn, cond, br, steps, init.js)


# --------------------------------------------------------------------------- fresh assembly
def towards(mech: Mechanism, q, guess):
    """``q`` with its angles moved by whole turns to within half a turn of ``guess``."""
    angle = ~jnp.asarray(mech.coord_is_length())
    return q - where(angle, 2 * jnp.pi * jnp.round((q - guess) / (2 * jnp.pi)), 0.0)


def whole_turns(mech: Mechanism, opts: SolverOptions, q, guess, u, p, ok, residual):
    """``towards(q, guess)`` where ``ok`` and the equations do not notice the turns (the
    scaled residual stays within ``max(ftol, 2 residual)``), else ``q``: a stroke's angles
    are continuous as numbers."""
    dtype = q.dtype
    q_w = towards(mech, q, guess)
    _, ftol, _ = tolerances(opts, dtype)
    r_w = mech.residual(q_w, u, p) / mech.residual_scales(p, dtype)
    return where(ok & (small_norm(r_w) <= jnp.maximum(ftol, 2 * residual)), q_w, q)


#: Starts of ``assemble`` besides the guess: fixed offsets from the reference pose, in
#: half-turns for angles and length scales for lengths (deterministic, so a stroke's result
#: does not depend on anything but its inputs).  14: with 6, 1 in ~20 random six-bars
#: crossing gaps left a stretch after a gap on the other branch of a loop; with 14, none of
#: 210 did (tried one after another only while a point is unresolved: the count costs
#: run time only where the guess fails, and no compile time).
STARTS = 14


def start_offsets(m: int) -> np.ndarray:
    """``(STARTS, m)`` fixed offsets in [-1, 1] (a seeded generator: deterministic)."""
    return np.random.default_rng(20261124).uniform(-1.0, 1.0, (STARTS, m))


def score(status):
    """How good an answer is: 2 a root on the branch, 1 one only on another, 0 none."""
    return where(status == Status.CONVERGED, 2, where(status == Status.BRANCH, 1, 0))


class _Starts(NamedTuple):
    """``multistart``'s loop state: the next start `j`, the `best` answer so far, its
    `score`, the start `j_best` it came from, whether the last start run `stalled`."""

    j: jax.Array
    best: Solution
    score: jax.Array
    j_best: jax.Array
    stalled: jax.Array


def multistart(mech: Mechanism, opts: SolverOptions, u, p, starts, caps, count, target, inputs_finite: bool = False,
               skip=None, after_stall=None, budget=None, fold=None) -> tuple[Solution, jax.Array]:
    """``newton.newton`` from ``starts[j]`` (``(S, m)``) with the step cap ``caps[j]``, for
    ``j = 0 .. count - 1`` (``count`` may be traced) one after another until a root on the
    requested branch (``target``) is found.  One call site of the kernel, in a
    ``while_loop``: under ``vmap`` a lane whose first start closes costs one Newton solve,
    and finished lanes skip the later starts.  The best answer is kept: a root on the
    branch, else one that exists only on another branch (``BRANCH`` says more than a
    stall), else the first start's own status; the earliest start wins a tie.  ``skip``
    (traced bool): no start is run (the lane's answer is not wanted).  ``after_stall``
    (``(S,)`` bools): start ``j`` is run only where start ``j - 1`` did not stall
    (``INFEASIBLE``: a least-squares minimum above tolerance, which a shorter step from the
    same pose reaches again).  ``fold`` (``(S,)`` bools, may be traced): start ``j`` is
    instead ``across_fold`` of the best root so far, run only where that root is on
    another branch.  ``budget``: each start's iterations (``newton.newton``'s).
    Returns ``(best root record (a Solution), index of its start)``."""
    dtype = starts.dtype
    last = starts.shape[0] - 1
    after = jnp.zeros((last + 1,), bool) if after_stall is None else jnp.asarray(after_stall)

    def wanted(c: _Starts):
        return (c.j < count) & (c.score < 2)

    def attempt(c: _Starts) -> _Starts:
        j, best, best_score = c.j, c.best, c.score
        k = jnp.clip(j, 0, last)
        run = wanted(c) & ~(after[k] & c.stalled)
        start = starts[k]
        if fold is not None:
            mirrored = fold[k]  # run only from a root on another branch
            run = run & (~mirrored | (best_score == 1))
            start = where(mirrored, across_fold(mech, best.q, u, p), start)
        res = newton(mech, opts, u, p, start, target, caps[k].astype(dtype), skip=~run, inputs_finite=inputs_finite, budget=budget)
        take = run & (score(res.status) > best_score)
        pick = lambda a, b: where(take, a, b)  # noqa: E731
        stalled = where(run, res.status == Status.INFEASIBLE, c.stalled)
        return _Starts(j + 1, jax.tree_util.tree_map(pick, res, best), pick(score(res.status), best_score), pick(k, c.j_best), stalled)

    zero = jnp.zeros((), dtype)
    branch0 = branch_value(mech, starts[0], u, p) if has_branch(mech) else jnp.asarray(jnp.nan, dtype)
    none = Solution(q=starts[0], status=jnp.asarray(Status.MAX_STEPS, jnp.int32), steps=jnp.zeros((), jnp.int32),
                    residual=zero, cond=zero, branch=branch0, flipped=jnp.zeros((), jnp.int32))
    first = jnp.asarray(-1) if skip is None else where(skip, 2, -1)
    init = _Starts(jnp.zeros((), jnp.int32), none, first, jnp.zeros((), jnp.int32), jnp.asarray(False))
    out = jax.lax.while_loop(wanted, attempt, per_lane(init, jnp.all(jnp.isfinite(starts[0]))))
    return out.best, out.j_best


def fresh_starts(mech: Mechanism, opts: SolverOptions, ref, p) -> tuple[jax.Array, jax.Array]:
    """``(starts (STARTS + 2, m), caps (STARTS + 2,))``: a fresh assembly's starts for
    ``multistart`` around the pose ``ref``: ``ref`` itself, ``ref`` with a tenth of the step
    cap (which keeps Newton on the near side of a fold, a toggle a stroke re-enters at,
    where full steps overshoot), then ``STARTS`` fixed offsets (half-turns for angles,
    length scales for lengths): the assembly a stroke needs at its first point and after a
    gap, where no pose near the last trusted one exists to continue from."""
    dtype = ref.dtype
    s = coord_scales(mech, p, dtype)
    angle = ~jnp.asarray(mech.coord_is_length())
    table = ref[None] + jnp.asarray(start_offsets(mech.m), dtype) * where(angle, jnp.pi, s)
    caps = np.full(STARTS + 2, opts.max_step)
    caps[1] = 0.1 * opts.max_step
    return jnp.concatenate([ref[None], ref[None], table]), jnp.asarray(caps, dtype)


#: Inverse iterations for the near-null vectors of a root's Jacobian (``across_fold``):
#: the error shrinks by ``sigma_min / sigma_2`` each, a small ratio at a toggle.
FOLD_ITERATIONS = 6


def across_fold(mech: Mechanism, q, u, p):
    """The other root across a fold from the root ``q`` (``(m,)``): where a loop is near a
    toggle, its two assembly modes are two roots ``q`` and ``q + t v`` on either side of
    the fold, ``v`` the Jacobian's near-null right vector.  On the quadratic model of the
    scaled residual along ``v``, projected on the near-null left vector ``w``
    (``w' Phi(q + t v) = sigma t + c t^2 / 2``, ``sigma = w' J v``, ``c = w' Phi''[v, v]``)
    the other root is ``t = -2 sigma / c``.  A start for the requested branch where Newton
    from every nearby pose lands on the other one (a stretch of stroke between two gaps,
    a point or two long, sits next to a toggle).  ``q`` itself where the model has no
    finite root.  No LAPACK: the vectors by inverse iteration on the block inverse."""
    dtype = q.dtype
    evaluate, s = evaluator(mech, u, p, dtype)
    _, js = evaluate(q)
    inv = inv_small(js, blocks(mech))
    start = jnp.asarray(1.0 + 0.1 * np.arange(mech.m), dtype)  # deterministic, not orthogonal to a null vector

    def iterate(_, vw):  # on J'J and JJ' (singular vectors, not J's eigenvectors)
        v_, w_ = inv @ (inv.T @ vw[0]), inv.T @ (inv @ vw[1])
        return v_ / small_norm(v_), w_ / small_norm(w_)

    v, w = jax.lax.fori_loop(0, FOLD_ITERATIONS, iterate, (start, start))
    R = mech.residual_scales(p, dtype)
    along = lambda t: mech.residual(q + t * v * s, u, p) / R  # noqa: E731
    curve = jax.jvp(lambda t: jax.jvp(along, (t,), (jnp.ones((), dtype),))[1], (jnp.zeros((), dtype),), (jnp.ones((), dtype),))[1]
    t = -2.0 * jnp.dot(w, js @ v) / jnp.dot(w, curve)
    other = q + t * v * s
    return where(jnp.all(jnp.isfinite(other)), other, q)
