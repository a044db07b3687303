"""Sequential quadratic programming with exact second derivatives, in JAX, one start per lane
of a vmapped program (``queue``: more starts than lanes, each lane taking the next start).

The problem, in scaled variables ``x`` (``n`` of them)::

    min f(x)   s.t.   h(x) = 0  (p equalities),   g(x) <= 0  (m inequalities, box rows included)

Each iteration solves the quadratic model at the iterate ``x`` with the multipliers
``(y, z)`` of the last step::

    min  1/2 d' B d + grad f' d    s.t.   h + J_h d = 0,   g + J_g d <= 0

by ``design.qp`` (a convex QP: Mehrotra's interior point), where ``B`` is the exact Hessian
of the Lagrangian ``W = Hess(f + y.h + z.g)`` (forward over reverse mode, through the
implicit rule of every position solve: ``design.stroke_problem`` or ``nlp.second_order``)
made positive definite: ``B = W + rho J_A' J_A + delta I``, with ``J_A`` the equalities and
the inequalities whose multiplier is positive (curvature the constraints already fix:
on the active constraints' null space ``B = W``, so the step is Newton's and the local
convergence quadratic) and ``delta`` the smallest of a few shifts that lets ``B`` be
factorised by Cholesky.

The step is taken with a backtracking line search on the exact penalty
``phi = f + nu (|h|_1 + |max(g, 0)|_1)`` (``nu`` above the multipliers' largest size), with
up to ``max_soc`` second-order corrections when the full step is refused (the Maratos
effect: a full step that the penalty refuses only because of the constraints' curvature is
corrected by one more QP with the constraint values at the trial point), and a damping
``lm I`` added to ``B`` that acts as a trust region's radius (``_damping``).  **A trial design that cannot be
evaluated (a position that does not assemble) has an infinite penalty: the line search
itself backs off** (no made-up violation reaches the model).

A start ends when IPOPT's scaled KKT residual ``E_0`` (dual residual over ``s_d``, primal
infeasibility, complementarity ``|z_i g_i|`` over ``s_c``) is at most ``tol``, or says why
not (``Status``).  The loop evaluates the problem once per iteration at one call site, so
the compiled program holds one copy of the problem and its derivatives, and one QP solve.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.linalg import where
from ..solver.newton import per_lane
from ..solver.status import Status
from .nlp import Evaluation, cholesky_small, kkt_error
from .qp import solve_qp

__all__ = ["SQPOptions", "sqp", "queue", "iteration", "running", "merit"]


@dataclasses.dataclass(frozen=True)
class SQPOptions:
    """Settings (static: part of the compiled program).

    - `tol`: scaled KKT residual that ends a start; `s_max`: IPOPT's scaling threshold.
    - `max_iter`: iterations per start (each one evaluation); `max_backtrack`: halvings
      of one step.
    - `eta`: the line search's sufficient decrease (Armijo) factor.
    - `active`: an inequality is active in ``B``'s convexification when its multiplier
      exceeds ``active`` times the largest one.
    - `max_soc`: second-order corrections tried for one direction (IPOPT's ``max_soc``).
    """

    tol: float = 1e-8
    s_max: float = 100.0
    max_iter: int = 500
    max_backtrack: int = 30
    eta: float = 1e-4
    active: float = 1e-6
    max_soc: int = 4


class SQPState(NamedTuple):
    """One start's accepted iterate: the point `x` with the multipliers `y`, `z` its
    derivatives were taken with, the problem there (`f`, `c` = h then g, `grad`, `jac`,
    `hess`), its KKT residual `error`, the penalty `nu`, `k` iterations, `status`, `done`."""

    k: jax.Array
    x: jax.Array
    y: jax.Array
    z: jax.Array
    f: jax.Array
    c: jax.Array
    grad: jax.Array
    jac: jax.Array
    hess: jax.Array
    error: jax.Array
    nu: jax.Array
    status: jax.Array
    done: jax.Array


class SQPLoop(NamedTuple):
    """The loop's state: the accepted iterate `st`, and what is evaluated next: the point
    `xt` with multipliers `yt`, `zt` (the start, or the trial ``x + alpha d``, or the
    `soc`-th second-order correction of ``x + d``), the damping `lm` the step was solved
    with, the penalty `phi0` at `st`, its slope `dphi` along `d` and the model's predicted
    decrease `pred`, `backtracks` (refused trials in a row); `phase` 0 while the start cannot be
    evaluated (it is moved halfway to the reference, `pulled` times)."""

    st: SQPState
    phase: jax.Array
    pulled: jax.Array
    xt: jax.Array
    yt: jax.Array
    zt: jax.Array
    d: jax.Array
    alpha: jax.Array
    lm: jax.Array
    soc: jax.Array  # second-order corrections of the current direction so far
    phi0: jax.Array
    dphi: jax.Array
    pred: jax.Array
    backtracks: jax.Array


#: Shifts tried (times the Hessian's scale), the smallest first; for each, the weights of
#: the convexification tried (times ``rho0``, the Hessian's scale over the active rows'
#: largest squared norm), the smallest first.  The first pair whose ``B`` has a Cholesky
#: factor is used: curvature the active constraints fix is convexified by ``rho``; only
#: negative curvature left on their null space costs a shift.
_SHIFTS = (0.0,) + tuple(1e-10 * 10.0**k for k in range(14))
_RHOS = tuple(10.0**k for k in range(0, 10, 2))


def modified_hessian(hess, jac, z, p: int, active: float):
    """``(B, ok)``: ``B = W + rho J_A' J_A + delta I`` (module docstring), ``ok`` False if
    no tried pair gave a Cholesky factor."""
    n = hess.shape[0]
    scale = jnp.maximum(jnp.max(jnp.abs(jnp.diagonal(hess))), 1.0)
    on = jnp.concatenate([jnp.ones((p,), bool), z > active * jnp.maximum(jnp.max(z, initial=0.0), 1e-300)])
    ja = jac * on[:, None]
    jtj = ja.T @ ja
    rho0 = scale / jnp.maximum(jnp.max(jnp.diagonal(jtj)), 1e-300)
    eye = jnp.eye(n, dtype=hess.dtype)
    grid = [(d, r) for d in _SHIFTS for r in _RHOS]
    deltas = jnp.asarray([d for d, _ in grid], hess.dtype) * scale
    rhos = jnp.asarray([r for _, r in grid], hess.dtype) * rho0

    def candidate(k):
        return hess + rhos[k] * jtj + deltas[k] * eye

    def unfit(c):
        k, ok = c
        return ~ok & (k < len(grid))

    def next_pair(c):
        k, _ = c
        return k + 1, cholesky_small(candidate(k))[1]

    k, ok = jax.lax.while_loop(unfit, next_pair, (jnp.zeros((), jnp.int32), jnp.asarray(False)))
    return candidate(jnp.maximum(k - 1, 0)), ok


def merit(f, c, nu, p: int):
    """The exact penalty ``f + nu (|h|_1 + |max(g, 0)|_1)``."""
    return f + nu * (jnp.sum(jnp.abs(c[:p])) + jnp.sum(jnp.maximum(c[p:], 0.0)))


def _violation(c, p: int):
    return jnp.sum(jnp.abs(c[:p])) + jnp.sum(jnp.maximum(c[p:], 0.0))


def _kkt(st: SQPState, p: int, o: SQPOptions):
    # slacks -g where feasible: the complementarity is |z_i g_i|
    s = jnp.maximum(-st.c[p:], 0.0)
    return kkt_error(st.grad, st.jac, st.y, st.z, s, st.c, p, 0.0, o.s_max)


def initial_loop(x0, y0, z0, p: int, m: int) -> SQPLoop:
    """The loop before the first evaluation: `x0` to be evaluated with multipliers
    ``(y0, z0)`` (their Hessian is the first step's model)."""
    dtype, n = x0.dtype, x0.shape[0]
    nan = jnp.asarray(jnp.nan, dtype)
    zero_i = jnp.zeros((), jnp.int32)
    st = SQPState(k=zero_i, x=x0, y=y0, z=z0, f=nan, c=jnp.full((p + m,), nan), grad=jnp.zeros((n,), dtype),
                  jac=jnp.zeros((p + m, n), dtype), hess=jnp.zeros((n, n), dtype), error=jnp.asarray(jnp.inf, dtype),
                  nu=jnp.asarray(1.0, dtype), status=jnp.asarray(Status.MAX_STEPS, jnp.int32), done=jnp.asarray(False))
    return SQPLoop(st=st, phase=zero_i, pulled=zero_i, xt=x0, yt=y0, zt=z0, d=jnp.zeros((n,), dtype), alpha=jnp.ones((), dtype), lm=jnp.zeros((), dtype),
                   soc=zero_i, phi0=nan, dphi=nan, pred=nan, backtracks=zero_i)


class _Judged(NamedTuple):
    st: SQPState  # the iterate after judging the evaluated point
    accept: jax.Array
    start_bad: jax.Array
    ok: jax.Array


def judge(lp: SQPLoop, ev: Evaluation, p: int, o: SQPOptions, prepare=None) -> _Judged:
    """Accept the evaluated point (a start that evaluates; a trial that passes Armijo on
    the penalty, with room for its round-off) or not, and the iterate's KKT residual.  A
    start that evaluates is first given to ``prepare(x, ev) -> (x, ev)`` (an epigraph
    variable set just above the peaks, with the constraint values that follow)."""
    st = lp.st
    start = lp.phase == 0
    if prepare is not None:
        xp, evp = prepare(lp.xt, ev)
        lp = lp._replace(xt=where(start, xp, lp.xt))
        ev = jax.tree_util.tree_map(lambda a, b: where(start, a, b), evp, ev)
    trial_phi = merit(ev.f, ev.c, st.nu, p)
    slack = 10.0 * float(jnp.finfo(lp.xt.dtype).eps) * jnp.abs(lp.phi0)
    armijo = trial_phi <= lp.phi0 + o.eta * lp.alpha * jnp.minimum(lp.dphi, 0.0) + slack
    # a step whose predicted decrease is at the penalty's round-off: the KKT test decides
    noise = jnp.abs(lp.dphi) <= 100.0 * float(jnp.finfo(lp.xt.dtype).eps) * jnp.maximum(jnp.abs(lp.phi0), 1.0)
    good = ~start & ev.ok & (armijo | noise)
    accept = good | (start & ev.ok)
    new = st._replace(x=lp.xt, y=lp.yt, z=lp.zt, f=ev.f, c=ev.c, grad=ev.grad, jac=ev.jac, hess=ev.hess)
    new = new._replace(error=_kkt(new, p, o))
    cur = jax.tree_util.tree_map(lambda a, b: where(accept, a, b), new, st)
    cur = cur._replace(k=where(start, st.k, st.k + 1))
    return _Judged(cur, accept, start & ~ev.ok, ev.ok), ev


def _damping(lp: SQPLoop, j: _Judged, ev: Evaluation, scale, p: int):
    """The damping of the next direction, as a trust region's radius.  After a full step
    (or its correction) accepted, by the ratio ``r`` of the penalty's actual to predicted
    decrease: ``r > 3/4`` a third (none once negligible), ``r < 1/4`` twice; after a step
    accepted only once shortened to ``alpha``, ``2 / alpha`` times (at least ``1e-4`` of
    the Hessian's scale): the next step is then about as long as the one that worked."""
    actual = lp.phi0 - merit(ev.f, ev.c, lp.st.nu, p)
    r = actual / jnp.maximum(lp.pred, 1e-300)
    down = jnp.where(lp.lm > 1e-10 * scale, lp.lm / 3.0, 0.0)
    full = where(r > 0.75, down, where(r < 0.25, jnp.maximum(2.0 * lp.lm, 1e-4 * scale), lp.lm))
    short = jnp.maximum(2.0 * lp.lm / lp.alpha, 1e-4 * scale)
    return where(j.accept, where(lp.alpha >= 1.0, full, short), lp.lm)


def step(lp: SQPLoop, j: _Judged, ev: Evaluation, ref, p: int, o: SQPOptions) -> SQPLoop:
    """The point to evaluate next, and the start's status.

    After an accepted point: the QP step from it, in full.  After a refused full step that
    evaluated: a second-order correction (the same QP with the constraint values at the
    trial, less their linear change along the trial's step), up to ``max_soc`` in a row.
    After any other refusal (the corrections refused too, or a design that does not
    assemble): the step halved.  The damping of the next direction follows how far the
    accepted steps reach (``_damping``)."""
    cur = j.st
    jh, jg = cur.jac[:p], cur.jac[p:]
    use_soc = ~j.accept & (lp.alpha >= 1.0) & (lp.soc < o.max_soc) & j.ok & (lp.phase == 1)
    scale = jnp.maximum(jnp.max(jnp.abs(jnp.diagonal(cur.hess))), 1.0)
    lm = _damping(lp, j, ev, scale, p)
    # the QP: at the iterate, or (second-order correction) with the trial's constraint values
    c_qp = where(use_soc, ev.c - cur.jac @ (lp.xt - cur.x), cur.c)
    B, b_ok = modified_hessian(cur.hess, cur.jac, cur.z, p, o.active)
    B = B + lm * jnp.eye(B.shape[0], dtype=B.dtype)
    qp = solve_qp(B, cur.grad, jh, c_qp[:p], jg, c_qp[p:])
    nu = where(j.accept, 1.1 * jnp.max(jnp.abs(jnp.concatenate([qp.y, qp.z])), initial=0.0) + 1e-8, cur.nu)
    finite = jnp.all(jnp.isfinite(qp.d))
    converged = j.accept & (cur.error <= o.tol)
    backtracks = where(j.accept, 0, lp.backtracks + 1)
    small = ~j.accept & (backtracks >= o.max_backtrack) & (lp.phase == 1)
    give_up = j.start_bad & (lp.pulled >= 20)
    bad = ~(finite & b_ok) & ~converged & (j.accept | use_soc)
    status = where(converged, Status.CONVERGED, where(give_up, Status.INFEASIBLE,
                   where(bad, Status.NONFINITE, where(small, Status.SMALL_STEP, Status.MAX_STEPS))))
    done = converged | give_up | bad | small
    cur = cur._replace(nu=nu, status=status.astype(jnp.int32), done=done)
    fresh = j.accept | (lp.phase == 0)
    d = where(fresh, qp.d, lp.d)
    alpha = where(fresh | use_soc, 1.0, jnp.where(lp.soc > 0, 0.5, 0.5 * lp.alpha))
    phi0 = where(j.accept, merit(cur.f, cur.c, nu, p), lp.phi0)
    dphi = where(fresh, cur.grad @ qp.d - nu * _violation(cur.c, p), lp.dphi)
    pred = where(fresh, -(dphi + 0.5 * qp.d @ (B @ qp.d)), lp.pred)
    xt = where(j.start_bad, 0.5 * (lp.xt + ref), where(use_soc, cur.x + qp.d, cur.x + alpha * d))
    yt = where(fresh, qp.y, lp.yt)
    zt = where(fresh, jnp.maximum(qp.z, 0.0), lp.zt)
    return SQPLoop(st=cur, phase=where(j.start_bad, 0, 1).astype(jnp.int32), pulled=lp.pulled + j.start_bad.astype(jnp.int32),
                   xt=xt, yt=yt, zt=zt, d=d, alpha=alpha, lm=lm, soc=where(use_soc, lp.soc + 1, 0).astype(jnp.int32), phi0=phi0,
                   dphi=dphi, pred=pred, backtracks=backtracks)


def iteration(evaluate, lp: SQPLoop, ref, p: int, o: SQPOptions, prepare=None) -> SQPLoop:
    """One iteration of one start: evaluate the point ``lp.xt`` (one call site of the
    problem), judge it (``judge``), and choose what to evaluate next (``step``)."""
    ev = Evaluation(*evaluate(lp.xt, lp.yt, lp.zt))
    j, ev = judge(lp, ev, p, o, prepare)
    return step(lp, j, ev, ref, p, o)


def running(lp: SQPLoop, o: SQPOptions):
    """Whether a start still iterates (not done, iterations left)."""
    return ~lp.st.done & (lp.st.k < o.max_iter)


def sqp(evaluate, x0, y0, z0, options: SQPOptions = SQPOptions(), ref=None, prepare=None):
    """Solve one start (vmap it for a batch, or ``queue`` many).  `evaluate(x, y, z) ->
    Evaluation` as ``nlp.second_order`` or ``stroke_problem`` give it; `x0` ``(n,)``; `y0`
    ``(p,)``, `z0` ``(m,)`` the multipliers whose Lagrangian Hessian models the first step
    (for an epigraph statement: ``1/N`` on each of its ``N`` peak rows, which the
    objective's stationarity in ``t`` asks to sum to one).  A start that cannot be evaluated
    is moved halfway towards `ref` (at most 20 times); one that evaluates goes through
    `prepare` (``judge``).

    Returns ``(SQPState, pulled)``."""
    ref = x0 if ref is None else ref
    p = y0.shape[0]
    # every loop value depends on the start from the outset: under vmap the loop's body is
    # traced once, not once more per value found to be batched (see newton.per_lane)
    init = per_lane(initial_loop(x0, y0, z0, p, z0.shape[0]), jnp.all(jnp.isfinite(x0)))
    out = jax.lax.while_loop(lambda lp: running(lp, options), lambda lp: iteration(evaluate, lp, ref, p, options, prepare), init)
    return out.st, out.pulled


class _Queue(NamedTuple):
    lanes: SQPLoop  # (L, ...) the starts being solved
    start: jax.Array  # (L,) which start each lane holds; S: idle
    taken: jax.Array  # starts handed out so far
    out: SQPState  # (S, ...) finished starts
    pulled: jax.Array  # (S,)


def queue(evaluate, x0, y0, z0, lanes: int, options: SQPOptions = SQPOptions(), ref=None, prepare=None):
    """Solve ``S`` starts (``x0 (S, n)``; `y0`, `z0` one start's, as ``sqp``) on `lanes`
    lanes of one vmapped loop: a lane whose start ends writes it out and takes the next
    one.  A vmapped batch of ``sqp`` iterates every start as long as the slowest; here the
    lanes stay busy, so the work is the starts' iterations added up (over `lanes`), plus
    the last start's tail.  `ref` ``(n,)``: the reference for starts that do not evaluate
    (default: the first start).  Returns ``(SQPState, pulled)`` with ``(S,)`` in front, in
    the starts' order."""
    o = options
    S, L = x0.shape[0], min(lanes, x0.shape[0])
    p = y0.shape[0]
    ref = x0[0] if ref is None else ref

    def fresh(i):
        xi = x0[jnp.minimum(i, S - 1)]
        return per_lane(initial_loop(xi, y0, z0, p, z0.shape[0]), jnp.all(jnp.isfinite(xi)))

    init_lanes = jax.vmap(fresh)(jnp.arange(L))
    one = jax.tree_util.tree_map(lambda a: a[0], init_lanes.st)
    out = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (S,) + a.shape), one)
    q0 = _Queue(init_lanes, jnp.arange(L), jnp.asarray(L), out, jnp.zeros((S,), jnp.int32))

    def body(q: _Queue) -> _Queue:
        lanes_ = jax.vmap(lambda lp: iteration(evaluate, lp, ref, p, o, prepare))(q.lanes)
        ended = ~jax.vmap(lambda lp: running(lp, o))(lanes_) & (q.start < S)
        slot = jnp.where(ended, q.start, S)  # S: written nowhere
        out = jax.tree_util.tree_map(lambda a, v: a.at[slot].set(v, mode="drop"), q.out, lanes_.st)
        pulled = q.pulled.at[slot].set(lanes_.pulled, mode="drop")
        nxt = q.taken + jnp.cumsum(ended) - 1
        start = jnp.where(ended, jnp.where(nxt < S, nxt, S), q.start)
        new = jax.vmap(fresh)(start)
        lanes_ = jax.tree_util.tree_map(lambda a, b: jnp.where(ended.reshape((L,) + (1,) * (a.ndim - 1)), a, b), new, lanes_)
        return _Queue(lanes_, start, q.taken + jnp.sum(ended), out, pulled)

    q = jax.lax.while_loop(lambda q: jnp.any(q.start < S), body, q0)
    return q.out, q.pulled
