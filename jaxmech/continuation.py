"""Strokes by continuation: blocks walked by one scan, a guarded predictor, gaps, a
reverse walk, and the public ``solve_stroke``.

A stroke ``us (N, dof)`` is cut into blocks of ``k`` consecutive points.  A ``lax.scan``
walks the blocks in order (``stroke_stages.walk_block``); the last point of each solved
block is the *anchor* of the next: its root ``q`` and the implicit derivatives ``dq/du``,
``d2q/du2`` there give every point of the next block a second-order predicted guess
(``stroke_point.predict``), and checked Newton steps solve the whole block at once
(vectorised over its points and over the designs); points that fail them are solved by the
robust kernel (``stroke_point.assemble``).  A block whose guesses are good (a smooth
stroke) takes one Newton step per point.

Gaps (stretches where the mechanism cannot be assembled): an anchor that failed is never
used.  The last trusted anchor is kept, and once a block ends in failure its derivatives
are dropped, so the points after a gap restart from the last trusted pose itself (damped
Newton, branch guard) instead of a Taylor series extrapolated across the gap.

The reverse walk: a stroke that re-enters the assemblable range does so at a toggle,
where the requested branch's poses exist but are hard to reach from the last pose before
the gap (Newton's steps there run across the fold to the other branch); they are easy to
reach from the well-conditioned stretch after them.  So where a design has a failed point
followed by a converged one, the same scan walks the stroke once more in reverse, from that
design's last converged pose, and the points it solves on the requested branch that the
forward walk did not take its answer (``merge_reverse``).  It is part of the one compiled
program (the scan's second half, skipped block by block when no design needs it), so a
stroke gives the same statuses and values eager and under a user's ``jax.jit``.

Two programs: called with concrete arguments, a stroke first runs the straight-line
program (checked steps only, up to ``FRESH_STEPS`` plain Newton steps from each design's
guess at its first point, forward only: ``walk(..., robust=False)``), and the robust
program (the re-solve and the reverse walk) only where some point failed it: a design whose
points all pass keeps the straight-line values, the others take the robust program's (so a
design's answer never depends on the other designs of its batch).  A smooth stroke's first
answer thus compiles only what it runs.  ``run_scene`` and the sweep kernels follow the same rule per design
(``straight_then_robust``), so a sweep and ``run_scene`` give the same bits.  A traced call
(a user's ``jit``, ``vmap``) is the robust program; its values may differ from the
straight-line program's in the last bit (two compiled programs).

Compiled shapes are bucketed: a stroke is padded (repeating its last input) to the next of
a few sizes per octave, so 361 and 362 points share one compiled program.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from .branches import branch_value, has_branch
from .inputs import batch_shape, prepare
from .linalg import where
from .mechanism import Mechanism
from .newton import coord_scales
from .options import SolverOptions
from .solution import Solution, raise_if_failed, require_concrete
from .status import Status
from .stroke_point import assemble, checked_step, predict
from .stroke_attach import Walked, attach, eager_attach
from .stroke_stages import BlockInput, PointResults, StrokeCarry, StrokeSetup, WalkState, stroke_step, walk_block
from .xla import jit, unfused

__all__ = ["solve_stroke", "stroke", "walk", "attach", "Walked", "straight_then_robust", "all_converged", "predict", "bucket", "assemble", "checked_step", "merge_reverse"]


# --------------------------------------------------------------------------- shapes
def bucket(n: int) -> int:
    """The compiled size for ``n`` stroke points: ``n`` rounded up to a multiple of a power
    of two with five significant bits (at most 1/16 = 6% padding)."""
    e = max(0, int(n).bit_length() - 5)
    return -(-int(n) // (1 << e)) << e


def block_size(n: int, anchors: int) -> int:
    """Stroke points per block for ``n`` points and (at most about) ``anchors`` anchors."""
    return max(1, -(-(n - 1) // max(1, anchors)))


def block_layout(x, k: int, nblk: int):
    """Per-point values ``x (..., N, c)`` (inputs, flags) as blocks: block 0 is point 0
    repeated ``k`` times (its last entry is the first anchor, solved from the user's guess),
    blocks 1.. hold points 1..N-1, the last padded by repeating point N-1.  Returns
    ``(nblk + 1, ..., k, c)``."""
    n, dof = x.shape[-2:]
    lead = x.shape[:-2]
    pad = jnp.broadcast_to(x[..., -1:, :], lead + (nblk * k - (n - 1), dof))
    rest = jnp.concatenate([x[..., 1:, :], pad], axis=-2) if n > 1 else x[..., :0, :]
    out = jnp.concatenate([jnp.broadcast_to(x[..., :1, :], lead + (k, dof)), rest], axis=-2)
    return jnp.moveaxis(out.reshape(lead + (nblk + 1, k, dof)), -3, 0)


def block_points(nb: int, k: int, nblk: int) -> np.ndarray:
    """``(nblk + 1, k)``: the stroke point each block entry reports (``-1``: block 0's
    repeats, or padding past the last point)."""
    idx = np.concatenate([np.full(k - 1, -1), np.arange(nblk * k + 1)])
    return np.where(idx < nb, idx, -1).reshape(nblk + 1, k)


def unblock(x, d: int, k: int, nb: int):
    """``(nblk + 1, D, k, ...)`` scan outputs -> ``(D, nb, ...)``: point 0 is block 0's last entry."""
    return jnp.moveaxis(x, 0, 1).reshape((d, x.shape[0] * k) + x.shape[3:])[:, k - 1 : k - 1 + nb]


# --------------------------------------------------------------------------- the program's parts
def stroke_setup(mech, options, derivs, us, p, guess, robust: bool = True):
    """``(StrokeSetup, us, guess)`` with non-finite inputs, parameters and guesses replaced
    once, here, by harmless values (their samples are flagged later): no derivative code
    ever sees a NaN that could leak into a batch gradient."""
    stop = jax.lax.stop_gradient
    d, dtype = guess.shape[0], guess.dtype
    us_s = where(jnp.isfinite(us), us, 0.0)
    # The parameters as one (n_params, D) array: one reduction says which designs are finite.
    # Tested one by one, XLA's CPU fusion copied the chain of tests into every consumer of
    # the status (flap_msd, 29 parameters: 1,000 is-finite instructions in the program).
    pv = jnp.stack(list(p.values())) if p else jnp.zeros((0, d), dtype)
    ps = jax.tree_util.tree_map(stop, dict(zip(p, unfused(where(jnp.isfinite(pv), pv, 1.0)))) if p else {})
    g0 = stop(where(jnp.isfinite(guess), guess, 0.0))
    u_first = jnp.broadcast_to(us_s[..., 0, :], (d, us.shape[-1]))
    if has_branch(mech):
        b0 = jnp.sign(jax.vmap(lambda g_, u_, p_: branch_value(mech, g_, u_, p_))(g0, u_first, ps))
    else:
        b0 = jnp.zeros((d,), dtype)
    scales = jax.vmap(lambda p_: coord_scales(mech, p_, dtype))(ps)
    return StrokeSetup(mech, options, bool(derivs), us.ndim == 2, ps, b0, scales, robust), us_s, g0


def inputs_finite(us, p, guess):
    """``(D, N)``: the points whose input, design parameters and guess are all finite."""
    d = guess.shape[0]
    pv = jnp.stack(list(p.values())) if p else jnp.zeros((0, d), guess.dtype)
    return jnp.all(jnp.isfinite(pv), axis=0)[:, None] & jnp.all(jnp.isfinite(us), axis=-1) & jnp.all(jnp.isfinite(guess), axis=-1)[:, None]


def empty_points(setup: StrokeSetup, g0, u_first, k: int) -> PointResults:
    """Zeros shaped like one block's ``PointResults`` (what a skipped reverse block outputs)."""
    mech, (d, m), dtype = setup.mech, g0.shape, g0.dtype
    dof = u_first.shape[-1]
    br = jax.eval_shape(jax.vmap(lambda g_, u_, p_: branch_value(mech, g_, u_, p_)), g0, u_first, setup.p)
    z = lambda *shape: jnp.zeros((d, k) + shape, dtype)  # noqa: E731
    i = jnp.zeros((d, k), jnp.int32)
    derivs = (z(m, dof), z(m, dof, dof)) if setup.derivs else (None, None)
    return PointResults(z(m), i, i, z(), z(), jnp.zeros((d, k) + br.shape[1:], br.dtype), *derivs)


def reverse_points(x, n, fill=None):
    """``x (..., nb, ...)`` (points on axis ``-2`` without ``fill``, else axis 1) with its
    first ``n`` points in reverse order (``n`` traced): a flip and a dynamic slice, not a
    gather (a gather per field cost hundreds of lines of the program).  The entries past
    ``n`` are ``fill`` (``(..., 1, dof)``) where given, else unspecified."""
    axis = -2 if fill is not None else 1
    nb = x.shape[axis]
    f = jnp.flip(x, axis)
    out = jax.lax.dynamic_slice_in_dim(jnp.concatenate([f, f], axis), nb - n, nb, axis % x.ndim)
    if fill is None:
        return out
    return where((jnp.arange(nb) < n)[:, None], out, fill)


def walk_inputs(setup: StrokeSetup, us_s, valid, n, k: int, nblk: int):
    """``(BlockInput, us_r)``: the scan's inputs, the forward blocks then the reverse walk's,
    and the reversed stroke ``us_r`` (the stroke's ``n`` points reversed, padded with point 0:
    ``n`` is traced, one program serves a bucket)."""
    nb = us_s.shape[-2]
    idx = block_points(nb, k, nblk)
    # the inputs' block layout (no gather), less block 0's repeats and the padding
    valid_f = block_layout(valid[..., None], k, nblk)[..., 0] & ((idx >= 0)[:, None] & (jnp.asarray(idx)[:, None] < n))
    us_r = reverse_points(us_s, n, fill=us_s[..., :1, :])
    flags = np.arange(2 * (nblk + 1)) >= nblk + 1
    return BlockInput(
        u=jnp.concatenate([block_layout(us_s, k, nblk), block_layout(us_r, k, nblk)]),
        valid=jnp.concatenate([valid_f, jnp.zeros_like(valid_f)]),
        reverse=jnp.asarray(flags),
        restart=jnp.asarray(np.arange(2 * (nblk + 1)) == nblk + 1),
        fresh=jnp.asarray(np.isin(np.arange(2 * (nblk + 1)), (0, nblk + 1))),
    ), us_r


def merge_reverse(mech: Mechanism, fwd: PointResults, back: PointResults, need, n, valid) -> PointResults:
    """The forward walk's points, ``(D, nb, ...)``, where a design that ``need``s it takes the
    reverse walk's answer (``back``, in reversed order) at the points the forward walk did
    not solve (``valid``: finite inputs) and the reverse walk solved on the branch.

    The reverse walk may count turns differently: each run it filled is shifted by the whole
    turns that match it to the forward walk at the converged point that follows the run
    (where both walks found the same pose), so the angles stay continuous as numbers.
    """
    nb = fwd.status.shape[1]
    i = jnp.arange(nb)
    back = jax.tree_util.tree_map(lambda x: reverse_points(x, n), back)
    conv_f = (fwd.status == Status.CONVERGED) & valid
    conv_b = back.status == Status.CONVERGED
    take = need[:, None] & ~conv_f & conv_b & (i < n)
    merged = PointResults(*(None if f is None else where(take.reshape(take.shape + (1,) * (f.ndim - 2)), b, f) for f, b in zip(fwd, back)))
    # r1: the first point at or after each one that the reverse walk did not fill; one
    # gather reads both walks' agreement and turn difference there
    r1 = jax.lax.cummin(jnp.where(take, nb, i), axis=1, reverse=True)
    both = (conv_f & conv_b)[..., None].astype(fwd.q.dtype)
    at_r1 = jnp.take_along_axis(jnp.concatenate([fwd.q - back.q, both], axis=-1), jnp.clip(r1, 0, nb - 1)[..., None], axis=1)
    joined = take & (r1 < n) & (at_r1[..., -1] > 0.5)
    angle = ~jnp.asarray(mech.coord_is_length())
    turns = jnp.round(at_r1[..., :-1] / (2 * jnp.pi))
    # a select, not "+ 0.0": an untouched angle keeps its bits (-0.0 too), as without the walk
    return merged._replace(q=where(joined[..., None] & angle, merged.q + 2 * jnp.pi * turns, merged.q))


# --------------------------------------------------------------------------- the stroke program
def walk(mech, options, derivs, us, p, guess, n, robust: bool = True) -> Walked:
    """Strokes of D designs walked, forward then in reverse where needed: ``us (nb, dof)``
    shared or ``(D, nb, dof)`` one per design (bucketed: the first ``n`` points are the
    stroke), ``p`` leaves ``(D,)``, ``guess (D, m)``.  The forward walk and the reverse walk
    are one scan over the blocks of the stroke and then of the reversed stroke
    (``stroke_stages.stroke_step``).  Values only: nothing here is differentiated.

    ``robust=False``: the straight-line walk (checked steps only, up to ``CHECKED_STEPS`` a
    point and ``FRESH_STEPS`` from the guess, forward only): a point those do not bring to
    the tests stays failed.  Where both walks converge they agree to rounding: the robust
    walk takes one checked step a point and re-solves the rest, the first point included."""
    setup, us_s, g0 = stroke_setup(mech, options, derivs, us, p, guess, robust)
    d, nb = guess.shape[0], us.shape[-2]
    k = block_size(nb, options.anchors)
    nblk = -(-(nb - 1) // k) if nb > 1 else 0
    valid = inputs_finite(us, p, guess)  # (D, nb)
    xs, us_r = walk_inputs(setup, us_s, valid, n, k, nblk)
    u_first = jnp.broadcast_to(us_s[..., 0, :], (d, us.shape[-1]))
    m, dof = mech.m, us.shape[-1]
    init = StrokeCarry(g0, jnp.zeros((d, m, dof), g0.dtype), jnp.zeros((d, m, dof, dof), g0.dtype), u_first,
                       WalkState(jnp.zeros((d,), bool), jnp.zeros((d,), bool), g0))  # fmt: skip
    if not robust:
        forward = jax.tree_util.tree_map(lambda x: x[: nblk + 1], xs)
        _, out = jax.lax.scan(functools.partial(walk_block, setup), init, forward)
        return Walked(jax.tree_util.tree_map(lambda x: unblock(x, d, k, nb), out), valid, setup.b0)
    u_first_r = jnp.broadcast_to(us_r[..., 0, :], (d, dof))
    step = functools.partial(stroke_step, setup, g0, u_first_r, empty_points(setup, g0, u_first, k))
    last, out = jax.lax.scan(step, init, xs)
    fwd = jax.tree_util.tree_map(lambda x: unblock(x[: nblk + 1], d, k, nb), out)
    back = jax.tree_util.tree_map(lambda x: unblock(x[nblk + 1 :], d, k, nb), out)
    return Walked(merge_reverse(mech, fwd, back, last.walk.need, n, valid), valid, setup.b0)


@functools.partial(jit, static_argnums=(0, 1, 2, 3, 4), stored=True)  # a new process loads it (jaxmech.stored)
def _stroke_program(mech, options, derivs, single, robust, us, p, guess, n):
    """``walk`` then ``attach``: ``(Solution, d1, d2)`` with ``(D, nb)`` in front (the design
    axis dropped with ``single``; ``d1``, ``d2`` None without ``derivs``)."""
    res = attach(mech, walk(mech, options, derivs, us, p, guess, n, robust), us, p)
    return jax.tree_util.tree_map(lambda x: x[0], res) if single else res


@functools.partial(jit, static_argnums=(0, 1, 2, 3), stored=True)
def _walk_program(mech, options, derivs, robust, us, p, guess, n) -> Walked:
    """``walk`` alone, for a stroke differentiated eagerly (``jax.grad`` outside any ``jit``):
    its inputs are then concrete once their gradients are stopped, so this program is the
    stored one (``stroke_attach.eager_attach`` attaches its result)."""
    return walk(mech, options, derivs, us, p, guess, n, robust)


def all_converged(status) -> np.ndarray:
    """Per design (``()`` for one), whether every sample of ``status (..., N)`` converged."""
    return np.all(np.asarray(status) == Status.CONVERGED, axis=-1)


def _per_design(passed: np.ndarray, straight, robust):
    """``straight``'s values for the designs that ``passed``, ``robust``'s for the others
    (host arrays, design axis first): a design's answer never depends on the others'."""
    if passed.ndim == 0:
        return straight if passed else robust

    def pick(a, b):
        a, b = np.asarray(a), np.asarray(b)
        return jax.device_put(np.where(passed.reshape(passed.shape + (1,) * (a.ndim - 1)), a, b))

    return jax.tree_util.tree_map(pick, straight, robust)


def straight_then_robust(run, passed_of):
    """``run(False)`` (a straight-line program), then ``run(True)`` (the robust one) only if
    some design did not pass (``passed_of(result)``: a bool per design, ``(D,)`` or ``()``):
    each design keeps the first result where it passed and takes the second's elsewhere.
    One rule for every concrete stroke: ``stroke``, ``scenes.evaluation.evaluate`` and the
    sweep kernels, so a design's result is the same whichever of them computed it."""
    straight = run(False)
    passed = np.asarray(passed_of(straight))
    return straight if np.all(passed) else _per_design(passed, straight, run(True))


def stroke(mech: Mechanism, us, p: Mapping, guess, options: SolverOptions, derivs: bool, per_design: bool = False,
           robust: bool | None = None):
    """Checks, broadcasting and shape bucketing shared by ``solve_stroke`` and
    ``kinematics.stroke_kinematics``.  Returns ``(Solution, d1, d2)`` (None without ``derivs``).
    ``per_design``: ``us (D, N, dof)`` holds one stroke per design (``p`` leaves ``(D,)``).
    ``robust``: None picks the program (concrete arguments: the straight-line one, then the
    robust one where a point failed it; traced: the robust one); True or False forces one
    (False: a caller that checks the statuses and runs the robust one itself)."""
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
    # n traced: one program serves every length of a bucket
    # Concrete arguments run the straight-line program first (checked steps only: a third
    # of the compile) and the robust one only where some point failed it: a smooth stroke's
    # first answer compiles only what it runs.
    derivs, n_ = bool(derivs), np.int32(n)
    stopped = jax.tree_util.tree_map(jax.lax.stop_gradient, (us_, pf, gf)) if traced and robust is None else None
    if robust is not None:
        out = _stroke_program(mech, options, derivs, single, bool(robust), us_, pf, gf, n_)
    elif not traced:
        out = straight_then_robust(lambda r: _stroke_program(mech, options, derivs, single, r, us_, pf, gf, n_),
                                   lambda o: all_converged(o[0].status))  # fmt: skip
    elif not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(stopped)):
        # differentiated eagerly: the walk (values only) runs as a stored program, and the
        # autodiff traces only the implicit rule's attachment
        walked = straight_then_robust(lambda r: _walk_program(mech, options, derivs, r, *stopped, n_),
                                      lambda w: np.all(np.asarray(w.converged), axis=-1))  # fmt: skip
        out = eager_attach(mech, single, walked, us_, pf)
    else:
        out = _stroke_program(mech, options, derivs, single, True, us_, pf, gf, n_)
    if nb > n:
        axis = 0 if single else 1
        if traced:
            out = jax.tree_util.tree_map(lambda x: jax.lax.slice_in_dim(x, 0, n, axis=axis), out)
        else:
            # jax.device_put, not jnp.asarray: the latter compiles a small staging program per shape
            out = jax.tree_util.tree_map(lambda x: jax.device_put(np.asarray(x).take(np.arange(n), axis=axis)), out)
    return out


def solve_stroke(mech: Mechanism, us, p: Mapping, guess, *, options: SolverOptions = SolverOptions(), throw: bool = False) -> Solution:
    """Solve a whole stroke by continuation, for one design or a batch of designs.

    **Arguments**

    - `us`: the stroke, ``(N,)`` for one input or ``(N, dof)``, in order along the path.
    - `p`: parameters; scalar leaves for one design, or leaves of shape ``(D,)`` for D designs.
    - `guess`: coordinates at ``us[0]``, ``(m,)`` or ``(D, m)``: it picks the branch, which
      continuation then keeps (``BRANCH`` status where only the other branch closes).
    - `options`: ``SolverOptions`` (``options.anchors``: how many points are solved in
      sequence; more anchors are safer near toggles and slower).
    - `throw`: raise ``RuntimeError`` if any sample did not converge.  Needs concrete
      arguments: with traced ones (inside ``jax.jit``, ``vmap``, ``grad``) ``throw=True``
      raises ``ValueError`` at once; check ``sol.status`` instead.

    **Returns** a ``Solution`` with shape ``(N, ...)`` for one design, ``(D, N, ...)`` for D;
    differentiable in ``us`` and ``p`` by the implicit function theorem.
    """
    if throw:
        require_concrete((us, p, guess))
    sol, _, _ = stroke(mech, us, p, guess, options, derivs=False)
    if throw:
        raise_if_failed(sol)
    return sol
