"""Strokes by continuation: blocks walked by one scan, a guarded predictor, gaps and their
repair, and the public ``solve_stroke``.

A stroke ``us (N, dof)`` is cut into blocks of ``k`` consecutive points.  A ``lax.scan``
walks the blocks in order (``stages.walk_block``); the last point of each solved
block is the *anchor* of the next: its root ``q`` and the implicit derivatives ``dq/du``,
``d2q/du2`` there give every point of the next block a second-order predicted guess
(``point.predict``), and checked Newton steps solve the whole block at once
(vectorised over its points and over the designs).  A block whose guesses are good (a
smooth stroke) takes one Newton step per point.

Gaps (stretches where the mechanism cannot be assembled): an anchor that failed is never
used.  The last trusted anchor is kept, and once a block ends in failure its derivatives
are dropped, so the walk never extrapolates a Taylor series across a gap.  The points the
walk does not solve (a gap, and what follows it) are ``repair``'s: one fresh
assembly at each failed end of the stroke, continuation from there back towards the gap
(a stroke re-enters the assemblable range at a toggle, reachable from the far side only),
and every point still failed solved on its own from its nearest converged neighbours:
bounded work per failed point, batched over all of them.

One program for traced calls (a user's ``jit``, ``vmap``, ``grad``): the walk, then the
repair under a ``lax.cond`` that skips it when every point converged.  Concrete calls run
the walk's program for every design and the repair's program only for the designs with a
failed point (``straight_then_robust``: gathered into batches of ``robust_size`` designs),
from the walk's own results: a design's answer never depends on the others of its batch,
and the smooth case compiles and runs the walk alone.  ``run_scene`` and the sweep kernels
follow the same rule per design, so a sweep and ``run_scene`` give the same bits.  An eager
autodiff (``jax.grad``, ``jvp``, ``jacfwd`` outside any ``jit``) takes the values of that
concrete call, bit for bit, and their tangents from the implicit rule's Jacobians
(``attachment.eager_attach``): it traces a few products, not the stroke.

Compiled shapes are bucketed: a stroke is padded (repeating its last input) to the next of
a few sizes per octave, so 361 and 362 points share one compiled program.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanism.branches import branch_value, has_branch
from ..solver.inputs import batch_shape, prepare
from ..solver.linalg import where
from ..mechanism.mechanism import Mechanism
from ..solver.newton import coord_scales
from ..solver.options import SolverOptions
from ..solver.solution import Solution, raise_if_failed, require_concrete
from ..solver.status import Status
from .point import checked_step, predict
from .attachment import Walked, attach, eager_attach
from .repair import failed_points, repair
from .stages import BlockInput, PointResults, StrokeCarry, StrokeSetup, walk_block
from ..solver.xla import jit, unfused

__all__ = ["solve_stroke", "stroke", "walk", "attach", "Walked", "repaired_rows", "take_rows", "robust_size",
           "repair_stroke", "repair_strokes", "all_converged", "predict", "bucket", "checked_step"]


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
def stroke_setup(mech, options, derivs, us, p, guess):
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
    return StrokeSetup(mech, options, bool(derivs), us.ndim == 2, ps, b0, scales), us_s, g0


def inputs_finite(us, p, guess):
    """``(D, N)``: the points whose input, design parameters and guess are all finite."""
    d = guess.shape[0]
    pv = jnp.stack(list(p.values())) if p else jnp.zeros((0, d), guess.dtype)
    return jnp.all(jnp.isfinite(pv), axis=0)[:, None] & jnp.all(jnp.isfinite(us), axis=-1) & jnp.all(jnp.isfinite(guess), axis=-1)[:, None]


def walk_inputs(us_s, k: int, nblk: int) -> BlockInput:
    """The scan's inputs: the stroke's blocks (``block_layout``), the first one fresh."""
    return BlockInput(u=block_layout(us_s, k, nblk), fresh=jnp.asarray(np.arange(nblk + 1) == 0))


# --------------------------------------------------------------------------- the stroke program
def walk(mech, options, derivs, us, p, guess, n, robust: bool = True) -> Walked:
    """Strokes of D designs: ``us (nb, dof)`` shared or ``(D, nb, dof)`` one per design
    (bucketed: the first ``n`` points are the stroke), ``p`` leaves ``(D,)``, ``guess
    (D, m)``.  The walk (one scan over the stroke's blocks, ``stages.walk_block``),
    then, with ``robust``, ``repair.repair`` of the points it did not solve (under a
    ``lax.cond``: skipped where every point converged).  Values only: nothing here is
    differentiated."""
    setup, us_s, g0 = stroke_setup(mech, options, derivs, us, p, guess)
    d, nb = guess.shape[0], us.shape[-2]
    k = block_size(nb, options.anchors)
    nblk = -(-(nb - 1) // k) if nb > 1 else 0
    valid = inputs_finite(us, p, guess)  # (D, nb)
    u_first = jnp.broadcast_to(us_s[..., 0, :], (d, us.shape[-1]))
    m, dof = mech.m, us.shape[-1]
    init = StrokeCarry(g0, jnp.zeros((d, m, dof), g0.dtype), jnp.zeros((d, m, dof, dof), g0.dtype), u_first, jnp.zeros((d,), jnp.int32))
    _, out = jax.lax.scan(functools.partial(walk_block, setup), init, walk_inputs(us_s, k, nblk))
    points = jax.tree_util.tree_map(lambda x: unblock(x, d, k, nb), out)
    if robust:
        points = jax.lax.cond(jnp.any(failed_points(points, valid, n)), lambda x: repair(setup, us_s, x, valid, n, g0), lambda x: x, points)
    return Walked(points, valid, setup.b0)


@functools.partial(jit, static_argnums=(0, 1, 2, 3, 4))
def _stroke_program(mech, options, derivs, single, robust, us, p, guess, n):
    """``walk`` then ``attach``: ``(Solution, d1, d2)`` with ``(D, nb)`` in front (the design
    axis dropped with ``single``; ``d1``, ``d2`` None without ``derivs``)."""
    res = attach(mech, walk(mech, options, derivs, us, p, guess, n, robust), us, p)
    return jax.tree_util.tree_map(lambda x: x[0], res) if single else res


def as_points(sol: Solution, d1, d2) -> PointResults:
    """A stroke's ``(Solution, d1, d2)`` (``attach``'s) as the walk's ``PointResults`` again:
    the values at converged points (``attach`` passes them through), zeros elsewhere."""
    ok = sol.status == Status.CONVERGED
    zero = lambda x: None if x is None else where(ok.reshape(ok.shape + (1,) * (x.ndim - ok.ndim)), x, 0.0)  # noqa: E731
    return PointResults(q=zero(sol.q), status=sol.status, steps=sol.steps, residual=sol.residual, cond=sol.cond,
                        branch=sol.branch, flipped=jnp.zeros_like(sol.status), d1=zero(d1), d2=zero(d2))


def repair_stroke(mech, options, derivs, us, p, guess, n, walked):
    """``(Solution, d1, d2)`` of a walked stroke (the walk's ``(Solution, d1, d2)``, ``(D, nb)``
    in front) with its failed points repaired (``repair.repair``); traceable."""
    setup, us_s, g0 = stroke_setup(mech, options, derivs, us, p, guess)
    valid = inputs_finite(us, p, guess)
    points = repair(setup, us_s, as_points(*walked), valid, n, g0)
    return attach(mech, Walked(points, valid, setup.b0), us, p)


def repair_strokes(mech, us, p, guess, options, walked):
    """Per-design strokes ``us (D, N, dof)`` walked by the walk alone (``walked``: its
    ``(Solution, d1, d2)``, ``(D, N)`` in front), with their failed points repaired: what a
    scene's repair stage runs (traceable; bucketed as ``stroke`` buckets)."""
    n = us.shape[-2]
    nb = bucket(n)

    def pad(x):
        return x if nb == n else jnp.concatenate([x, jnp.repeat(x[:, -1:], nb - n, axis=1)], axis=1)

    out = repair_stroke(mech, options, walked[1] is not None, pad(us), p, guess, jnp.int32(n), jax.tree_util.tree_map(pad, walked))
    return jax.tree_util.tree_map(lambda x: x[:, :n], out)


@functools.partial(jit, static_argnums=(0, 1, 2))
def _repair_program(mech, options, derivs, us, p, guess, n, walked):
    """``repair_stroke`` as a program of its own: what a concrete stroke runs for the designs
    whose walk left a point failed."""
    return repair_stroke(mech, options, derivs, us, p, guess, n, walked)


# --------------------------------------------------------------------------- concrete strokes
def all_converged(status) -> np.ndarray:
    """Per design (``()`` for one), whether every sample of ``status (..., N)`` converged."""
    return np.all(np.asarray(status) == Status.CONVERGED, axis=-1)


def robust_size(d: int) -> int:
    """How many designs one call of a repair program takes for a batch of ``d``: all of a
    small batch, else a sixteenth of it (a power of two, at least 8), so the repair
    compiles once per batch size and costs about what the failed designs need."""
    if d <= 8:
        return d
    return min(d, max(8, 1 << (d // 16 - 1).bit_length()))


def _per_design(passed: np.ndarray, straight, robust):
    """``straight``'s values for the designs that ``passed``, ``robust``'s for the others
    (host arrays, design axis first): a design's answer never depends on the others'."""
    if passed.ndim == 0:
        return straight if passed else robust

    def pick(a, b):
        a, b = np.asarray(a), np.asarray(b)
        return jax.device_put(np.where(passed.reshape(passed.shape + (1,) * (a.ndim - 1)), a, b))

    return jax.tree_util.tree_map(pick, straight, robust)


def _rows_on_host() -> bool:
    """Whether a concrete stroke's arrays live in host memory (the CPU backend): its designs
    are then gathered and scattered with numpy, which compiles nothing and costs a copy of
    the rows (the device programs did the same work in 2-7 ms a call on 2,048 four-bar
    designs, and compiled in 0.2 s each on a sweep's first call)."""
    return jax.default_backend() == "cpu"


def take_rows(tree, idx):
    """Every leaf of ``tree`` (design axis first, concrete) at the designs ``idx``: with
    numpy where the arrays live on the host, else on the device."""
    if _rows_on_host():
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[idx], tree)
    return _take_rows(tree, idx)


@jax.jit
def _take_rows(tree, idx):
    return jax.tree_util.tree_map(lambda x: jnp.take(x, idx, axis=0), tree)


@jax.jit
def _put_rows(tree, idx, rows):
    """``tree`` with the designs ``idx`` (out of range: dropped) replaced by ``rows``."""
    return jax.tree_util.tree_map(lambda x, r: x.at[idx].set(r, mode="drop"), tree, rows)


def repaired_rows(straight, passed: np.ndarray, repair_rows, size: int, work: np.ndarray | None = None):
    """``straight`` (design axis first) with the rows of the designs that did not pass
    replaced by ``repair_rows(idx)``'s (``idx``: ``size`` design indices, the failed ones in
    order, padded with a design that passed (nothing to repair: it costs nothing), else
    the first failed one).  ``work`` (per design, optional): the failed designs go in
    ascending order of it (stable), so that designs with little to repair share a call
    instead of waiting on the phases of designs with a gap (a design's rows do not depend
    on the others of its call).  Gathered and scattered with numpy on the CPU backend, on
    the device elsewhere (``take_rows``)."""
    failed = np.flatnonzero(~passed)
    if work is not None:
        failed = failed[np.argsort(np.asarray(work)[failed], kind="stable")]
    good = np.flatnonzero(passed)
    host = _rows_on_host()
    out = jax.tree_util.tree_map(np.array, straight) if host else straight  # np.array: a writable copy
    for start in range(0, failed.size, size):
        part = failed[start : start + size]
        pad = size - part.size
        idx = np.concatenate([part, np.full(pad, good[0] if good.size else part[0])]).astype(np.int32)
        rows = repair_rows(idx)
        if host:
            for o, r in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(rows)):
                o[part] = np.asarray(r)[: part.size]  # the padding rows are left out
        else:
            put = np.concatenate([part, np.full(pad, passed.size)]).astype(np.int32)  # padding rows are dropped
            out = _put_rows(out, put, rows)
    return jax.device_put(out) if host else out


def straight_then_robust(run, passed_of, repair_rows=None, size: int | None = None):
    """``run(False)`` (the walk alone), then, only if some design did not pass
    (``passed_of(result)``: a bool per design, ``(D,)`` or ``()``), its repair: by
    ``repair_rows(idx, straight)`` for the failed designs alone in batches of ``size``
    (``repaired_rows``) where given, else ``run(True)`` for all.  Each design keeps the
    first result where it passed.  One rule for every concrete stroke: ``stroke``,
    ``scenes.evaluation.evaluate`` and the sweep kernels, so a design's result is the same
    whichever of them computed it."""
    straight = run(False)
    passed = np.asarray(passed_of(straight))
    if np.all(passed):
        return straight
    if repair_rows is None or passed.ndim == 0:
        return _per_design(passed, straight, run(True))
    return repaired_rows(straight, passed, lambda idx: repair_rows(idx, straight), size or robust_size(passed.size))


def stroke(mech: Mechanism, us, p: Mapping, guess, options: SolverOptions, derivs: bool, per_design: bool = False,
           robust: bool | None = None):
    """Checks, broadcasting and shape bucketing shared by ``solve_stroke`` and
    ``kinematics.stroke_kinematics``.  Returns ``(Solution, d1, d2)`` (None without ``derivs``).
    ``per_design``: ``us (D, N, dof)`` holds one stroke per design (``p`` leaves ``(D,)``).
    ``robust``: None picks the programs (concrete arguments: the walk, then the repair for
    the designs where a point failed it; traced: the walk and the repair as one program);
    True or False forces one (False: the walk alone, for a caller that checks the statuses
    and repairs itself)."""
    us_, p, guess = prepare(mech, us, p, guess, options, u_what="us")
    if not per_design and mech.dof == 1 and not isinstance(us, Mapping) and np.ndim(us) == 1:
        us_ = us_.reshape((-1, 1))  # (N,): N points of the one input, a one-point stroke too
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
    derivs, n_ = bool(derivs), np.int32(n)
    stopped = jax.tree_util.tree_map(jax.lax.stop_gradient, (us_, pf, gf)) if traced and robust is None else None
    if robust is not None:
        out = _stroke_program(mech, options, derivs, single, bool(robust), us_, pf, gf, n_)
    elif not traced:
        out = _concrete(mech, options, derivs, single, per_design, us_, pf, gf, n_)
    elif not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(stopped)):
        # differentiated eagerly: the values are the concrete stroke's (its programs), and
        # the autodiff traces only the implicit rule's Jacobians contracted with its tangents
        out = eager_attach(mech, single, _concrete(mech, options, derivs, single, per_design, *stopped, n_), us_, pf)
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


def _concrete(mech, options, derivs, single, per_design, us_, pf, gf, n_):
    """A concrete stroke (bucketed, ``(D, nb)``): the walk's program for every design, the
    repair's for the designs it left a point failed (``straight_then_robust``)."""
    n = int(n_)

    def passed_of(o):
        return all_converged(np.asarray(o[0].status)[..., :n])

    def repair_rows(idx, straight):
        p_i, g_i, walked = take_rows((pf, gf, straight), idx)
        return _repair_program(mech, options, derivs, take_rows(us_, idx) if per_design else us_, p_i, g_i, n_, walked)

    if single:
        straight = _stroke_program(mech, options, derivs, True, False, us_, pf, gf, n_)
        if passed_of(straight):
            return straight
        walked = jax.tree_util.tree_map(lambda x: np.asarray(x)[None], straight)
        return jax.tree_util.tree_map(lambda x: x[0], _repair_program(mech, options, derivs, us_, pf, gf, n_, walked))
    run = lambda r: _stroke_program(mech, options, derivs, False, r, us_, pf, gf, n_)  # noqa: E731
    return straight_then_robust(run, passed_of, repair_rows)


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
