"""Position solve: damped Newton on the loop-closure equations, with implicit derivatives.

Every function here works on one sample; batching is ``jax.vmap`` (the public
``solve``/``solve_stroke`` broadcast for the user).

Derivatives never go through the Newton iterations.  The converged root ``q*`` is
attached to ``(u, p)`` by a custom JVP that implements the implicit function theorem:
differentiating ``Phi(q*(u, p), u, p) = 0`` gives

    Phi_q dq + Phi_u du + Phi_p dp = 0   =>   dq = -Phi_q^{-1} (Phi_u du + Phi_p dp).

The rule is written in JAX primitives evaluated at the attached (differentiable) root,
so forward mode, reverse mode (by transposition of the linear solve) and every higher
order follow.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._linalg import cond1, small_max, small_norm, small_tmatmul, solve_blocks, solve_small, where
from .mechanism import Mechanism
from .structure import blocks
from .status import Status, status_message

__all__ = ["SolverOptions", "Solution", "solve", "solve_one", "newton", "on_branch", "off_branch", "flipped_mask", "implicit_root", "root_derivatives", "attach_derivatives", "tolerances", "coord_scales", "evaluator"]


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Static solver settings (hashable; part of the compiled function's identity).

    - `max_steps`: Newton/Levenberg-Marquardt iteration budget per sample.
    - `xtol`: converged when the next scaled Newton step is below this (rad, or
      multiples of the design's length scale).  Default ``eps**(2/3)`` of the dtype.
    - `ftol`: converged residual, relative to the design's length scale.  Default
      ``1024 eps``.
    - `cond_max`: a sample whose scaled Jacobian condition number exceeds this is reported
      ``SINGULAR`` (the toggle band).  Default ``eps**-0.5 / 32`` (2.1e6 in float64): an
      exact toggle's Newton iterate lands near ``eps**-0.5``, so it falls in the band in
      any unit system.
    - `max_step`: largest scaled step per iteration (rad, or length scales); keeps far-off
      guesses from jumping across assembly branches.
    - `patience`: iterations with less than 10% residual decrease before a sample is
      declared stalled (``INFEASIBLE``).
    - `anchors`: stroke points solved in sequence (``solve_stroke``); the points between
      two anchors are solved together from the earlier one's predictor.  More anchors:
      safer near toggles, slower.
    - `dtype`: require this floating dtype (``"float64"`` raises if x64 is off or an
      argument is float32); ``None`` follows the arguments.
    """

    max_steps: int = 80
    xtol: float | None = None
    ftol: float | None = None
    cond_max: float | None = None
    max_step: float = 1.0
    patience: int = 8
    anchors: int = 512
    dtype: str | None = None


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Solution:
    """Result of a position solve (a pytree; every array field has the batch shape in front).

    - `q`: dependent coordinates, ``(..., m)``; NaN where the status is not ``CONVERGED``.
    - `status`: ``(...)`` int32 ``Status`` codes.
    - `steps`: iterations used.
    - `residual`: final ``|Phi / R|_2``, R the residual scale (the length scale for loops).
    - `cond`: 1-norm condition number of the scaled constraint Jacobian ``Phi_q``.
    - `branch`: the mechanism's branch indicator at the solution, ``(...)`` or
      ``(..., n_branches)`` for one per loop (NaN if none defined).
    - `flipped`: ``(...)`` int32 bit mask of the branch entries whose sign differs from the
      requested one (bit ``i`` for ``branches[i]``); nonzero exactly where ``BRANCH``.
    - `coords`: coordinate names (static).
    - `branches`: names of the branch indicator's entries (static).
    """

    q: jax.Array
    status: jax.Array
    steps: jax.Array
    residual: jax.Array
    cond: jax.Array
    branch: jax.Array
    flipped: jax.Array
    coords: tuple = dataclasses.field(metadata=dict(static=True), default=())
    branches: tuple = dataclasses.field(metadata=dict(static=True), default=())

    def __getitem__(self, name: str):
        """Coordinate by name: ``sol["theta3"]``."""
        try:
            return self.q[..., self.coords.index(name)]
        except ValueError:
            raise KeyError(f"unknown coordinate {name!r}; coordinates: {self.coords}") from None

    @property
    def ok(self):
        """Boolean mask of converged samples."""
        return self.status == Status.CONVERGED

    def message(self, index=()) -> str:
        """Why the sample at ``index`` (a tuple into the batch shape) has its status, in
        words: for ``BRANCH`` the loops whose assembly flipped, for ``SINGULAR`` the
        condition number, with the fix."""
        code = int(np.asarray(self.status)[index])
        text = status_message(code)
        if code == Status.BRANCH:
            bits = int(np.asarray(self.flipped)[index])
            loops = [n for i, n in enumerate(self.branches) if bits >> i & 1]
            if loops:
                text += f": {', '.join(repr(n) for n in loops)} flipped; give a guess (or stroke start) on the branch you want, or a stroke that stays on it"
        elif code == Status.SINGULAR:
            text += (
                f": scaled condition number {float(np.asarray(self.cond)[index]):.3g} is inside the toggle band "
                "(SolverOptions.cond_max); keep the input away from the toggle, where positions and "
                "their derivatives are ill-defined"
            )
        return text


# --------------------------------------------------------------------------- tolerances
def tolerances(opts: SolverOptions, dtype):
    """``(xtol, ftol, cond_max)`` of ``opts`` for ``dtype`` (defaults from its machine eps)."""
    eps = float(jnp.finfo(dtype).eps)
    xtol = opts.xtol if opts.xtol is not None else eps ** (2.0 / 3.0)
    ftol = opts.ftol if opts.ftol is not None else 1024.0 * eps
    # A toggle band, scale-free: at an exact toggle (a double root) Newton stops where the
    # residual reaches round-off, about sqrt(eps) from the singular pose, where the scaled
    # condition number is about eps**-0.5 (seen: 0.9-4x that).  The band starts 32x below,
    # so a toggle reads SINGULAR whatever the units, never CONVERGED by a hair.
    cond_max = opts.cond_max if opts.cond_max is not None else eps**-0.5 / 32.0
    return xtol, ftol, cond_max


def _all_finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


def coord_scales(mech: Mechanism, p, dtype):
    """``s (m,)``: 1 for angles, the design's length scale for lengths (m)."""
    L = mech.length_scale(p).astype(dtype)
    return where(jnp.asarray(mech.coord_is_length()), L, jnp.ones((), dtype))


def evaluator(mech: Mechanism, u, p, dtype):
    """``q -> (Phi/R, d(Phi/R)/dz)`` with ``z = q / s``, and the coordinate scales ``s``.

    ``s`` is 1 for angles and the design's length scale for lengths; ``R`` is the residual
    scale (the length scale for loop closures).  Both make tolerances unit-independent.
    """
    R = mech.residual_scales(p, dtype)
    s = coord_scales(mech, p, dtype)

    def evaluate(q):
        def f(q_):
            r = mech.residual(q_, u, p) / R
            return r, r

        j, r = jax.jacfwd(f, has_aux=True)(q)
        return r, j * s[None, :]

    return evaluate, s


# --------------------------------------------------------------------------- branches
def off_branch(target, value):
    """Per branch entry: whether ``value``'s sign differs from the requested sign ``target``
    (``target`` 0 or NaN: that entry is free).  Shapes ``()`` or ``(n_branches,)``."""
    return (target != 0) & jnp.isfinite(target) & (jnp.sign(value) != target)


def on_branch(target, value):
    """Whether a branch indicator ``value`` has every requested sign ``target``."""
    return ~jnp.any(off_branch(target, value))


def flipped_mask(target, value):
    """int32 bit mask of the branch entries off their requested sign (``Solution.flipped``)."""
    off = jnp.atleast_1d(off_branch(target, value))
    return jnp.sum(where(off, 2 ** jnp.arange(off.shape[-1], dtype=jnp.int32), 0), axis=-1).astype(jnp.int32)


# --------------------------------------------------------------------------- the Newton kernel
class _NewtonState(NamedTuple):
    """Loop state of ``newton`` (one sample).  ``q``, ``r``, ``rn``, ``js`` belong to the best
    iterate so far; ``dz`` is the next scaled step from it."""

    k: jax.Array  # iterations run (the first only evaluates the guess)
    q: jax.Array  # best iterate (m,)
    r: jax.Array  # scaled residual there (m,)
    rn: jax.Array  # its 2-norm (inf before the first evaluation)
    js: jax.Array  # scaled Jacobian there (m, m)
    dz: jax.Array  # next scaled step (m,), capped at max_step
    size: jax.Array  # max |dz| before the cap
    mu: jax.Array  # Levenberg-Marquardt parameter (0: plain Newton)
    slow: jax.Array  # iterations without a 10% residual decrease
    done: jax.Array
    stalled: jax.Array
    guard: jax.Array  # whether steps that flip the branch indicator are refused
    crossed: jax.Array  # whether the guard refused a better step


def newton(mech: Mechanism, opts: SolverOptions, u, p, guess, target=None, max_step=None):
    """Damped Newton / Levenberg-Marquardt for one sample (no gradients): the one kernel that
    serves single solves, stroke anchors and every stroke point.

    Work is in scaled variables: ``z = q / s`` with ``s`` = 1 for angles and the design's
    length scale ``L`` for lengths, residual ``Phi / R`` (``R = L`` for loop closures, or the
    mechanism's ``residual_scale``).  Each iteration evaluates the residual and Jacobian once
    (at the trial point; the first iteration at the guess) and solves one small system: the
    Newton step while steps lower ``|Phi|``, else the Levenberg-Marquardt step with
    parameter ``mu``, which makes far-off guesses safe without costing the quadratic
    convergence near a root.  A step that leaves the requested branch (``target``: the
    signs of the branch indicator, by default the guess's) is refused like one that raises
    the residual, so the damping finds the root on that branch; if the residual then
    stalls, the guard is lifted once: a root found across is ``BRANCH``, none found
    ``INFEASIBLE``.  A guess off the requested branch may move freely until it reaches it.

    ``max_step`` (may be traced) overrides ``opts.max_step``.

    Returns ``(q, status, steps, residual, cond, branch, flipped)``; ``q`` is the last
    iterate (not masked), ``flipped`` the ``Solution.flipped`` bit mask.  A closed residual (``<= ftol``) whose step cannot meet ``xtol`` means the
    Jacobian is (nearly) singular at an existing pose: ``SINGULAR``, whatever the units.
    """
    dtype = guess.dtype
    xtol, ftol, cond_max = tolerances(opts, dtype)
    tiny = float(jnp.finfo(dtype).tiny)
    evaluate, s = evaluator(mech, u, p, dtype)
    m = mech.m
    eye = jnp.eye(m, dtype=dtype)

    order = blocks(mech)
    cap = opts.max_step if max_step is None else max_step

    def damped(a, r, mu):
        # One solve: Newton (a dz = r) or LM ((a'a + mu D) dz = a' r), chosen by mu.
        lm = mu > 0
        ata = small_tmatmul(a, a)
        eye_b = jnp.eye(a.shape[0], dtype=dtype)
        return solve_small(where(lm, ata + mu * (ata * eye_b + 1e-12 * eye_b), a), where(lm, small_tmatmul(a, r), r))

    def step(r, js, mu):
        if len(order) == 1:
            dz = damped(js, r, mu)
        else:
            # Block-triangular Jacobian (structure.py): the step block by block, each block's
            # right-hand side less the earlier blocks' share; with mu = 0 this is the Newton
            # step exactly, with mu > 0 each block is damped as Levenberg-Marquardt.
            x: dict = {}
            for rows, cols in order:
                rhs = jnp.stack([r[i] - sum((js[i, j] * xj for j, xj in x.items()), jnp.zeros((), dtype)) for i in rows])
                sub = jnp.stack([jnp.stack([js[i, j] for j in cols]) for i in rows])
                xb = damped(sub, rhs, mu)
                x.update({j: xb[t] for t, j in enumerate(cols)})
            dz = jnp.stack([x[j] for j in range(m)])
        dz = where(jnp.all(jnp.isfinite(dz)), dz, jnp.zeros_like(dz))
        size = small_max(jnp.abs(dz))
        # Cap the step: far from a root a Newton step can leap onto another branch.
        return dz * jnp.minimum(1.0, cap / jnp.maximum(size, tiny)), size

    if mech.branch is not None:
        b_guess = jnp.sign(mech.branch_value(guess, u, p)) if target is None else target

        def same_branch(q):
            return on_branch(b_guess, mech.branch_value(q, u, p))
    else:

        def same_branch(q):
            return jnp.asarray(True)

    def cond_fn(st: _NewtonState):
        return (~st.done) & (st.k < opts.max_steps + 1)

    def body(st: _NewtonState) -> _NewtonState:
        qt = st.q - st.dz * s
        rt, jt = evaluate(qt)
        rtn = small_norm(rt)
        better = jnp.isfinite(rtn) & ((rtn < st.rn) | (rtn <= ftol))
        on_b = same_branch(qt) | ~st.guard | ~same_branch(st.q)
        crossed = st.crossed | (better & ~on_b)
        accept = better & on_b
        q, r, rn, js = jax.tree_util.tree_map(lambda a, b: where(accept, a, b), (qt, rt, rtn, jt), (st.q, st.r, st.rn, st.js))
        mu = where(accept, where(st.mu > 1e-6, st.mu / 10.0, 0.0), jnp.maximum(10.0 * st.mu, 1e-3))
        # Steps refused only for crossing the branch are not lack of progress: the damping
        # is still shortening them towards this branch's root.
        slow = where(accept & (rtn < 0.9 * st.rn), 0, where(better & ~on_b, st.slow, st.slow + 1))
        stalled = (slow >= opts.patience) | (mu > 1e12 * jnp.maximum(small_max(jnp.sum(js * js, axis=0)), 1.0))
        lift = stalled & st.guard & crossed
        mu = where(lift, 0.0, mu)
        slow = where(lift, 0, slow)
        stalled = stalled & ~lift
        dz, size = step(r, js, mu)
        converged = (size <= xtol) & (rn <= ftol)
        done = converged | stalled | ~jnp.isfinite(rn)
        return _NewtonState(st.k + 1, q, r, rn, js, dz, size, mu, slow, done, stalled, st.guard & ~lift, crossed)

    inputs_ok = _all_finite((u, p, guess))
    zero = jnp.zeros((), dtype)
    init = _NewtonState(
        k=jnp.zeros((), jnp.int32), q=guess, r=jnp.zeros((m,), dtype), rn=jnp.asarray(jnp.inf, dtype), js=eye,
        dz=jnp.zeros((m,), dtype), size=zero, mu=zero, slow=jnp.zeros((), jnp.int32), done=~inputs_ok,
        stalled=jnp.asarray(False), guard=jnp.asarray(True), crossed=jnp.asarray(False),
    )
    st = jax.lax.while_loop(cond_fn, body, init)

    cond = cond1(st.js, blocks(mech))
    # Near a toggle the attainable accuracy of q is about cond * eps, not xtol: a closed
    # residual whose next step is within that is converged (the band above cond_max is
    # SINGULAR), so below the band the status does not hang on round-off or on the units.
    eps = float(jnp.finfo(dtype).eps)
    converged = (st.size <= jnp.maximum(xtol, 8.0 * eps * jnp.minimum(cond, cond_max))) & (st.rn <= ftol)
    q = where(converged, st.q - st.dz * s, st.q)  # the last Newton step is free: it was computed already
    finite = inputs_ok & jnp.isfinite(st.rn) & jnp.all(jnp.isfinite(q))
    closed = st.rn <= ftol
    status = where(
        ~finite,
        Status.NONFINITE,
        where(
            closed & ((cond > cond_max) | ~converged),
            Status.SINGULAR,
            where(converged, Status.CONVERGED, where(st.stalled, Status.INFEASIBLE, Status.MAX_STEPS)),
        ),
    ).astype(jnp.int32)
    if mech.branch is not None:
        branch = mech.branch_value(q, u, p)
        status = where((status == Status.CONVERGED) & ~on_branch(b_guess, branch), Status.BRANCH, status).astype(jnp.int32)
        flipped = where(status == Status.BRANCH, flipped_mask(b_guess, branch), 0)
    else:
        branch = jnp.asarray(jnp.nan, dtype)
        flipped = jnp.zeros((), jnp.int32)
    steps = jnp.maximum(st.k - 1, 0)
    return q, status, steps, st.rn, cond, branch, flipped


# --------------------------------------------------------------------------- implicit derivatives
@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def implicit_root(mech: Mechanism, q_star, ok, u, p):
    """Attach a converged root ``q*`` to ``(u, p)`` for differentiation (identity on values).

    Tangent: ``dq = -Phi_q^{-1} (Phi_u du + Phi_p dp)`` (implicit function theorem).  Where
    ``ok`` is False the tangent is exactly zero and every intermediate is finite, so a
    failed sample never puts NaN into a batch gradient.
    """
    return q_star


@implicit_root.defjvp
def _implicit_root_jvp(mech, primals, tangents):
    q_star, ok, u, p = primals
    _, _, du, dp = tangents
    q = implicit_root(mech, q_star, ok, u, p)  # differentiable again: second order follows
    # Evaluate the rule at a safe point where the sample failed (its NaNs would leak through
    # 0 * NaN in the transposed, reverse-mode, computation).
    q_s = where(ok, q, jnp.zeros_like(q))
    u_s = where(ok, u, jnp.zeros_like(u))
    p_s = jax.tree_util.tree_map(lambda x: where(ok, x, jnp.ones_like(x)), p)
    du = where(ok, du, jnp.zeros_like(du))
    dp = jax.tree_util.tree_map(lambda x: where(ok, x, jnp.zeros_like(x)), dp)
    _, rhs = jax.jvp(lambda u_, p_: mech.residual(q_s, u_, p_), (u_s, p_s), (du, dp))
    jac = jax.jacfwd(mech.residual)(q_s, u_s, p_s)
    jac = where(ok, jac, jnp.eye(mech.m, dtype=jac.dtype))
    dq = -solve_blocks(jac, rhs, blocks(mech))
    return q, where(ok, dq, jnp.zeros_like(dq))


def root_derivatives(mech: Mechanism, q, u, p, ok):
    """``dq/du (m, dof)`` and ``d2q/du2 (m, dof, dof)`` at a root ``q`` (finite) of one sample.

    Differentiating ``Phi(q(u), u) = 0`` once and twice along the inputs:

        Phi_q q' = -Phi_u,        Phi_q q''[j, k] = -D2 Phi[x_j, x_k],  x_j = (q'_j, e_j),

    so one Jacobian, one factorisation and one second directional derivative per input
    pair serve both orders.  The second derivative is taken with the primal point ``(q, u)``
    itself (not ``q + 0 x``), so under jit it shares its sines and cosines with the
    solver's last Jacobian.  Where ``ok`` is False the Jacobian is replaced by the identity
    and the results are zero: finite in both directions of differentiation.
    """
    m, dof = mech.m, mech.dof
    jq = jax.jacfwd(mech.residual, 0)(q, u, p)
    jq = where(ok, jq, jnp.eye(m, dtype=jq.dtype))
    ju = jax.jacfwd(mech.residual, 1)(q, u, p)
    d1 = -solve_blocks(jq, ju, blocks(mech))
    res = lambda q_, u_: mech.residual(q_, u_, p)  # noqa: E731
    eye = jnp.eye(dof, dtype=d1.dtype)

    def second(j, k):
        inner = lambda q_, u_: jax.jvp(res, (q_, u_), (d1[:, k], eye[k]))[1]  # noqa: E731
        return jax.jvp(inner, (q, u), (d1[:, j], eye[j]))[1]

    hess = jnp.stack([jnp.stack([second(j, k) for k in range(dof)], axis=-1) for j in range(dof)], axis=-2)
    d2 = -solve_blocks(jq, hess.reshape(m, dof * dof), blocks(mech)).reshape(m, dof, dof)
    zero_if = lambda x: where(ok, x, jnp.zeros_like(x))  # noqa: E731
    return zero_if(d1), zero_if(d2)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def attach_derivatives(mech: Mechanism, d1, d2, q_star, ok, u, p):
    """``(d1, d2)`` (``dq/du`` and ``d2q/du2`` computed without gradients at the root
    ``q_star``), made differentiable in ``u`` and ``p`` like ``root_derivatives`` of the
    attached root: its tangent is ``root_derivatives``'s, taken through ``implicit_root``.
    Values pass unchanged; nothing is traced for the tangent unless one is asked for."""
    return d1, d2


@attach_derivatives.defjvp
def _attach_derivatives_jvp(mech, primals, tangents):
    _, _, q_star, ok, u, p = primals
    _, _, _, _, du, dp = tangents
    q_s = where(ok, q_star, jnp.zeros_like(q_star))

    def fn(u_, p_):
        e1, e2 = root_derivatives(mech, implicit_root(mech, q_s, ok, u_, p_), u_, p_, ok)
        return where(ok, e1, jnp.nan), where(ok, e2, jnp.nan)

    (e1, e2), (t1, t2) = jax.jvp(fn, (u, p), (du, dp))
    return (e1, e2), (where(ok, t1, 0.0), where(ok, t2, 0.0))


def solve_one(mech: Mechanism, u, p, guess, options: SolverOptions = SolverOptions()) -> Solution:
    """Solve ``Phi(q, u, p) = 0`` for one sample, differentiable in ``u`` and ``p``.

    `u`: ``(dof,)``; `p`: mapping of scalars; `guess`: ``(m,)``, which selects the branch.
    Returns a ``Solution`` with scalar status.  No checks: use ``solve`` from user code.
    """
    stop = jax.lax.stop_gradient
    q_raw, status, steps, rn, cond, branch, flipped = newton(mech, options, stop(u), jax.tree_util.tree_map(stop, p), stop(guess))
    ok = status == Status.CONVERGED
    q_star = where(ok, q_raw, jnp.nan)
    q = implicit_root(mech, q_star, ok, u, p)
    return Solution(q=q, status=status, steps=steps, residual=rn, cond=cond, branch=branch, flipped=flipped, coords=mech.coords, branches=mech.branches)


# --------------------------------------------------------------------------- user-facing batching
def _stack_named(mech: Mechanism, names, values: Mapping, what: str, kind: str):
    """``{name: array}`` -> array ``(..., len(names))`` in ``names`` order, or ValueError."""
    unknown = [k for k in values if k not in names]
    if unknown:
        raise ValueError(f"{mech.name}: unknown {kind} name(s) {unknown} in {what}; {kind}s are {list(names)}")
    missing = [k for k in names if k not in values]
    if missing:
        raise ValueError(f"{mech.name}: missing {kind}(s) {missing} in {what}")
    xp = _xp(*values.values())
    return xp.stack(xp.broadcast_arrays(*[xp.asarray(values[k]) for k in names]), axis=-1)


def _xp(*values):
    """numpy for concrete values, jax.numpy inside a trace.  Input handling on the host: an
    eager jnp op on a new shape compiles a small program of its own (10-50 ms each)."""
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(values))
    return jnp if traced else np


def _with_last_axis(mech: Mechanism, x, names, what: str, kind: str):
    x = _xp(x).asarray(x)
    if x.ndim == 0 or x.shape[-1] != len(names):
        raise ValueError(f"{mech.name}: {what} must have a last axis of size {len(names)} ({kind}s {names}), got shape {x.shape}")
    return x


def as_inputs(mech: Mechanism, u, what="u"):
    """Inputs as an array ``(..., dof)``.  A dict maps input names to arrays; for one-input
    mechanisms a bare array is the batch of that input."""
    if isinstance(u, Mapping):
        return _stack_named(mech, mech.inputs, u, what, "input")
    if mech.dof == 1:
        return _xp(u).asarray(u)[..., None]
    return _with_last_axis(mech, u, mech.inputs, what, "input")


def as_coords(mech: Mechanism, q, what="guess"):
    """Coordinates as an array ``(..., m)``, from an array or ``{coord_name: array}``."""
    if isinstance(q, Mapping):
        return _stack_named(mech, mech.coords, q, what, "coordinate")
    return _with_last_axis(mech, q, mech.coords, what, "coordinate")


def _check_dtype(options: SolverOptions, named: dict[str, Any]):
    if options.dtype is None:
        return
    want = jnp.dtype(options.dtype)
    if want == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError(
            "dtype='float64' was asked for but JAX runs in float32: call "
            "jax.config.update('jax_enable_x64', True) before creating arrays"
        )
    for name, x in named.items():
        for leaf in jax.tree_util.tree_leaves(x):
            dt = np.asarray(leaf).dtype if not isinstance(leaf, jax.Array) else leaf.dtype
            if jnp.issubdtype(dt, jnp.floating) and dt != want:
                raise ValueError(f"{name} is {dt} but dtype={want} was asked for; convert it with .astype({want.name!r})")


def prepare(mech: Mechanism, u, p, guess, options: SolverOptions, u_what="u"):
    mech.check_params(p)
    _check_dtype(options, {u_what: u, "p": p, "guess": guess})
    u = as_inputs(mech, u, u_what)
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(u, guess, *[_xp(v).asarray(v) for v in p.values()], float)
    if options.dtype is not None:
        dtype = jnp.dtype(options.dtype)
    u = u.astype(dtype)
    guess = guess.astype(dtype)
    p = {k: _xp(p[k]).asarray(p[k], dtype) for k in mech.params}
    return u, p, guess


def batch_shape(mech, shapes: dict[str, tuple]):
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        desc = ", ".join(f"{k}: {v}" for k, v in shapes.items())
        raise ValueError(f"{mech.name}: batch shapes do not broadcast ({desc})") from None


@functools.partial(jax.jit, static_argnums=(0, 1))
def _solve_flat(mech, options, u, p, guess):
    return jax.vmap(lambda u_, p_, g_: solve_one(mech, u_, p_, g_, options))(u, p, guess)


def solve(mech: Mechanism, u, p: Mapping, guess, *, options: SolverOptions = SolverOptions(), throw: bool = False) -> Solution:
    """Solve the loop closure for a batch of inputs and designs (jit-compiled, vmapped).

    **Arguments**

    - `u`: driven inputs; array ``(..., dof)`` (or the bare batch array for one input), or a
      dict ``{input_name: array}``.  Radians for angles, metres for lengths.
    - `p`: ``{param_name: scalar or array}``; arrays broadcast against the batch.
    - `guess`: ``(..., m)`` or ``{coord_name: array}``; picks the assembly branch.
    - `options`: ``SolverOptions``.
    - `throw`: raise ``RuntimeError`` if any sample did not converge (one bad sample raises
      for the whole batch).

    **Returns** a ``Solution`` whose fields have the broadcast batch shape in front;
    differentiable in ``u`` and ``p`` by the implicit function theorem.

    **Raises** ``ValueError`` for unknown names, bad values, shapes or dtypes (before tracing).
    """
    u, p, guess = prepare(mech, u, p, guess, options)
    shape = batch_shape(mech, {"u": u.shape[:-1], "guess": guess.shape[:-1], **{f"p[{k!r}]": v.shape for k, v in p.items()}})
    n = int(np.prod(shape, dtype=np.int64))
    uf = jnp.broadcast_to(u, shape + u.shape[-1:]).reshape(n, -1)
    gf = jnp.broadcast_to(guess, shape + guess.shape[-1:]).reshape(n, -1)
    pf = {k: jnp.broadcast_to(v, shape).reshape(n) for k, v in p.items()}
    sol = _solve_flat(mech, options, uf, pf, gf)
    sol = jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), sol)
    if throw:
        raise_if_failed(sol)
    return sol


def raise_if_failed(sol: Solution):
    from .status import status_counts

    status = np.asarray(sol.status)
    if np.any(status != Status.CONVERGED):
        bad = {k: v for k, v in status_counts(status).items() if k != "CONVERGED"}
        first = np.argwhere(status != Status.CONVERGED)[0]
        raise RuntimeError(
            f"{int(np.sum(status != Status.CONVERGED))} of {status.size} samples failed {bad}; "
            f"first at index {tuple(int(i) for i in first)}: {sol.message(tuple(first))}"
        )


