"""The implicit Runge-Kutta steps of forward dynamics: ``y' = f(t, y)`` in the inputs
(``rhs``: ``M(u) u_ddot + h(u, u_dot, t) = tau``, the loop closed at every evaluation),
the stage equations solved by simplified Newton and attached to their arguments by an
implicit-function custom JVP, one step after another in a scan (``integrate_chunk``,
``integrate``).  The run around them (``forward_dynamics``, ``Trajectory``) is in
``forward``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.linalg import solve_small
from ..solver.implicit import implicit_positions, implicit_solution
from ..mechanism.mechanism import Vars
from ..solver.options import SolverOptions
from .closure import close_loop
from .forward_friction import friction_accelerations
from .model import Model
from ..solver.status import Status
from .virtual_power import generalized_forces, mass_matrix

__all__ = ["METHODS", "Integrator", "newton_tolerance", "rhs", "coordinate_rates", "stage_residual", "Run",
           "StepCarry", "Chunk", "integrate_chunk", "integrate"]


def tableau(name):
    r6, r3 = np.sqrt(6.0), np.sqrt(3.0)
    if name == "radau5":  # Radau IIA, 3 stages, order 5, L-stable, stiffly accurate
        A = [[(88 - 7 * r6) / 360, (296 - 169 * r6) / 1800, (-2 + 3 * r6) / 225],
             [(296 + 169 * r6) / 1800, (88 + 7 * r6) / 360, (-2 - 3 * r6) / 225],
             [(16 - r6) / 36, (16 + r6) / 36, 1 / 9]]
        c = [(4 - r6) / 10, (4 + r6) / 10, 1.0]
    elif name == "gauss4":  # Gauss-Legendre, 2 stages, order 4, A-stable, symplectic
        A = [[0.25, 0.25 - r3 / 6], [0.25 + r3 / 6, 0.25]]
        c = [0.5 - r3 / 6, 0.5 + r3 / 6]
    elif name == "midpoint":  # implicit midpoint, order 2, A-stable, symplectic
        A, c = [[0.5]], [0.5]
    else:
        raise ValueError(f"unknown method {name!r}; choose one of {METHODS}")
    A = np.array(A)
    b = A[-1] if name == "radau5" else (np.array([0.5, 0.5]) if name == "gauss4" else np.array([1.0]))
    # y_{n+1} = y_n + h b^T F = y_n + b^T A^{-1} Z with Z_i = Y_i - y_n: no extra f evaluations.
    d = np.linalg.solve(A.T, b)
    return A, np.array(c), d


#: Implicit Runge-Kutta methods of ``forward_dynamics``: ``"radau5"`` (L-stable: use it with
#: a motor inductance), ``"gauss4"`` and ``"midpoint"`` (A-stable, symplectic: best energy
#: behaviour for unloaded mechanisms, but they do not damp a stiff electrical mode).
METHODS = ("radau5", "gauss4", "midpoint")



@dataclasses.dataclass(frozen=True)
class Integrator:
    """Static settings of one forward-dynamics program (hashable: they are the compiled
    program's identity; numbers that change between runs are arguments of ``integrate``).

    - `model`: the ``Model``; `method`: one of ``METHODS``; `steps`: number of steps of
      the program (``forward_dynamics`` runs a longer run as repeated chunks of ``CHUNK``).
    - `load`: extra generalized force at the inputs, ``fn(q, u, p, v, t) -> (dof,)`` (the
      convention of ``Moment`` and ``PointForce``), or None.
    - `actuators`: ``((input index, actuator), ...)``, each a ``StatefulActuator``
      (``jaxmech.actuators``: a ``DCMotor`` with its voltage, an ``OilCylinder``...); their
      states follow ``(u, u_dot)`` in the state vector, in this order.
    - `close_iters`: Newton steps that close the loop at each stage (``close_loop``).
    - `newton_tol`, `newton_max`: the stage Newton's tolerance (scaled increment; ``None``:
      ``newton_tolerance`` of the dtype) and budget.
    - `options`: the user's ``SolverOptions`` (the loop closures' ``ftol`` and ``cond_max``).
    - `friction`: joint friction (a ``dynamics.friction.JointFriction``, its parameters in
      ``p``) or None; `friction_speed`: each of its joints' speed scale ``W`` (rad/s at a
      pin, m/s in a guide), the regularised sign's band being ``width W``
      (``dynamics.forward_friction``).
    """

    model: Model
    method: str = "radau5"
    steps: int = 1
    load: Callable | None = None
    actuators: tuple = ()
    close_iters: int = 5
    newton_tol: float | None = None
    newton_max: int = 12
    options: SolverOptions = SolverOptions()
    friction: object = None
    friction_speed: tuple = ()


def newton_tolerance(dtype) -> float:
    """Default stage-Newton tolerance on the scaled increment: ``4096 eps`` of ``dtype``
    (9.1e-13 in float64): the stages then hold their converged digits to a few thousand
    round-off units, well below the method's truncation error at any usable step."""
    return 4096.0 * float(jnp.finfo(dtype).eps)


def rhs(integ: Integrator, p, t, y, qg):
    """``y' = f(t, y)`` with ``y = (u, u_dot, [i])``: ``M u_ddot = tau - h(u, u_dot, t)``
    (and ``di/dt`` with an inductive motor), the loop closed near ``qg`` (``close_loop``);
    with joint friction ``u_ddot`` is ``forward_friction.friction_accelerations``'.  NaN
    where the loop cannot be closed; with friction, NaN accelerations (the rates finite)
    where its Newton did not converge.  `p`: the parameter mapping (arrays)."""
    model, load, iters = integ.model, integ.load, integ.close_iters
    mech = model.mechanism
    dof = mech.dof
    u, ud = y[:dof], y[dof : 2 * dof]
    q, ok = close_loop(mech, u, p, qg, iters, integ.options)
    M = mass_matrix(model, q, u, p)
    # h(u, u_dot, t): the inverse-dynamics force at zero input acceleration
    # (for one input: (1/2) M'(u) u_dot^2 - Q(u, u_dot, t)).
    if integ.friction is None:
        hvec, _ = generalized_forces(model, q, u, ud, jnp.zeros_like(ud), p, t)
    tau = jnp.zeros_like(u)
    if load is not None:
        # The convention of every load: fn(q, u, p, v, t) with names (Moment, PointForce),
        # v the coordinates' and inputs' rates (q_dot = dq/du u_dot, implicit).
        _, qd = jax.jvp(lambda u_: implicit_positions(mech, jax.lax.stop_gradient(q), ok, u_, p), (u,), (ud,))
        v = Vars({**{n: qd[i] for i, n in enumerate(mech.coords)}, **{n: ud[i] for i, n in enumerate(mech.inputs)}})
        tau = tau + jnp.reshape(load(mech.vars_q(q), mech.vars_u(u), Vars(p), v, t), (dof,))
    # Each actuator: its force on its input, and the rates of its own states (StatefulActuator).
    rates, at = [], 2 * dof
    for k_in, act in integ.actuators:
        state = y[at : at + act.n_states]
        at += act.n_states
        tau = tau.at[k_in].add(act.force(state, u[k_in], ud[k_in], t, p))
        rates.append(jnp.reshape(jnp.asarray(act.rate(state, u[k_in], ud[k_in], t, p), y.dtype), (act.n_states,)))
    if integ.friction is None:
        udd = solve_small(M, tau - hvec)
    else:
        udd = friction_accelerations(model, integ.friction, integ.friction_speed, q, u, ud, p, t, M, tau).u_ddot
    f = jnp.concatenate([ud, udd, *rates])
    return jnp.where(ok, f, jnp.nan)


def coordinate_rates(mech, y, q, p):
    """The coordinates' rates ``q_dot = dq/du u_dot`` ``(m,)`` at a state ``y`` whose loop is
    closed at ``q`` (through the implicit positions, so differentiable in `p`); NaN where
    ``q`` is not finite."""
    dof = mech.dof
    qs = jax.lax.stop_gradient(q)
    ok = jnp.all(jnp.isfinite(qs))
    _, qd = jax.jvp(lambda u_: implicit_positions(mech, qs, ok, u_, p), (y[:dof],), (y[dof : 2 * dof],))
    return jnp.where(ok, qd, jnp.nan)


def stage_residual(integ: Integrator, A, c, Z, args):
    """Stage equations ``G(Z, args) = Z - h A F(y + Z)`` (``Z_i = Y_i - y_n``) of the
    tableau ``(A, c)`` (numpy arrays), ``args = (y, qg, p, t, h)``."""
    y, qg, p, t, h = args
    F = jax.vmap(lambda ci, zi: rhs(integ, p, t + ci * h, y + zi, qg))(c, Z)
    return Z - h * (jnp.asarray(A, Z.dtype) @ F)


class Run(NamedTuple):
    """What ``integrate`` returns (unpacks like the 5-tuple it replaces): the states `ys`
    ``(steps+1, n)`` and solved coordinates `qs` ``(steps+1, m)`` (NaN after a stop), the
    run's ``Status`` `status`, the time `t_stop` (s) of its last valid state, and the
    simplified-Newton iterations `newton` ``(steps,)`` of each step."""

    ys: jax.Array
    qs: jax.Array
    status: jax.Array
    t_stop: jax.Array
    newton: jax.Array


class StepCarry(NamedTuple):
    """The state carried from step to step (and from chunk to chunk): the last accepted
    state `y` and its coordinates `q`, the run's ``Status`` `status` and the time
    `t_stop` (s) of its last valid state; `fresh`: whether `y` was just accepted (its
    derivative is still to be read from the next step's first Newton iteration)."""

    y: jax.Array
    q: jax.Array
    status: jax.Array
    t_stop: jax.Array
    fresh: jax.Array


class Chunk(NamedTuple):
    """What ``integrate_chunk`` returns: the `carry` after its steps, and per step the
    accepted state `ys` and coordinates `qs` (NaN when not accepted, or past the steps
    asked for), the stage-Newton iterations `newton`, and `rate`: ``f(t, y)`` at the state
    the step started from (row k of the run for step k; NaN where the step was skipped)."""

    carry: StepCarry
    ys: jax.Array
    qs: jax.Array
    newton: jax.Array
    rate: jax.Array


class StageSolve(NamedTuple):
    """``stage_newton``'s result: the stages `Z` ``(s, n)``, the `iterations`, the last
    scaled increment `err` (-1 where a stage could not be evaluated) and `f0`, the
    right-hand side at the step's start (its first iteration's unperturbed point)."""

    Z: jax.Array
    iterations: jax.Array
    err: jax.Array
    f0: jax.Array


class StepContext(NamedTuple):
    """What every step of one ``integrate`` run shares: the settings, the tableau (numpy
    ``A_np, c_np`` for the stage residual, arrays ``A, c, d``), the parameters `p` (and
    `ps`, the same without gradient), the start time `t0` and step `h` (s), the stroke
    bounds `lo`, `hi`, the stage Newton's tolerance and the finite-difference step, and
    `n`: the number of steps asked for (step `n` only reads the last state's rate, later
    ones are skipped)."""

    integ: Integrator
    A_np: np.ndarray
    c_np: np.ndarray
    A: jax.Array
    c: jax.Array
    d: jax.Array
    p: Mapping
    ps: Mapping
    t0: jax.Array
    h: jax.Array
    lo: jax.Array
    hi: jax.Array
    newton_tol: float
    fd_step: float
    n: jax.Array


def _friction_failure(stages, dof: int):
    """The stage Newton's mark of a non-finite stage with friction: -2 where a stage's rates
    are finite but its accelerations not (friction's Newton did not converge there: ``rhs``),
    else -1 (the loop could not be closed)."""
    jammed = jnp.all(jnp.isfinite(stages[:, :dof])) & ~jnp.all(jnp.isfinite(stages[:, dof:2 * dof]))
    return jnp.where(jammed, -2.0, -1.0)


def stage_newton(cx: StepContext, t, ys, qg):
    """The stage equations ``Z = h A F(ys + Z)`` of the step from ``(t, ys)`` solved by
    simplified Newton from ``Z = 0``: a ``StageSolve`` (with ``f(t, ys)``, free: the first
    iteration evaluates it for the Jacobian).

    One iteration matrix ``I - h A (x) J(ys)`` per step.  J only steers the iteration (the
    converged stages do not depend on it), so a forward difference is enough, and it avoids
    third derivatives of the implicit positions.  The difference points ride in the same
    batched right-hand-side call as the stages: one copy of the right-hand side in the
    compiled step (compile time is dominated by it), at the price of n + 1 extra evaluations
    per iteration."""
    A, c, h = cx.A, cx.c, cx.h
    s, n = A.shape[0], ys.shape[0]
    scale = 1.0 + jnp.abs(ys)
    dy = cx.fd_step * scale
    ts = jnp.concatenate([t + c * h, jnp.full((n + 1,), t)])
    y_fd = jnp.concatenate([ys[None], ys + jnp.diag(dy)])
    eye = jnp.eye(s * n, dtype=ys.dtype)
    Z0 = jnp.zeros((s, n), ys.dtype)

    def cond_fn(st):
        return (st.iterations < cx.integ.newton_max) & (st.err > cx.newton_tol)

    def body(st):
        it, Z, Minv, f0 = st.iterations, st.Z, st.f0[0], st.f0[1]
        fb = jax.vmap(lambda ti, yi: rhs(cx.integ, cx.ps, ti, yi, qg))(ts, jnp.concatenate([ys + Z, y_fd]))
        J0 = jnp.where(it == 0, ((fb[s + 1 :] - fb[s]) / dy[:, None]).T, 0.0)
        J0 = jnp.where(jnp.isfinite(J0), J0, 0.0)
        Minv = jnp.where(it == 0, jnp.linalg.inv(eye - h * jnp.kron(A, J0)), Minv)
        dZ = -(Minv @ (Z - h * (A @ fb[:s])).reshape(-1)).reshape(Z.shape)
        err = jnp.max(jnp.abs(dZ) / scale)
        finite = jnp.isfinite(err)
        # err = -1 marks a non-finite stage (the loop could not be closed): stop.
        f0 = jnp.where(it == 0, fb[s], f0)
        fail = -1.0 if cx.integ.friction is None else _friction_failure(fb[:s], cx.integ.model.mechanism.dof)
        return StageSolve(jnp.where(finite, Z + dZ, Z), it + 1, jnp.where(finite, err, fail), (Minv, f0))

    # the loop's state is a StageSolve whose last field carries (iteration matrix, f0)
    init = StageSolve(Z0, jnp.zeros((), jnp.int32), jnp.asarray(jnp.inf, Z0.dtype), (eye, jnp.full_like(ys, jnp.nan)))
    out = jax.lax.while_loop(cond_fn, body, init)
    return out._replace(f0=out.f0[1])


def step_status(cx: StepContext, err, pos_ok, y_new):
    """The ``Status`` of one step: the loop not closed, the stages not converged (to
    ``1e3`` times the tolerance), a non-finite state, an input out of the stroke, or OK;
    with joint friction, ``FRICTION`` where friction's Newton failed at a stage."""
    dof = cx.integ.model.mechanism.dof
    conv = (err >= 0) & (err <= 1e3 * cx.newton_tol)
    finite = jnp.all(jnp.isfinite(y_new))
    out_of_stroke = jnp.any(y_new[:dof] < cx.lo) | jnp.any(y_new[:dof] > cx.hi)
    status = jnp.where(
        (err < 0) | ~pos_ok, Status.POSITION,
        jnp.where(~conv, Status.NOT_CONVERGED,
                  jnp.where(~finite, Status.NONFINITE,
                            jnp.where(out_of_stroke, Status.STROKE_END, Status.CONVERGED))))
    if cx.integ.friction is not None:  # -2: friction's Newton failed at a stage (stage_newton)
        status = jnp.where(err == -2.0, Status.FRICTION, status)
    return status


def advance(cx: StepContext, carry: StepCarry, k):
    """Step `k` (global index, a float) from ``carry``: one implicit Runge-Kutta step, the
    carry advanced where it is accepted (the run OK and `k` below the steps asked for);
    the step's state and coordinates (NaN when not accepted), its stage-Newton iterations
    and the right-hand side at its start."""
    integ = cx.integ
    dof = integ.model.mechanism.dof
    y, q, status, t_stop, _ = carry
    t = cx.t0 + k * cx.h
    stop = jax.lax.stop_gradient
    qg = stop(q)
    ys = stop(y)
    stages = stage_newton(cx, t, ys, qg)
    # The converged stages attached to their arguments by the implicit rule on
    # G(Z*, args) = 0: dZ = -G_Z^{-1} G_args dargs (a custom JVP rather than
    # jax.lax.custom_root, which traces the linearization of G, third derivatives of the
    # positions, on every call, differentiated or not).
    G = functools.partial(stage_residual, integ, cx.A_np, cx.c_np)
    Z_star = stop(stages.Z)
    Z = implicit_solution(G, Z_star, jnp.all(jnp.isfinite(Z_star)), (y, qg, cx.p, t, cx.h), checkpoint=True)
    y_new = y + cx.d @ Z
    q_new, pos_ok = close_loop(integ.model.mechanism, y_new[:dof], cx.p, qg, integ.close_iters, integ.options)
    new_status = step_status(cx, stages.err, pos_ok, y_new)
    # A step past the ones asked for (k = n), or after a stop at an accepted state (the
    # stroke's end), only reads the rate at its start: it changes nothing.
    counts = (status == Status.CONVERGED) & (k < cx.n)
    accept = counts & ((new_status == Status.CONVERGED) | (new_status == Status.STROKE_END))
    carry = StepCarry(jnp.where(accept, y_new, y), jnp.where(accept, q_new, q),
                      jnp.where(counts, new_status, status).astype(jnp.int32), jnp.where(accept, t + cx.h, t_stop), accept)
    rows = (jnp.where(accept, y_new, jnp.nan), jnp.where(accept, q_new, jnp.nan), stages.iterations, stages.f0)
    return carry, rows


def integration_step(cx: StepContext, carry: StepCarry, k):
    """Step `k` of the scan: ``advance`` from a state just accepted (``carry.fresh``) up to
    step `n` (the one past the last asked for, which only reads the last state's rate),
    else nothing (NaN rows, 0 iterations: a stopped run, or a chunk's tail past the run's
    end, costs no right-hand side)."""

    def skip(carry, k):
        nan = jnp.full_like(carry.y, jnp.nan)
        return carry, (nan, jnp.full_like(carry.q, jnp.nan), jnp.zeros((), jnp.int32), nan)

    return jax.lax.cond(carry.fresh & (k <= cx.n), functools.partial(advance, cx), skip, carry, k)


def step_context(integ: Integrator, p, t0, h, n, lo, hi, dtype) -> StepContext:
    """The ``StepContext`` of a run: the tableau of ``integ.method`` in `dtype`, `p` with and
    without gradient, the stage Newton's tolerance, `n` steps asked for."""
    newton_tol = newton_tolerance(dtype) if integ.newton_tol is None else integ.newton_tol
    A_np, c_np, d_np = tableau(integ.method)
    A, c, d = (jnp.asarray(x, dtype) for x in (A_np, c_np, d_np))
    ps = jax.tree_util.tree_map(jax.lax.stop_gradient, p)
    return StepContext(integ=integ, A_np=A_np, c_np=c_np, A=A, c=c, d=d, p=p, ps=ps, t0=t0, h=h, lo=lo, hi=hi,
                       newton_tol=newton_tol, fd_step=float(jnp.finfo(dtype).eps) ** 0.5, n=jnp.asarray(n, dtype))


def integrate_chunk(integ: Integrator, p, t0, h, k0, n, carry: StepCarry, lo, hi) -> Chunk:
    """``integ.steps`` steps of a run from ``carry``, the first being step `k0` of the run
    (its time ``t0 + k0 h``: the same numbers as one long scan), steps from `n` on skipped
    (traceable; `k0` and `n` traced, so one compiled chunk serves every duration)."""
    cx = step_context(integ, p, t0, h, n, lo, hi, carry.y.dtype)
    ks = k0 + jnp.arange(integ.steps, dtype=carry.y.dtype)
    # The step under jax.checkpoint: without it, reverse mode differentiated again (forward
    # or reverse over reverse) lost half of second derivatives through the scan on jax
    # 0.10.2 (tests/test_hinge.py); reverse mode recomputes a step instead of storing it.
    carry, rows = jax.lax.scan(jax.checkpoint(functools.partial(integration_step, cx), prevent_cse=False), carry, ks)
    return Chunk(carry, *rows)


def integrate(integ: Integrator, p, t0, h, y0, q0, lo, hi) -> Run:
    """The forward-dynamics program of ``integ.steps`` fixed steps in one scan (traceable;
    jit it with `integ` static) from ``y0 = (u, u_dot, [i])`` at ``t0`` with step ``h``
    (s), ``q0`` the solved coordinates at ``t0``, the run stopped outside ``[lo, hi]``
    (``(dof,)`` each).  Each step is ``integration_step``.  ``forward_dynamics`` runs the
    same steps as chunks of ``CHUNK`` (``integrate_chunk``).

    **Returns** a ``Run``: ``(ys (steps+1, n), qs (steps+1, m), status, t_stop, newton (steps,))``.
    """
    init = StepCarry(y0, q0, jnp.asarray(Status.CONVERGED, jnp.int32), t0, jnp.asarray(True))
    (_, _, status, t_stop, _), ys, qs, its, _ = integrate_chunk(integ, p, t0, h, 0.0, integ.steps, init, lo, hi)
    return Run(jnp.concatenate([y0[None], ys]), jnp.concatenate([q0[None], qs]), status, t_stop, its)
