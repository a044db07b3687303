"""The Newton kernel: damped Newton / Levenberg-Marquardt on the loop-closure equations for
one sample, in scaled variables, with a branch guard; and the branch-sign helpers."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..mechanism.branches import branch_value, flipped_mask, has_branch, on_branch
from .linalg import cond1, entries, parts, small_max, small_norm, small_tmatmul, solve_small, where
from ..mechanism.mechanism import Mechanism
from .options import SolverOptions, tolerances
from .solution import Solution
from .status import Status
from ..mechanism.structure import blocks

__all__ = ["newton", "NewtonState", "newton_iteration", "evaluator", "coord_scales", "per_lane"]

#: Levenberg-Marquardt damping of the kernel (scaled units).  An accepted step divides
#: ``mu`` by ``MU_DECREASE`` (and drops it to 0, plain Newton, once it is below
#: ``MU_NEWTON``); a refused one multiplies it by ``MU_INCREASE``, starting from ``MU_START``.
MU_START = 1e-3
MU_DECREASE = 10.0
MU_INCREASE = 10.0
MU_NEWTON = 1e-6
#: A sample whose ``mu`` exceeds ``MU_STALL`` times its largest squared Jacobian column
#: makes no progress at any step length: stalled.
MU_STALL = 1e12
#: LM's damping floor in units of the dtype's eps (9.1e-13 in float64): keeps a zero
#: column of the scaled Jacobian from making the damped matrix singular.
FLOOR_EPS = 4096.0
#: "Progress": a residual decrease of at least this fraction.
PROGRESS = 0.9


def all_finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)



def per_lane(tree, flag):
    """``tree`` unchanged in value, each leaf made to depend on ``flag`` (a bool computed from
    the sample's inputs).  For the initial state of a ``while_loop``: under ``vmap`` JAX finds
    which loop values are batched by re-tracing the body until that set stops growing, so a
    state that is per sample from the start is traced one time fewer (per ``vmap`` level, and
    a loop inside a loop multiplies that); XLA folds ``select(c, x, x)`` away."""
    return jax.tree_util.tree_map(lambda x: where(flag, x, x), tree)


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


# --------------------------------------------------------------------------- the kernel
class NewtonState(NamedTuple):
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
    on: jax.Array  # whether the best iterate is on the requested branch (False before the first)


class NewtonProblem(NamedTuple):
    """What one sample's iterations need besides their state: the scaled evaluation
    ``evaluate(q) -> (Phi / R, d(Phi / R)/dz)``, the coordinate scales ``s``, the branch test
    ``same_branch(q, jac)``, the block order of the Jacobian, the step cap (scaled; may be
    traced) and the tolerances.  Not a pytree: it is closed over by the loop body."""

    evaluate: object
    s: jax.Array
    same_branch: object
    order: tuple
    cap: object
    xtol: float
    ftol: float
    opts: SolverOptions


def damped_solve(a, r, mu):
    """One solve: the Newton step ``a dz = r`` where ``mu == 0``, else the Levenberg-Marquardt
    step ``(a'a + mu (diag(a'a) + floor I)) dz = a' r`` (``floor``: ``FLOOR_EPS`` eps)."""
    dtype = a.dtype
    floor = FLOOR_EPS * float(jnp.finfo(dtype).eps)
    lm = mu > 0
    ata = small_tmatmul(a, a)
    eye_b = jnp.eye(a.shape[0], dtype=dtype)
    return solve_small(where(lm, ata + mu * (ata * eye_b + floor * eye_b), a), where(lm, small_tmatmul(a, r), r))


def capped_step(order, js, r, mu, cap):
    """``(dz, size)``: the damped scaled step for the scaled Jacobian ``js`` and residual ``r``,
    solved block by block along ``order`` (``structure.blocks``), scaled down to a max-norm
    of ``cap``; ``size`` is its max-norm before the cap (0 where the solve was not finite)."""
    dtype, m = js.dtype, js.shape[0]
    tiny = float(jnp.finfo(dtype).tiny)
    if len(order) == 1:
        dz = damped_solve(js, r, mu)
    else:
        # Block-triangular Jacobian (structure.py): the step block by block, each block's
        # right-hand side less the earlier blocks' share; with mu = 0 this is the Newton
        # step exactly, with mu > 0 each block is damped as Levenberg-Marquardt.
        x: dict = {}
        e, rs = entries(js), parts(r, 0)
        for rows, cols in order:
            rhs = jnp.stack([rs[i] - sum((e[i][j] * xj for j, xj in x.items()), jnp.zeros((), dtype)) for i in rows])
            sub = jnp.stack([jnp.stack([e[i][j] for j in cols]) for i in rows])
            xb = damped_solve(sub, rhs, mu)
            x.update(zip(cols, parts(xb, 0)))
        dz = jnp.stack([x[j] for j in range(m)])
    dz = where(jnp.all(jnp.isfinite(dz)), dz, jnp.zeros_like(dz))
    size = small_max(jnp.abs(dz))
    # Cap the step: far from a root a Newton step can leap onto another branch.
    return dz * jnp.minimum(1.0, cap / jnp.maximum(size, tiny)), size


def newton_iteration(pb: NewtonProblem, st: NewtonState) -> NewtonState:
    """One iteration: evaluate the trial point ``q - dz s``; accept it if it lowers the
    residual (or closes it) without leaving the branch, and adapt ``mu``: down on
    acceptance, up on refusal; lift the branch guard once if the residual stalls after the
    guard refused a better step; then the next damped step from the best iterate."""
    qt = st.q - st.dz * pb.s
    rt, jt = pb.evaluate(qt)
    rtn = small_norm(rt)
    better = jnp.isfinite(rtn) & ((rtn < st.rn) | (rtn <= pb.ftol))
    # A best iterate off the branch (the guess, before any is evaluated) moves freely.
    on_t = pb.same_branch(qt, jt)
    on_b = on_t | ~st.guard | ~st.on
    crossed = st.crossed | (better & ~on_b)
    accept = better & on_b
    q, r, rn, js = jax.tree_util.tree_map(lambda a, b: where(accept, a, b), (qt, rt, rtn, jt), (st.q, st.r, st.rn, st.js))
    mu = where(accept, where(st.mu > MU_NEWTON, st.mu / MU_DECREASE, 0.0), jnp.maximum(MU_INCREASE * st.mu, MU_START))
    # Steps refused only for crossing the branch are not lack of progress: the damping
    # is still shortening them towards this branch's root.
    slow = where(accept & (rtn < PROGRESS * st.rn), 0, where(better & ~on_b, st.slow, st.slow + 1))
    stalled = (slow >= pb.opts.patience) | (mu > MU_STALL * jnp.maximum(small_max(jnp.sum(js * js, axis=0)), 1.0))
    lift = stalled & st.guard & crossed
    mu = where(lift, 0.0, mu)
    slow = where(lift, 0, slow)
    stalled = stalled & ~lift
    dz, size = capped_step(pb.order, js, r, mu, pb.cap)
    converged = (size <= pb.xtol) & (rn <= pb.ftol)
    done = converged | stalled | ~jnp.isfinite(rn)
    return NewtonState(st.k + 1, q, r, rn, js, dz, size, mu, slow, done, stalled, st.guard & ~lift, crossed, where(accept, on_t, st.on))


def newton_status(pb: NewtonProblem, st: NewtonState, inputs_ok, cond_max):
    """``(q, status, cond)`` of a finished loop: the last (free) Newton step taken where
    converged, and the status.

    Near a toggle the attainable accuracy of q is about cond * eps, not xtol: a closed
    residual whose next step is within that is converged (the band above cond_max is
    SINGULAR), so below the band the status does not hang on round-off or on the units.
    """
    cond = cond1(st.js, pb.order)
    eps = float(jnp.finfo(st.q.dtype).eps)
    converged = (st.size <= jnp.maximum(pb.xtol, 8.0 * eps * jnp.minimum(cond, cond_max))) & (st.rn <= pb.ftol)
    q = where(converged, st.q - st.dz * pb.s, st.q)  # the last Newton step is free: it was computed already
    finite = inputs_ok & jnp.isfinite(st.rn) & jnp.all(jnp.isfinite(q))
    closed = st.rn <= pb.ftol
    status = where(
        ~finite,
        Status.NONFINITE,
        where(
            closed & ((cond > cond_max) | ~converged),
            Status.SINGULAR,
            where(converged, Status.CONVERGED, where(st.stalled, Status.INFEASIBLE, Status.MAX_STEPS)),
        ),
    ).astype(jnp.int32)
    return q, status, cond


def newton(mech: Mechanism, opts: SolverOptions, u, p, guess, target=None, max_step=None, skip=None, inputs_finite: bool = False,
           budget=None) -> Solution:
    """Damped Newton / Levenberg-Marquardt for one sample (no gradients): the one kernel that
    serves single solves, stroke anchors and every stroke point.

    Work is in scaled variables: ``z = q / s`` with ``s`` = 1 for angles and the design's
    length scale ``L`` for lengths, residual ``Phi / R`` (``R = L`` for loop closures, or the
    mechanism's ``residual_scale``).  Each iteration (``newton_iteration``) evaluates the
    residual and Jacobian once (at the trial point; the first iteration at the guess) and
    solves one small system: the Newton step while steps lower ``|Phi|``, else the
    Levenberg-Marquardt step with parameter ``mu`` (the ``MU_*`` constants), which makes
    far-off guesses safe without costing the quadratic convergence near a root.  A step
    that leaves the requested branch (``target``: the signs of the branch indicator, by
    default the guess's) is refused like one that raises the residual, so the damping finds
    the root on that branch; if the residual then stalls, the guard is lifted once: a root
    found across is ``BRANCH``, none found ``INFEASIBLE``.  A guess off the requested branch
    may move freely until it reaches it.

    ``max_step`` (may be traced) overrides ``opts.max_step``, ``budget`` (may be traced)
    ``opts.max_iterations``; ``skip`` (traced bool) runs no iteration at all (under ``vmap``, a lane whose answer is not wanted then costs nothing).
    ``inputs_finite``: the caller has replaced non-finite inputs and parameters already (a
    stroke does, once per design), so only the guess is checked here.  A check of every
    parameter is a chain of ``is-finite`` tests that XLA's CPU fusion copies into each
    consumer: for flap_msd's 29 parameters, a thousand of the stroke program's instructions.

    Returns the root record, a ``Solution`` for one sample (without coordinate names); its
    ``q`` is the last iterate (not masked: NaN-free only where the status says so), its
    ``residual`` the scaled residual's 2-norm at that iterate's predecessor, its ``cond`` the
    scaled Jacobian's 1-norm condition number there.  A closed
    residual (``<= ftol``) whose step cannot meet ``xtol`` means the Jacobian is (nearly)
    singular at an existing pose: ``SINGULAR``, whatever the units.
    """
    dtype = guess.dtype
    xtol, ftol, cond_max = tolerances(opts, dtype)
    evaluate, s = evaluator(mech, u, p, dtype)
    m = mech.m
    branched = has_branch(mech)
    b_guess = (jnp.sign(branch_value(mech, guess, u, p)) if target is None else target) if branched else None

    def same_branch(q, jac):
        return on_branch(b_guess, branch_value(mech, q, u, p, jac)) if branched else jnp.asarray(True)

    pb = NewtonProblem(evaluate, s, same_branch, blocks(mech), opts.max_step if max_step is None else max_step, xtol, ftol, opts)
    inputs_ok = all_finite(guess) if inputs_finite else all_finite((u, p, guess))
    zero = jnp.zeros((), dtype)
    init = NewtonState(
        k=jnp.zeros((), jnp.int32), q=guess, r=jnp.zeros((m,), dtype), rn=jnp.asarray(jnp.inf, dtype), js=jnp.eye(m, dtype=dtype),
        dz=jnp.zeros((m,), dtype), size=zero, mu=zero, slow=jnp.zeros((), jnp.int32), done=~inputs_ok if skip is None else ~inputs_ok | skip,
        stalled=jnp.asarray(False), guard=jnp.asarray(True), crossed=jnp.asarray(False), on=jnp.asarray(False),
    )
    budget = opts.max_iterations if budget is None else budget
    st = jax.lax.while_loop(lambda st: (~st.done) & (st.k < budget + 1), functools.partial(newton_iteration, pb), per_lane(init, inputs_ok))
    q, status, cond = newton_status(pb, st, inputs_ok, cond_max)
    if branched:
        # The blocks' determinants from the Jacobian of the last evaluated iterate (at most
        # one xtol step from q: a sign that differs there is a singular pose): a Jacobian
        # evaluated again at q was half of this kernel's program (six-bar: 663 of 1396 eqns).
        branch = branch_value(mech, q, u, p, st.js)
        status = where((status == Status.CONVERGED) & ~on_branch(b_guess, branch), Status.BRANCH, status).astype(jnp.int32)
        flipped = where(status == Status.BRANCH, flipped_mask(b_guess, branch), 0)
    else:
        branch = jnp.asarray(jnp.nan, dtype)
        flipped = jnp.zeros((), jnp.int32)
    return Solution(q=q, status=status, steps=jnp.maximum(st.k - 1, 0), residual=st.rn, cond=cond, branch=branch, flipped=flipped)
