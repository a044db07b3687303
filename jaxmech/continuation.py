"""Strokes by continuation: anchors, a guarded predictor, gaps, and stroke kinematics.

A stroke ``us (N, dof)`` is cut into blocks of ``k`` consecutive points.  A ``lax.scan``
walks the blocks in order; the last point of each solved block is the *anchor* of the
next: its root ``q`` and the implicit derivatives ``dq/du``, ``d2q/du2`` there give every
point of the next block a second-order predicted guess, and the one Newton kernel
(``newton.newton``) solves the whole block at once (vectorised over its points and over
the designs).  So one compiled kernel serves anchors and points alike, and a block whose
guesses are good (a smooth stroke) takes one Newton step per point.

Gaps (stretches where the mechanism cannot be assembled): an anchor that failed is never
used.  The last trusted anchor is kept, and once a block ends in failure its derivatives
are dropped, so the points after a gap restart from the last trusted pose itself (damped
Newton, branch guard) instead of a Taylor series extrapolated across the gap.

Compiled shapes are bucketed: a stroke is padded (repeating its last input) to the next of
a few sizes per octave, so 361 and 362 points share one compiled program.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from .linalg import cond1, small_max, small_norm, solve_blocks, where
from .xla import jit, unfused
from .mechanism import Mechanism
from .structure import blocks
from .implicit import attach_derivatives, implicit_root, root_derivatives
from .inputs import batch_shape, prepare
from .branches import branch_names, branch_value, flipped_mask, has_branch, on_branch
from .newton import coord_scales, evaluator, newton, per_lane
from .options import SolverOptions, tolerances
from .solution import Solution, raise_if_failed
from .status import Status

__all__ = ["solve_stroke", "stroke", "predict", "bucket", "assemble", "checked_step"]


# --------------------------------------------------------------------------- predictor
def _series_terms(d1, d2, du):
    """``(q' du, q'' du du / 2)`` as elementwise products and sums over the (few) inputs: a
    ``dot`` under ``vmap`` is lowered by XLA according to the batch size, with a rounding
    that depends on it, and a stroke's result must not depend on its batch."""
    first = jnp.sum(d1 * du, axis=-1)
    second = 0.5 * jnp.sum(d2 * du[:, None] * du[None, :], axis=(-2, -1))
    return first, second


def _trusted_terms(d1, d2, du, s, max_step):
    """``(d1, d2)`` with the terms the Taylor series cannot be trusted with over ``du`` zeroed.

    Near a singular position the series diverges (there ``q''`` is huge: a flap design
    that starts near a toggle had its second-order term predict 2000 rad, and Newton then
    converged to the same pose 319 turns away, where angle-dependent loads are wrong).  So
    the second-order term is kept only while it is under a quarter of the first-order one
    (scaled max norms: the series is then converging), and a step of more than ``max_step``
    (scaled, as Newton's) is not predicted at all: the anchor itself is the guess.
    """
    first, second = _series_terms(d1, d2, du)
    size = lambda x: small_max(jnp.abs(x) / s)  # noqa: E731
    keep2 = size(second) <= 0.25 * size(first)
    step = where(keep2, first + second, first)
    keep1 = size(step) <= max_step
    return where(keep1, d1, 0.0), where(keep1 & keep2, d2, 0.0)


def predict(q, d1, d2, du, s, max_step):
    """Guarded second-order predictor ``q + q' du + q'' du du / 2`` from a solved anchor
    (``q (m,)``, ``d1 (m, dof)``, ``d2 (m, dof, dof)``) over ``du (dof,)``, with the terms
    its series cannot be trusted with dropped.  ``s``: coordinate scales (``newton.coord_scales``)."""
    d1, d2 = _trusted_terms(d1, d2, du, s, max_step)
    first, second = _series_terms(d1, d2, du)
    return q + first + second


# --------------------------------------------------------------------------- one checked step
def _lean_xtol(opts: SolverOptions, dtype):
    """Step test of ``checked_step``.  Derivatives are taken at its iterate, one Newton step
    ``dz`` from the reported root, and they move by ``|dz|`` times the curvature;
    ``dz <= 1e4 eps`` keeps that below 1e-9 relative up to a condition number of ~1e3
    (beyond which the robust kernel re-solves the point anyway)."""
    return min(tolerances(opts, dtype)[0], 1e4 * float(jnp.finfo(dtype).eps))


def checked_step(mech: Mechanism, opts: SolverOptions, u, p, guess, b0):
    """One plain Newton step from a close (predicted) guess, then the convergence,
    conditioning, finiteness and branch tests of ``newton.newton``: straight-line code for
    the common case of a stroke point; the points that fail it go to ``newton.newton``.

    Returns ``(q1, q, ok, residual, cond, branch)``: ``q1`` is the iterate the tests (and the
    derivatives) are evaluated at, always finite; ``q = q1 - dz`` adds the next step.
    """
    dtype = guess.dtype
    _, ftol, cond_max = tolerances(opts, dtype)
    evaluate, s = evaluator(mech, u, p, dtype)
    r, js = evaluate(guess)
    order = blocks(mech)  # block-triangular solves (structure.py)
    q = guess - solve_blocks(js, r, order) * s
    finite_q = jnp.all(jnp.isfinite(q))
    q = where(finite_q, q, jnp.zeros_like(q))
    r, js = evaluate(q)
    dz = solve_blocks(js, r, order)
    rn = small_norm(r)
    cond = cond1(js, order)
    br = branch_value(mech, q, u, p, js)
    ok = (small_max(jnp.abs(dz)) <= _lean_xtol(opts, dtype)) & (rn <= ftol) & (cond <= cond_max)
    ok = ok & finite_q & jnp.all(jnp.isfinite(dz)) & on_branch(b0, br)
    qf = where(ok, q - dz * s, q)
    # ok feeds every output: computed once (finite here), it saves ~20% of this step on CPU
    packed = unfused(jnp.concatenate([qf, ok.astype(dtype)[None]]))
    return q, packed[:-1], packed[-1] > 0.5, rn, cond, br


# --------------------------------------------------------------------------- restarts
#: Starts of ``assemble`` besides the guess: fixed offsets from the reference pose, in
#: half-turns for angles and length scales for lengths (deterministic, so a stroke's result
#: does not depend on anything but its inputs).  14: with 6, 1 in ~20 random six-bars
#: crossing gaps left a stretch after a gap on the other branch of a loop; with 14, none of
#: 210 did (tried one after another only while a point is unresolved: the count costs
#: run time only where the guess fails, and no compile time).
_STARTS = 14


def _offsets(m: int) -> np.ndarray:
    return np.random.default_rng(20261124).uniform(-1.0, 1.0, (_STARTS, m))


def assemble(mech: Mechanism, opts: SolverOptions, u, p, guess, ref, target, inputs_finite: bool = False):
    """A pose on the requested branch (``target``: signs of the branch indicator) at ``u``,
    from a guess and a reference pose ``ref`` (the last trusted pose of a stroke).

    ``newton.newton`` runs from one start after another until a root on the branch is
    found: the guess (the anchor itself where the predicted guess is off the branch), the
    guess again with a tenth of the step cap (which keeps Newton on the near side of a fold,
    a toggle the stroke re-enters at, where full steps overshoot), then ``_STARTS`` fixed
    offsets around ``ref``: the fresh assembly a stroke needs after a gap, where no pose
    near the last trusted one exists to continue from.  One call site of the kernel, in a
    ``while_loop``: under ``vmap`` a block whose points all close from their guesses costs
    one Newton solve, as without restarts, and finished lanes skip the later starts.  The
    best answer is kept: a root on the branch, else one that exists only on another branch
    (``BRANCH`` says more than a stall), else the guess's own status; the earliest start
    wins a tie.  Angles are then moved by whole turns to lie within half a turn of the
    guess (where the equations allow it: checked on the residual), so a stroke's angles are
    continuous as numbers.

    ``inputs_finite``: as for ``newton`` (the stroke program sanitises its inputs once).

    Returns ``(q, status, steps, residual, cond, branch)`` like ``newton`` (no ``flipped``).
    """
    dtype = guess.dtype
    s = coord_scales(mech, p, dtype)
    angle = ~jnp.asarray(mech.coord_is_length())
    g0 = where(on_branch(target, branch_value(mech, guess, u, p)), guess, ref) if has_branch(mech) else guess
    table = ref[None] + jnp.asarray(_offsets(mech.m), dtype) * where(angle, jnp.pi, s)
    last = _STARTS + 2
    score = lambda st: where(st == Status.CONVERGED, 2, where(st == Status.BRANCH, 1, 0))  # noqa: E731

    def wanted(carry):
        j, best = carry
        return (j < last) & (best[-1] < 2)

    def attempt(carry):
        j, best = carry
        g = where(j < 2, g0, table[jnp.clip(j - 2, 0, _STARTS - 1)])
        cap = where(j == 1, 0.1 * opts.max_step, opts.max_step).astype(dtype)
        q, st, steps, rn, cond, br, _ = newton(mech, opts, u, p, g, target, cap, skip=~wanted(carry), inputs_finite=inputs_finite)
        new = (q, st.astype(jnp.int32), steps.astype(jnp.int32), rn, cond, br, score(st))
        take = wanted(carry) & (new[-1] > best[-1])
        return j + 1, jax.tree_util.tree_map(lambda a, b: where(take, a, b), new, best)

    zero = jnp.zeros((), dtype)
    none = (guess, jnp.asarray(Status.MAX_STEPS, jnp.int32), jnp.zeros((), jnp.int32), zero, zero, branch_value(mech, guess, u, p), jnp.asarray(-1))
    init = per_lane((jnp.zeros((), jnp.int32), none), jnp.all(jnp.isfinite(guess)))
    _, (q, st, steps, rn, cond, br, _) = jax.lax.while_loop(wanted, attempt, init)
    # Whole turns towards the guess, kept only if the equations do not notice them.
    turns = where(angle, jnp.round((q - guess) / (2 * jnp.pi)), 0.0)
    q_w = q - 2 * jnp.pi * turns
    _, ftol, _ = tolerances(opts, dtype)
    r_w = mech.residual(q_w, u, p) / mech.residual_scales(p, dtype)
    q = where((st == Status.CONVERGED) & (small_norm(r_w) <= jnp.maximum(ftol, 2 * rn)), q_w, q)
    return q, st, steps, rn, cond, br


# --------------------------------------------------------------------------- shapes
def bucket(n: int) -> int:
    """The compiled size for ``n`` stroke points: ``n`` rounded up to a multiple of a power
    of two with five significant bits (at most 1/16 = 6% padding)."""
    e = max(0, int(n).bit_length() - 5)
    return -(-int(n) // (1 << e)) << e


def _block_size(n: int, anchors: int) -> int:
    """Stroke points per block for ``n`` points and (at most about) ``anchors`` anchors."""
    return max(1, -(-(n - 1) // max(1, anchors)))


# --------------------------------------------------------------------------- the stroke program
@functools.partial(jit, static_argnums=(0, 1, 2, 3), stored=True)  # a new process loads it (jaxmech.stored)
def _stroke_program(mech, options, derivs, single, us, p, guess):
    """Strokes of D designs: ``us (N, dof)`` shared or ``(D, N, dof)`` one per design
    (bucketed), ``p`` leaves ``(D,)``, ``guess (D, m)``.

    Returns ``(q, status, steps, residual, cond, branch, flipped, d1, d2)`` with ``(D, N)`` in front
    (the design axis dropped with ``single``); ``d1``, ``d2`` are None without ``derivs``.
    NaN where the status is not ``CONVERGED``.
    """
    stop = jax.lax.stop_gradient
    m = mech.m
    d = guess.shape[0]
    dtype = guess.dtype
    n, dof = us.shape[-2:]
    # A stroke shared by every design stays one array: a block's inputs are then not batched
    # over the designs, which keeps the steady-state program as small as it was (a shared
    # stroke broadcast per design cost 8-70% of the run time, measured).
    shared = us.ndim == 2
    ax = None if shared else 0  # the design axis of a block's inputs
    # Non-finite inputs and parameters are replaced once, here, by harmless values (their
    # samples are flagged): no derivative code ever sees a NaN that could leak into a batch
    # gradient.
    us_fin = jnp.all(jnp.isfinite(us), axis=-1)  # (N,) or (D, N)
    us_s = where(jnp.isfinite(us), us, 0.0)
    # The parameters as one (n_params, D) array: one reduction says which designs are finite.
    # Tested one by one, XLA's CPU fusion copied the chain of tests into every consumer of
    # the status (flap_msd, 29 parameters: 1,000 is-finite instructions in the program).
    pv = jnp.stack(list(p.values())) if p else jnp.zeros((0, d), dtype)
    p_fin = jnp.all(jnp.isfinite(pv), axis=0)
    p_s = dict(zip(p, unfused(where(jnp.isfinite(pv), pv, 1.0)))) if p else {}
    ps = jax.tree_util.tree_map(stop, p_s)
    g0 = stop(where(jnp.isfinite(guess), guess, 0.0))

    # Blocks: block 0 is the first input repeated (its last point is the first anchor, solved
    # from the user's guess); blocks 1.. cover points 1..n-1, the last padded by repetition.
    k = _block_size(n, options.anchors)
    nblk = -(-(n - 1) // k) if n > 1 else 0
    lead = us_s.shape[:-2]  # () or (D,)
    rest = jnp.concatenate([us_s[..., 1:, :], jnp.broadcast_to(us_s[..., -1:, :], lead + (nblk * k - (n - 1), dof))], axis=-2) if n > 1 else us_s[..., :0, :]
    blocks = jnp.concatenate([jnp.broadcast_to(us_s[..., :1, :], lead + (k, dof)), rest], axis=-2)
    blocks = jnp.moveaxis(blocks.reshape(lead + (nblk + 1, k, dof)), -3, 0)  # (nblk + 1, [D,] k, dof)
    u_first = jnp.broadcast_to(us_s[..., 0, :], (d, dof))

    if has_branch(mech):
        b0 = jnp.sign(jax.vmap(lambda g_, u_, p_: branch_value(mech, g_, u_, p_))(g0, u_first, ps))
    else:
        b0 = jnp.zeros((d,), dtype)
    scales = jax.vmap(lambda p_: coord_scales(mech, p_, dtype))(ps)

    def guesses(q_a, d1_a, d2_a, u_a, b_, p_, s_, u_blk):
        """One design's block of guesses ``(k, m)`` from its anchor's guarded predictor; the
        series is checked once, over the block's farthest point (its last)."""
        d1_t, d2_t = _trusted_terms(d1_a, d2_a, u_blk[-1] - u_a, s_, options.max_step)

        def one(u):
            first, second = _series_terms(d1_t, d2_t, u - u_a)
            return q_a + first + second

        return jax.vmap(one)(u_blk)

    def per_block(fn, u_blk, *args):
        """``fn(u, p, b0, *per-point args)`` over designs (outer) and the block's points
        (inner), ``(D, k, ...)`` in and out: what depends on the parameters alone is computed
        once per design (the checked step: 8% of the steady-state stroke, measured)."""
        return jax.vmap(lambda u_d, p_, b_, *pts: jax.vmap(lambda u_, *pp: fn(u_, p_, b_, *pp))(u_d, *pts), (ax, 0, 0) + (0,) * len(args))(u_blk, ps, b0, *args)

    def per_point(fn, u_blk, *args):
        """``per_block`` as one ``vmap`` over designs x points (the parameters repeated per
        point), for the robust kernel: JAX batches a ``while_loop`` (Newton's, ``assemble``'s)
        by re-tracing its body to a fixed point at every ``vmap`` level, and two nested levels
        were half the stroke's trace."""
        kk = u_blk.shape[-2]
        flat = lambda x: x.reshape((d * kk,) + x.shape[2:])  # noqa: E731
        rep = lambda x: jnp.repeat(x, kk, axis=0)  # noqa: E731
        out = jax.vmap(fn)(flat(jnp.broadcast_to(u_blk, (d, kk, dof))), jax.tree_util.tree_map(rep, ps), rep(b0), *map(flat, args))
        return jax.tree_util.tree_map(lambda x: x.reshape((d, kk) + x.shape[1:]), out)

    def robust(u_blk, g, q_a):
        """The full Newton kernel for every point of a block (run only for a block where the
        checked step failed somewhere: one ``lax.cond`` per block), from several starts."""

        def one(u, p_, b_, g_, q_a):
            q, st, steps, rn, cond, br = assemble(mech, options, u, p_, g_, q_a, b_, inputs_finite=True)
            return q, st.astype(jnp.int32), steps.astype(jnp.int32), rn, cond, br

        return per_point(one, u_blk, g, jnp.broadcast_to(q_a[:, None], g.shape))

    # A nested jit: the checked step's and the fallback's calls (same shapes) share one trace.
    @jax.jit
    def derivatives_of(q, u, p_, ok):
        return jax.vmap(jax.vmap(lambda q_, u_, p1, ok_: root_derivatives(mech, q_, u_, p1, ok_), (0, 0, None, 0)), (0, ax, 0, 0))(q, u, p_, ok)

    def derivatives(q, u, ok):
        return derivatives_of(q, u, ps, ok)

    def scan_fn(carry, u_blk):
        q_a, d1_a, d2_a, u_a = carry
        g = jax.vmap(guesses, (0, 0, 0, 0, 0, 0, 0, ax))(q_a, d1_a, d2_a, u_a, b0, ps, scales, u_blk)
        q1, qf, ok, rn, cond, br = per_block(lambda u, p_, b_, g_: checked_step(mech, options, u, p_, g_, b_), u_blk, g)
        status = where(ok, Status.CONVERGED, Status.MAX_STEPS).astype(jnp.int32)

        def with_derivatives(q_eval, good):
            if derivs:  # every point's dq/du and d2q/du2 (the last one's also serve the next anchor)
                d1, d2 = derivatives(where(good[..., None], q_eval, 0.0), u_blk, good)
                return d1, d2, d1[:, -1], d2[:, -1]
            e1, e2 = derivatives(where(good[:, -1:, None], q_eval[:, -1:], 0.0), u_blk[..., -1:, :], good[:, -1:])
            return None, None, e1[:, 0], e2[:, 0]

        # derivatives at the checked step's iterate share its sines and cosines
        fields = (qf, status, jnp.ones(ok.shape, jnp.int32), rn, cond, br) + with_derivatives(q1, ok)

        def fallback(fields):
            # Points the checked step accepted keep every value it gave (so a point's result
            # never depends on which other designs share its block); the rest take the
            # robust kernel's root, with derivatives there.
            q_r, *rest = robust(u_blk, g, q_a)
            st_r = rest[0]
            new = (q_r, *rest) + with_derivatives(q_r, st_r == Status.CONVERGED)
            keep = fields[1] == Status.CONVERGED

            def pick(a_, b_, k_):
                return None if a_ is None else where(k_.reshape(k_.shape + (1,) * (a_.ndim - k_.ndim)), a_, b_)

            # every field is per point but the last two (the next anchor's derivatives)
            masks = (keep,) * (len(fields) - 2) + (keep[:, -1],) * 2
            return tuple(pick(a_, b_, k_) for a_, b_, k_ in zip(fields, new, masks))

        qf, status, steps, rn, cond, br, d1, d2, e1, e2 = jax.lax.cond(jnp.any(~ok), fallback, lambda f: f, fields)
        # A failed block end is never an anchor: keep the last trusted pose, and drop its
        # derivatives (root_derivatives gives zeros where the point failed), so the next
        # block restarts from that pose instead of a series extrapolated across the gap.
        last_ok = status[:, -1] == Status.CONVERGED
        q_next = where(last_ok[:, None], qf[:, -1], q_a)
        u_next = where(last_ok[:, None], u_blk[..., -1, :], u_a)
        return (q_next, e1, e2, u_next), (qf, status, steps, rn, cond, br, d1, d2)

    init = (g0, jnp.zeros((d, m, dof), dtype), jnp.zeros((d, m, dof, dof), dtype), u_first)
    _, out = jax.lax.scan(scan_fn, init, blocks)
    # (nblk + 1, D, k, ...) -> (D, n, ...): point 0 is block 0's last entry
    out = jax.tree_util.tree_map(lambda x: jnp.moveaxis(x, 0, 1).reshape((d, (nblk + 1) * k) + x.shape[3:])[:, k - 1 : k - 1 + n], out)
    q, status, steps, rn, cond, br, d1, d2 = out
    inputs_ok = p_fin[:, None] & us_fin[..., :n] & jnp.all(jnp.isfinite(guess), axis=-1)[:, None]
    status = where(inputs_ok, status, Status.NONFINITE).astype(jnp.int32)
    flipped = jax.vmap(jax.vmap(flipped_mask, (None, 0)))(b0, br) if has_branch(mech) else jnp.zeros(status.shape, jnp.int32)
    flipped = where(status == Status.BRANCH, flipped, 0)
    ok = status == Status.CONVERGED
    q_star = where(ok[..., None], q, jnp.nan)

    # Attach the roots to (u, p): derivatives by the implicit function theorem.
    u_out = us_s[..., :n, :]
    q = jax.vmap(jax.vmap(lambda q_, ok_, u_, p_: implicit_root(mech, q_, ok_, u_, p_), (0, 0, 0, None)), (0, 0, ax, 0))(q_star, ok, u_out, p)
    if derivs:
        d1 = where(ok[..., None, None], d1, jnp.nan)
        d2 = where(ok[..., None, None, None], d2, jnp.nan)
        d1, d2 = jax.vmap(jax.vmap(lambda *a: attach_derivatives(mech, *a), (0, 0, 0, 0, 0, None)), (0, 0, 0, 0, ax, 0))(d1, d2, q_star, ok, u_out, p)
    res = (q, status, steps, rn, cond, br, flipped, d1, d2)
    return jax.tree_util.tree_map(lambda x: x[0], res) if single else res


def _backward(mech, options, derivs, single, us, p, guess, out, n):
    """Points that failed after a gap, solved again by continuation from the other side.

    A stroke that re-enters the assemblable range does so at a toggle, where the requested
    branch's poses exist but are hard to reach from the last pose before the gap (Newton's
    steps there run across the fold to the other branch).  The same poses are easy to reach
    from the well-conditioned stretch after them: so where a design has a failed point
    followed by a converged one, the stroke is walked once more in reverse, from that
    design's last converged pose, by the same compiled program (same shapes), and the
    points it solves on the requested branch that the forward pass did not take its answer.
    Concrete arguments only (the decision is made on the host); inside a user's trace the
    forward pass stands, and its failures keep their statuses.
    """
    nb = us.shape[-2]  # the bucketed stroke length
    status = np.asarray(out[1]).reshape(-1, nb)[:, :n]
    conv = status == Status.CONVERGED
    # a failed point with a converged one after it
    later = np.flip(np.logical_or.accumulate(np.flip(conv, 1), 1), 1)
    need = np.any(~conv[:, :-1] & later[:, 1:], axis=1)
    if not np.any(need):
        return out
    last = n - 1 - np.argmax(np.flip(conv, 1), axis=1)
    q = np.asarray(out[0]).reshape(-1, nb, mech.m)
    start = np.where(need[:, None], q[np.arange(q.shape[0]), last], np.asarray(guess))
    order = np.concatenate([np.arange(n - 1, -1, -1), np.zeros(nb - n, int)])
    back = _stroke_program(mech, options, derivs, single, jax.device_put(np.take(np.asarray(us), order, axis=-2)), p, jax.device_put(start.reshape(np.shape(guess))))
    axis = 0 if single else 1
    undo = np.concatenate([np.arange(n - 1, -1, -1), np.arange(n, nb)])  # reversed index of each point
    status_b = np.asarray(back[1]).reshape(-1, nb)[:, undo][:, :n]
    take = need[:, None] & ~conv & (status_b == Status.CONVERGED)
    take = np.concatenate([take, np.zeros((take.shape[0], nb - n), bool)], axis=1)
    take = take[0] if single else take

    def merge(f, b):
        if f is None:
            return None
        f, b = np.asarray(f), np.take(np.asarray(b), undo, axis=axis)
        return np.where(take.reshape(take.shape + (1,) * (f.ndim - take.ndim)), b, f)

    merged = [merge(f, b) for f, b in zip(out, back)]
    # The reverse walk may count turns differently: shift each run it filled by the whole
    # turns that match it to the forward pass at the converged point that follows the run
    # (where both passes found the same pose), so the angles stay continuous as numbers.
    qf = np.asarray(out[0]).reshape(-1, nb, mech.m)
    qb = np.take(np.asarray(back[0]), undo, axis=axis).reshape(qf.shape)
    qm = merged[0].reshape(qf.shape)
    filled = take.reshape(-1, nb)
    for d_ in range(qf.shape[0]):
        runs = np.flatnonzero(filled[d_] & ~np.concatenate([[False], filled[d_, :-1]]))
        for r0 in runs:
            r1 = r0 + np.argmin(filled[d_, r0:]) if not filled[d_, -1] else nb
            if r1 < n and conv[d_, r1] and status_b[d_, r1] == Status.CONVERGED:
                qm[d_, r0:r1] += 2 * np.pi * np.round((qf[d_, r1] - qb[d_, r1]) / (2 * np.pi))
    merged[0] = qm.reshape(merged[0].shape)
    return tuple(None if x is None else jax.device_put(x) for x in merged)


def stroke(mech: Mechanism, us, p: Mapping, guess, options: SolverOptions, derivs: bool, per_design: bool = False):
    """Checks, broadcasting and shape bucketing shared by ``solve_stroke`` and
    ``kinematics.stroke_kinematics``.  Returns ``(Solution, d1, d2)`` (None without ``derivs``).
    ``per_design``: ``us (D, N, dof)`` holds one stroke per design (``p`` leaves ``(D,)``)."""
    us_, p, guess = prepare(mech, us, p, guess, options, u_what="us")
    if per_design:
        us_ = us_.reshape(np.shape(us))  # (D, N, dof) as given
        if us_.ndim != 3 or us_.shape[-1] != mech.dof or us_.shape[1] < 1:
            raise ValueError(f"{mech.name}: per-design strokes must have shape (D, N, {mech.dof}), got {jnp.shape(us)}")
    elif us_.ndim != 2 or us_.shape[0] < 1:
        raise ValueError(f"{mech.name}: us must be one stroke of shape (N,) or (N, {mech.dof}) with N >= 1, got {jnp.shape(us)}")
    shapes = {f"p[{k!r}]": v.shape for k, v in p.items()}
    shapes["guess"] = guess.shape[:-1]
    if per_design:
        shapes["us"] = us_.shape[:1]
    shape = batch_shape(mech, shapes)
    if len(shape) > 1:
        raise ValueError(f"{mech.name}: solve_stroke takes one batch axis of designs, got batch shape {shape}")
    single = shape == ()
    d = 1 if single else shape[0]
    # Concrete arguments are padded and sliced on the host (numpy): an eager jnp op on a new
    # shape compiles a small program of its own (10-50 ms each).
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((us_, p, guess)))
    xp = jnp if traced else np
    pf = {k: xp.broadcast_to(v, (d,)) for k, v in p.items()}
    gf = xp.broadcast_to(guess, (d, mech.m))
    n = us_.shape[-2]
    nb = bucket(n)
    if nb > n:  # pad by repeating the last input
        us_ = xp.concatenate([us_, xp.repeat(us_[..., -1:, :], nb - n, axis=-2)], axis=-2)
    out = _stroke_program(mech, options, bool(derivs), single, us_, pf, gf)
    if not traced:
        out = _backward(mech, options, bool(derivs), single, us_, pf, gf, out, n)
    if nb > n:
        axis = 0 if single else 1
        if traced:
            out = jax.tree_util.tree_map(lambda x: jax.lax.slice_in_dim(x, 0, n, axis=axis), out)
        else:
            # jax.device_put, not jnp.asarray: the latter compiles a small staging program per shape
            out = jax.tree_util.tree_map(lambda x: jax.device_put(np.asarray(x).take(np.arange(n), axis=axis)), out)
    q, status, steps, rn, cond, br, flipped, d1, d2 = out
    sol = Solution(q=q, status=status, steps=steps, residual=rn, cond=cond, branch=br, flipped=flipped, coords=mech.coords, branches=branch_names(mech))
    return sol, d1, d2


def solve_stroke(mech: Mechanism, us, p: Mapping, guess, *, options: SolverOptions = SolverOptions(), throw: bool = False) -> Solution:
    """Solve a whole stroke by continuation, for one design or a batch of designs.

    **Arguments**

    - `us`: the stroke, ``(N,)`` for one input or ``(N, dof)``, in order along the path.
    - `p`: parameters; scalar leaves for one design, or leaves of shape ``(D,)`` for D designs.
    - `guess`: coordinates at ``us[0]``, ``(m,)`` or ``(D, m)``: it picks the branch, which
      continuation then keeps (``BRANCH`` status where only the other branch closes).
    - `options`: ``SolverOptions`` (``options.anchors``: how many points are solved in
      sequence; more anchors are safer near toggles and slower).
    - `throw`: raise ``RuntimeError`` if any sample did not converge.

    **Returns** a ``Solution`` with shape ``(N, ...)`` for one design, ``(D, N, ...)`` for D;
    differentiable in ``us`` and ``p`` by the implicit function theorem.
    """
    sol, _, _ = stroke(mech, us, p, guess, options, derivs=False)
    if throw:
        raise_if_failed(sol)
    return sol
