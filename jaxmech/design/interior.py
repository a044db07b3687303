"""A primal-dual interior-point method with exact second derivatives, written in JAX so that
many starts run as one vmapped program.

The problem, in scaled variables ``x`` (``n`` of them)::

    min f(x)   s.t.   h(x) = 0  (p equalities),   g(x) <= 0  (m inequalities, box rows included)

With slacks ``g + s = 0, s > 0`` and multipliers ``y`` (equalities), ``z > 0``
(inequalities), the barrier problem's optimality conditions are

    r_d = grad f + J_h' y + J_g' z = 0,   h = 0,   g + s = 0,   s_i z_i = mu .

One Newton step on them, with ``W`` the Hessian of the Lagrangian ``f + y.h + z.g`` (exact:
forward over reverse mode, through the implicit rule of every position solve) and
``Sigma = Z / S``, eliminates ``ds`` and ``dz``::

    [ W + J_g' Sigma J_g + delta I   J_h' ] [dx]   [ -r_d - J_g' (Sigma g + mu / s) ]
    [ J_h                             0   ] [dy] = [ -h                             ]
    dz = Sigma (J_g dx + g) + mu / s ,     ds = -(g + s) - J_g dx .

``delta`` is the smallest of a few shifts that makes the top-left block positive definite
(its Cholesky factor exists), which gives the step the inertia of a descent direction; the
equalities are eliminated by a Schur complement.  Steps keep ``s, z`` inside their bounds
(fraction to the boundary, ``tau``), and a backtracking line search on the merit function
``f - mu sum log s + nu (|h|_1 + |g + s|_1)`` shortens the primal step; **a trial design
that cannot be evaluated (a position that does not assemble) counts as an infinite merit,
so the line search itself backs off from it** (no made-up violation reaches the model).
The barrier parameter falls (``mu <- max(tol / 10, min(0.2 mu, mu^1.5))``) once the barrier
problem is solved to ``10 mu``.  A start ends when the scaled KKT residual (IPOPT's ``E_0``:
dual residual over ``s_d``, primal infeasibility, complementarity over ``s_c``) is at most
``tol``, or says why not (``status``).
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..linalg import parts, solve_small, where

__all__ = ["IPStatus", "IPOptions", "IPState", "Evaluation", "NewtonStep", "IPLoop", "Accepted", "Direction", "second_order",
           "initial_loop", "accept_trial", "newton_direction", "next_loop", "interior_point", "cholesky_small", "kkt_error"]


class IPStatus(enum.IntEnum):
    """How a start ended."""

    CONVERGED = 0  #: scaled KKT residual <= tol
    MAX_ITERATIONS = 1  #: the iteration budget ran out first
    SMALL_STEP = 2  #: the line search could not find an acceptable step
    START_NOT_EVALUATED = 3  #: the start cannot be evaluated (does not assemble)
    NONFINITE = 4  #: a derivative or a step was not finite


IP_MESSAGES = {
    IPStatus.CONVERGED: "converged: scaled KKT residual within tolerance",
    IPStatus.MAX_ITERATIONS: "stopped on the iteration limit before the KKT residual met the tolerance",
    IPStatus.SMALL_STEP: "the line search found no acceptable step (every shorter step failed or did not decrease the merit)",
    IPStatus.START_NOT_EVALUATED: "the start cannot be evaluated (the design does not assemble there)",
    IPStatus.NONFINITE: "a derivative or a step was not finite",
}


@dataclasses.dataclass(frozen=True)
class IPOptions:
    """Settings (static: part of the compiled program).

    - `tol`: scaled KKT residual that ends a start.
    - `max_iter`: Newton iterations per start; `max_backtrack`: halvings per line search.
    - `mu0`: initial barrier parameter; `tau_min`: least fraction-to-boundary factor.
    - `s_max`: IPOPT's scaling threshold for the dual residual and complementarity.
    """

    tol: float = 1e-8
    max_iter: int = 100
    max_backtrack: int = 30
    mu0: float = 0.1
    tau_min: float = 0.99
    s_max: float = 100.0


class Evaluation(NamedTuple):
    """The problem and its derivatives at one point (``second_order``'s ``evaluate``): the
    objective `f`, the constraints `c` (``h`` then ``g``), ``grad f``, the constraints'
    Jacobian `jac` ``(p + m, n)``, the Hessian `hess` of the Lagrangian, and `ok` (finite
    and evaluable).  Unpacks like the 6-tuple it replaces."""

    f: jax.Array
    c: jax.Array
    grad: jax.Array
    jac: jax.Array
    hess: jax.Array
    ok: jax.Array


class NewtonStep(NamedTuple):
    """One step of the condensed Newton system (``_newton_step``): primal `dx`, equality
    and inequality multipliers `dy`, `dz`, slacks `ds`, and `ok` (factorised, finite)."""

    dx: jax.Array
    dy: jax.Array
    dz: jax.Array
    ds: jax.Array
    ok: jax.Array


class IPState(NamedTuple):
    """Loop state of one start."""

    k: jax.Array  # iterations done
    x: jax.Array  # (n,)
    s: jax.Array  # (m,) slacks of g(x) <= 0
    y: jax.Array  # (p,)
    z: jax.Array  # (m,)
    mu: jax.Array
    nu: jax.Array  # merit penalty
    f: jax.Array
    c: jax.Array  # (p + m,) h then g at x
    grad: jax.Array  # (n,)
    jac: jax.Array  # (p + m, n)
    hess: jax.Array  # (n, n) Hessian of the Lagrangian at (x, y, z)
    error: jax.Array  # scaled KKT residual (mu = 0)
    status: jax.Array
    done: jax.Array
    alpha: jax.Array  # the last primal step length (diagnostic)


def second_order(problem: Callable, p: int):
    """``evaluate(x, y, z) -> Evaluation(f, c, grad f, J_c, W, ok)`` from ``problem(x) -> (f, h, g, ok)``
    (``h (p,)``, ``g (m,)``): values, the constraints' Jacobian and the Hessian ``W`` of the
    Lagrangian ``f + y.h + z.g``, by one linearisation of ``x -> (values, grad L)`` (forward
    over reverse mode) with the ``n`` unit tangents at once."""

    def values(x):
        f, h, g, ok = problem(x)
        return jnp.concatenate([jnp.reshape(f, (1,)), h, g]), ok

    def evaluate(x, y, z):
        w = jnp.concatenate([jnp.ones((1,), x.dtype), y, z])

        def both(x_):
            v, ok = values(x_)
            grad_l = jax.grad(lambda x2: jnp.dot(w, values(x2)[0]))(x_)
            return v, grad_l, ok

        (v, grad_l, ok), lin = jax.linearize(lambda x_: both(x_), x)
        tan_v, tan_g, _ = jax.vmap(lin)(jnp.eye(x.shape[0], dtype=x.dtype))
        jac = tan_v.T  # (1 + p + m, n)
        hess = 0.5 * (tan_g + tan_g.T)
        ok = ok & jnp.all(jnp.isfinite(v)) & jnp.all(jnp.isfinite(jac)) & jnp.all(jnp.isfinite(hess))
        return Evaluation(v[0], v[1:], jac[0], jac[1:], hess, ok)

    return evaluate, values


def cholesky_small(a):
    """``(L, ok)``: the Cholesky factor of a small symmetric matrix, a column per step of a
    ``fori_loop`` (compact to compile; no LAPACK call, see ``stored.calls_lapack``); ``ok``
    False where a pivot is not positive (``L`` is then not to be used)."""
    n = a.shape[0]
    rows = jnp.arange(n)

    def column(j, carry):
        L, ok = carry
        lj = L[j]  # row j: its entries left of j are final, the rest zero
        d = a[j, j] - lj @ lj
        ok = ok & (d > 0)
        ljj = jnp.sqrt(jnp.where(d > 0, d, 1.0))
        col = (a[:, j] - L @ lj) / ljj
        col = jnp.where(rows > j, col, jnp.where(rows == j, ljj, 0.0))
        return L.at[:, j].set(col), ok

    return jax.lax.fori_loop(0, n, column, (jnp.zeros_like(a), jnp.asarray(True)))


def _chol_solve(L, b):
    """``(L L') x = b`` for a lower-triangular ``L`` (``b`` of shape ``(n,)`` or ``(n, k)``):
    forward and back substitution, a row per step of a ``fori_loop``."""
    n = L.shape[0]
    vec = b.ndim == 1
    b = b.reshape(n, -1)

    def forward(i, y):
        return y.at[i].set((b[i] - L[i] @ y) / L[i, i])  # rows of y below i are still zero

    def backward(k, x):
        i = n - 1 - k
        return x.at[i].set((y[i] - L[:, i] @ x) / L[i, i])  # entries of x above i are still zero

    y = jax.lax.fori_loop(0, n, forward, jnp.zeros_like(b))
    x = jax.lax.fori_loop(0, n, backward, jnp.zeros_like(b))
    return x[:, 0] if vec else x


#: Shifts tried (times the Hessian's scale) until the reduced matrix is positive definite:
#: none, then growing by 4 from 1e-8 (a coarse grid over-damps the step in a region of
#: negative curvature: a shift 4.6 times the one needed was seen to slow a start tenfold).
_SHIFTS = (0.0,) + tuple(1e-8 * 4.0**k for k in range(26))


def kkt_error(grad, jac, y, z, s, c, p, mu, s_max):
    """IPOPT's scaled optimality error ``E_mu`` (``mu = 0``: of the problem itself)."""
    m = z.shape[0]
    h, g = c[:p], c[p:]
    r_d = grad + jac.T @ jnp.concatenate([y, z])
    s_d = jnp.maximum(s_max, (jnp.sum(jnp.abs(y)) + jnp.sum(jnp.abs(z))) / max(p + m, 1)) / s_max
    s_c = jnp.maximum(s_max, jnp.sum(jnp.abs(z)) / max(m, 1)) / s_max
    primal = jnp.maximum(jnp.max(jnp.abs(h), initial=0.0), jnp.max(jnp.abs(g + s), initial=0.0))
    comp = jnp.max(jnp.abs(s * z - mu), initial=0.0) / s_c
    return jnp.maximum(jnp.maximum(jnp.max(jnp.abs(r_d)) / s_d, primal), comp)


def _newton_step(st: IPState, p: int) -> NewtonStep:
    """The ``NewtonStep`` of the condensed Newton system at ``st`` (module docstring)."""
    n = st.x.shape[0]
    jh, jg = st.jac[:p], st.jac[p:]
    h, g = st.c[:p], st.c[p:]
    sigma = st.z / st.s
    r_d = st.grad + jh.T @ st.y + jg.T @ st.z
    # shifts relative to the Lagrangian's own curvature (Sigma's entries can be 1e10: a
    # shift scaled by them would freeze the step)
    scale = jnp.maximum(jnp.max(jnp.abs(jnp.diagonal(st.hess))), 1.0)
    # rho J_h' J_h added to the top block (and rho J_h' (J_h dx) = -rho J_h' h to its right
    # side) leaves the solution as it is, and makes the block positive definite wherever the
    # Hessian is positive definite on the equalities' null space (Debreu): no shift is then
    # needed for curvature the equalities remove
    jhjh = jh.T @ jh
    rho = 100.0 * scale / jnp.maximum(jnp.max(jnp.abs(jnp.diagonal(jhjh)), initial=0.0), 1e-300) if p else 0.0
    top = st.hess + (jg.T * sigma[None, :]) @ jg + rho * jhjh
    rhs = -r_d - jg.T @ (sigma * g + st.mu / st.s) - rho * (jh.T @ h)
    eye = jnp.eye(n, dtype=st.x.dtype)
    shifts = jnp.asarray(_SHIFTS, st.x.dtype) * scale

    def unfit(c):
        k, _, ok = c
        return ~ok & (k < len(_SHIFTS))

    def next_shift(c):
        k, _, _ = c
        L, ok = cholesky_small(top + shifts[k] * eye)
        return k + 1, L, ok

    # the smallest shift that makes the matrix positive definite (one factorisation site)
    _, L, chol_ok = jax.lax.while_loop(unfit, next_shift, (jnp.zeros((), jnp.int32), jnp.zeros_like(top), jnp.asarray(False)))
    if p:
        # Schur complement: (J_h T^-1 J_h') dy = J_h T^-1 rhs + h,  dx = T^-1 (rhs - J_h' dy)
        t_rhs = _chol_solve(L, rhs)
        t_jh = _chol_solve(L, jh.T)  # (n, p)
        schur = jh @ t_jh
        dy = solve_small(schur, jh @ t_rhs + h)
        dx = t_rhs - t_jh @ dy
    else:
        dy = jnp.zeros((0,), st.x.dtype)
        dx = _chol_solve(L, rhs)
    dz = sigma * (jg @ dx + g) + st.mu / st.s
    ds = -(g + st.s) - jg @ dx
    ok = chol_ok & jnp.all(jnp.isfinite(dx)) & jnp.all(jnp.isfinite(dy)) & jnp.all(jnp.isfinite(dz))
    return NewtonStep(dx, dy, dz, ds, ok)


def _to_boundary(v, dv, tau):
    """Largest ``alpha`` in (0, 1] with ``v + alpha dv >= (1 - tau) v`` (``v > 0``)."""
    ratio = jnp.where(dv < 0, -tau * v / jnp.where(dv < 0, dv, -1.0), jnp.inf)
    return jnp.minimum(1.0, jnp.min(ratio, initial=jnp.inf))


def _merit(f, c, s, mu, nu, p):
    return f - mu * jnp.sum(jnp.log(s)) + nu * (jnp.sum(jnp.abs(c[:p])) + jnp.sum(jnp.abs(c[p:] + s)))


class IPLoop(NamedTuple):
    """State of ``interior_point``'s one loop: the accepted iterate and the point to evaluate
    next (the start, moved or prepared, or a line-search trial along the last step)."""

    st: IPState
    phase: jax.Array  # 0: finding an evaluable start, 1: prepared start, 2: iterating
    pulled: jax.Array  # times the start was moved halfway to `ref`
    xt: jax.Array  # the point evaluated next
    yt: jax.Array
    zt: jax.Array
    st_s: jax.Array  # trial slacks
    dx: jax.Array  # the last Newton step's primal and slack parts
    ds: jax.Array
    phi0: jax.Array  # merit at the accepted point, and its directional derivative
    dphi: jax.Array
    backtracks: jax.Array  # halvings of the current line search


class Accepted(NamedTuple):
    """What one evaluation decided (``accept_trial``): the iterate after it (`state`), and
    the flags the rest of the iteration needs."""

    state: IPState
    ok: jax.Array  # the evaluation is finite and the design assembles
    trial: jax.Array  # the point was a line-search trial (phase 2)
    in_start: jax.Array  # the point was a start (phase 0 or 1)
    ready: jax.Array  # the start is evaluable and prepared: iterations begin from it
    accept: jax.Array  # the point becomes the iterate (a good trial, or a ready start)
    bad_start: jax.Array  # a start that cannot be evaluated
    give_up: jax.Array  # ... and it was moved towards `ref` 20 times already
    x_prep: jax.Array  # the start after ``prepare``
    error: jax.Array  # scaled KKT residual at the point (mu = 0)


class Direction(NamedTuple):
    """The Newton step from the accepted iterate (``newton_direction``): the step, its
    fraction-to-boundary lengths (primal `a_p`, dual `a_d`), the merit penalty `nu`, the
    merit `phi0` and its directional derivative `dphi`."""

    step: NewtonStep
    a_p: jax.Array
    a_d: jax.Array
    nu: jax.Array
    phi0: jax.Array
    dphi: jax.Array


def initial_loop(x0, p: int, m: int, o: IPOptions) -> IPLoop:
    """The loop state before the first evaluation: `x0` to be evaluated as the start, unit
    slacks and inequality multipliers, zero equality multipliers, ``mu = o.mu0``."""
    dtype = x0.dtype
    n = x0.shape[0]
    zeros_m = jnp.zeros((m,), dtype)
    nan = jnp.asarray(jnp.nan, dtype)
    init_state = IPState(k=jnp.zeros((), jnp.int32), x=x0, s=jnp.ones((m,), dtype), y=jnp.zeros((p,), dtype), z=jnp.ones((m,), dtype),
                         mu=jnp.asarray(o.mu0, dtype), nu=jnp.asarray(1.0, dtype), f=nan, c=jnp.full((p + m,), nan),
                         grad=jnp.zeros((n,), dtype), jac=jnp.zeros((p + m, n), dtype), hess=jnp.zeros((n, n), dtype),
                         error=jnp.asarray(jnp.inf, dtype), status=jnp.asarray(IPStatus.MAX_ITERATIONS, jnp.int32),
                         done=jnp.asarray(False), alpha=jnp.zeros((), dtype))
    return IPLoop(st=init_state, phase=jnp.zeros((), jnp.int32), pulled=jnp.zeros((), jnp.int32), xt=x0, yt=init_state.y,
                  zt=init_state.z, st_s=init_state.s, dx=jnp.zeros((n,), dtype), ds=zeros_m, phi0=nan, dphi=nan,
                  backtracks=jnp.zeros((), jnp.int32))


def accept_trial(lp: IPLoop, ev: Evaluation, p: int, o: IPOptions, prepare) -> Accepted:
    """Judge the point just evaluated (`ev` at ``lp.xt``): a start (phases 0 and 1) becomes
    the iterate once it is evaluable and prepared, with slacks and multipliers set from its
    constraints; a trial (phase 2) becomes it when it passes Armijo on the merit.  The
    barrier parameter falls once the barrier problem is solved to ``10 mu``."""
    st = lp.st
    dtype = lp.xt.dtype
    f, c, grad, jac, hess, ok = ev
    # ---- phase 0/1: the start
    in_start = lp.phase < 2
    bad_start = in_start & ~ok
    give_up = bad_start & (lp.pulled >= 20)
    x_prep = lp.xt if prepare is None else prepare(lp.xt, c)
    s0 = jnp.maximum(-c[p:], 1e-2 * jnp.maximum(1.0, jnp.abs(c[p:])))
    s0 = jnp.where(jnp.isfinite(s0), s0, 1.0)
    z0 = st.mu / s0
    ready = in_start & ok & ((lp.phase == 1) | (prepare is None))
    # ---- phase 2: the line search's trial
    trial = lp.phase == 2
    phi = _merit(f, c, lp.st_s, st.mu, st.nu, p)
    alpha = st.alpha
    # Armijo on the merit, with room for its round-off (near the optimum a decrease below
    # 10 eps |phi| cannot be told from noise; IPOPT relaxes its test the same way)
    slack = 10.0 * float(jnp.finfo(dtype).eps) * jnp.abs(lp.phi0)
    good = trial & ok & (phi <= lp.phi0 + 1e-4 * alpha * jnp.minimum(lp.dphi, 0.0) + slack)
    accept = good | ready
    x_new = lp.xt
    s_new = where(ready, s0, jnp.maximum(lp.st_s, 1e-300))
    y_new = where(ready, jnp.zeros((p,), dtype), lp.yt)
    z_new = where(ready, z0, jnp.clip(lp.zt, st.mu / (1e10 * s_new), 1e10 * st.mu / s_new))
    e_mu = kkt_error(grad, jac, y_new, z_new, s_new, c, p, st.mu, o.s_max)
    e_0 = kkt_error(grad, jac, y_new, z_new, s_new, c, p, 0.0, o.s_max)
    mu = where(good & (e_mu <= 10.0 * st.mu), jnp.maximum(o.tol / 10.0, jnp.minimum(0.2 * st.mu, st.mu ** 1.5)), st.mu)
    acc = IPState(k=st.k + trial.astype(jnp.int32), x=x_new, s=s_new, y=y_new, z=z_new, mu=mu, nu=st.nu, f=f, c=c, grad=grad, jac=jac,
                  hess=hess, error=e_0, status=st.status, done=st.done, alpha=where(good, alpha, 0.0))
    cur = jax.tree_util.tree_map(lambda a, b: where(accept, a, b), acc, st)
    return Accepted(state=cur, ok=ok, trial=trial, in_start=in_start, ready=ready, accept=accept, bad_start=bad_start,
                    give_up=give_up, x_prep=x_prep, error=e_0)


def newton_direction(cur: IPState, p: int, o: IPOptions) -> Direction:
    """The next Newton step from the iterate `cur`, the steps to the slacks' and
    multipliers' boundaries, and the merit's penalty, value and slope along the step."""
    step = _newton_step(cur, p)
    dx, dy, dz, ds, _ = step
    tau = jnp.maximum(o.tau_min, 1.0 - cur.mu)
    a_p = _to_boundary(cur.s, ds, tau)
    a_d = _to_boundary(cur.z, dz, tau)
    nu = 1.0 + 1.1 * jnp.max(jnp.abs(jnp.concatenate([cur.y + dy, cur.z + dz])), initial=0.0)
    phi0 = _merit(cur.f, cur.c, cur.s, cur.mu, nu, p)
    dphi = cur.grad @ dx - cur.mu * jnp.sum(ds / cur.s) - nu * (jnp.sum(jnp.abs(cur.c[:p])) + jnp.sum(jnp.abs(cur.c[p:] + cur.s)))
    return Direction(step=step, a_p=a_p, a_d=a_d, nu=nu, phi0=phi0, dphi=dphi)


def next_loop(lp: IPLoop, a: Accepted, d: Direction, ref, o: IPOptions) -> IPLoop:
    """The start's status after this iteration (converged, given up, a non-finite step, a
    line search out of halvings) and the point to evaluate next: the start moved halfway to
    `ref` or prepared, the first trial of a new step, or the last trial's step halved."""
    cur = a.state
    dx, dy, dz, ds, ok_step = d.step
    converged = a.accept & a.ok & (a.error <= o.tol)
    # a rejected trial: halve the step
    backtracks = where(a.accept, 0, lp.backtracks + a.trial.astype(jnp.int32))
    small = a.trial & ~a.accept & (backtracks >= o.max_backtrack)
    half = 0.5 * lp.st.alpha
    status = where(converged, IPStatus.CONVERGED,
                   where(a.give_up, IPStatus.START_NOT_EVALUATED,
                         where(a.accept & ~ok_step, IPStatus.NONFINITE, where(small, IPStatus.SMALL_STEP, IPStatus.MAX_ITERATIONS))))
    done = converged | a.give_up | (a.accept & ~ok_step) | small
    cur = cur._replace(nu=where(a.accept, d.nu, cur.nu), status=status.astype(jnp.int32), done=done, alpha=where(a.accept, d.a_p, half))
    step_alpha = where(a.accept, d.a_p, half)
    # where to evaluate next
    phase = where(a.bad_start, 0, where(a.in_start & a.ok & ~a.ready, 1, 2)).astype(jnp.int32)
    xt_start = where(a.bad_start, 0.5 * (lp.xt + ref), a.x_prep)
    d_x = where(a.accept, dx, lp.dx)
    d_s = where(a.accept, ds, lp.ds)
    xt = where(phase < 2, xt_start, cur.x + step_alpha * d_x)
    st_s = cur.s + step_alpha * d_s
    yt = where(a.accept, cur.y + d.a_d * dy, lp.yt)
    zt = where(a.accept, jnp.maximum(cur.z + d.a_d * dz, 1e-300), lp.zt)
    return IPLoop(st=cur, phase=phase, pulled=lp.pulled + a.bad_start.astype(jnp.int32), xt=xt, yt=yt, zt=zt, st_s=st_s,
                  dx=d_x, ds=d_s, phi0=where(a.accept, d.phi0, lp.phi0), dphi=where(a.accept, d.dphi, lp.dphi), backtracks=backtracks)


def interior_point(evaluate, x0, p: int, m: int, options: IPOptions = IPOptions(), ref=None, prepare=None):
    """Solve one start (vmap it for a batch).  `evaluate` as ``second_order`` gives it; `x0`
    ``(n,)``; `p`, `m` the numbers of equalities and inequalities (``c`` = h then g).

    The loop evaluates the problem at one point per iteration, at ONE call site (a compiled
    program holds one copy of the problem and its derivatives): the start (moved halfway to
    `ref` while it cannot be evaluated, at most 20 times; then ``prepare(x, c) -> x`` once, e.g.
    an epigraph variable set above the peaks, and evaluated again), then each line-search
    trial, whose derivatives serve the next Newton step when it is accepted.  One iteration
    is three stages: ``accept_trial``, ``newton_direction``, ``next_loop``.

    Returns ``(IPState, pulled)``: the final state (``status``: ``IPStatus``) and how many
    times the start was moved towards `ref`."""
    o = options
    ref = x0 if ref is None else ref

    def cond(lp: IPLoop):
        return ~lp.st.done & (lp.st.k < o.max_iter)

    def body(lp: IPLoop) -> IPLoop:
        a = accept_trial(lp, Evaluation(*evaluate(lp.xt, lp.yt, lp.zt)), p, o, prepare)
        return next_loop(lp, a, newton_direction(a.state, p, o), ref, o)

    out = jax.lax.while_loop(cond, body, initial_loop(x0, p, m, o))
    return out.st, out.pulled
