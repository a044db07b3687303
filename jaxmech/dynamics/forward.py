"""Forward dynamics: ``M(u) u_ddot + h(u, u_dot, t) = tau`` integrated in the inputs with an
implicit Runge-Kutta method (Radau IIA by default, L-stable for a stiff motor inductance),
the loop closed inside every stage, differentiable end to end.

``h = (1/2) M' u_dot^2 - Q`` for one input: the inverse-dynamics force at zero input
acceleration (``virtual_power.generalized_forces``).  The stage equations are attached to
their arguments by an implicit-function custom JVP; see ``forward_dynamics``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..linalg import solve_small
from ..actuators import DCMotor, parameter_names
from ..implicit import implicit_positions, implicit_solution
from ..mechanism import Vars
from ..inputs import as_coords, as_inputs
from ..options import SolverOptions
from ..positions import solve
from ..status import Status
from .closure import close_loop
from .model import Model, mechanism_params, prepare_params
from .status import DynStatus
from .virtual_power import generalized_forces, mass_matrix
from ..xla import jit

__all__ = ["METHODS", "Trajectory", "Integrator", "newton_tolerance", "rhs", "stage_residual", "Run", "integrate",
           "forward_dynamics"]


def _tableau(name):
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


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Forward-dynamics result (a pytree; leading axis = the ``steps + 1`` time points).

    - `t` (s), `u` ``(N+1, dof)``, `u_dot`, `q` ``(N+1, m)``.
    - `current`: motor current ``(N+1, 1)`` (A) with an inductive motor, else ``(N+1, 0)``.
    - `status`: ``DynStatus`` of the run (scalar); `t_stop`: time of the last valid state.
      Rows after a stop are NaN; with ``STROKE_END`` the first state past the end is kept.
    - `newton`: simplified-Newton iterations of each step ``(N,)``.
    - `states`: every actuator's states ``(N+1, k)`` in the order of the run's actuators
      (the motor first): a motor's current (A), a cylinder's pressure (Pa)...
    """

    t: jax.Array
    u: jax.Array
    u_dot: jax.Array
    current: jax.Array
    q: jax.Array
    status: jax.Array
    t_stop: jax.Array
    newton: jax.Array
    states: jax.Array


@dataclasses.dataclass(frozen=True)
class Integrator:
    """Static settings of one forward-dynamics program (hashable: they are the compiled
    program's identity; numbers that change between runs are arguments of ``integrate``).

    - `model`: the ``Model``; `method`: one of ``METHODS``; `steps`: number of steps.
    - `load`: extra generalized force at the inputs, ``fn(q, u, p, v, t) -> (dof,)`` (the
      convention of ``Moment`` and ``PointForce``), or None.
    - `actuators`: ``((input index, actuator), ...)``, each a ``StatefulActuator``
      (``jaxmech.actuators``: a ``DCMotor`` with its voltage, an ``OilCylinder``...); their
      states follow ``(u, u_dot)`` in the state vector, in this order.
    - `close_iters`: Newton steps that close the loop at each stage (``close_loop``).
    - `newton_tol`, `newton_max`: the stage Newton's tolerance (scaled increment; ``None``:
      ``newton_tolerance`` of the dtype) and budget.
    - `options`: the user's ``SolverOptions`` (the loop closures' ``ftol`` and ``cond_max``).
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


def newton_tolerance(dtype) -> float:
    """Default stage-Newton tolerance on the scaled increment: ``4096 eps`` of ``dtype``
    (9.1e-13 in float64): the stages then hold their converged digits to a few thousand
    round-off units, well below the method's truncation error at any usable step."""
    return 4096.0 * float(jnp.finfo(dtype).eps)


def rhs(integ: Integrator, p, t, y, qg):
    """``y' = f(t, y)`` with ``y = (u, u_dot, [i])``: ``M u_ddot = tau - h(u, u_dot, t)``
    (and ``di/dt`` with an inductive motor), the loop closed near ``qg`` (``close_loop``).
    NaN where the loop cannot be closed.  `p`: the parameter mapping (arrays)."""
    model, load, iters = integ.model, integ.load, integ.close_iters
    mech = model.mechanism
    dof = mech.dof
    u, ud = y[:dof], y[dof : 2 * dof]
    q, ok = close_loop(mech, u, p, qg, iters, integ.options)
    M = mass_matrix(model, q, u, p)
    # h(u, u_dot, t): the inverse-dynamics force at zero input acceleration
    # (for one input: (1/2) M'(u) u_dot^2 - Q(u, u_dot, t)).
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
    udd = solve_small(M, tau - hvec)
    f = jnp.concatenate([ud, udd, *rates])
    return jnp.where(ok, f, jnp.nan)


def stage_residual(integ: Integrator, A, c, Z, args):
    """Stage equations ``G(Z, args) = Z - h A F(y + Z)`` (``Z_i = Y_i - y_n``) of the
    tableau ``(A, c)`` (numpy arrays), ``args = (y, qg, p, t, h)``."""
    y, qg, p, t, h = args
    F = jax.vmap(lambda ci, zi: rhs(integ, p, t + ci * h, y + zi, qg))(c, Z)
    return Z - h * (jnp.asarray(A, Z.dtype) @ F)


class Run(NamedTuple):
    """What ``integrate`` returns (unpacks like the 5-tuple it replaces): the states `ys`
    ``(steps+1, n)`` and solved coordinates `qs` ``(steps+1, m)`` (NaN after a stop), the
    run's ``DynStatus`` `status`, the time `t_stop` (s) of its last valid state, and the
    simplified-Newton iterations `newton` ``(steps,)`` of each step."""

    ys: jax.Array
    qs: jax.Array
    status: jax.Array
    t_stop: jax.Array
    newton: jax.Array


class StepContext(NamedTuple):
    """What every step of one ``integrate`` run shares: the settings, the tableau (numpy
    ``A_np, c_np`` for the stage residual, arrays ``A, c, d``), the parameters `p` (and
    `ps`, the same without gradient), the start time `t0` and step `h` (s), the stroke
    bounds `lo`, `hi`, the stage Newton's tolerance and the finite-difference step."""

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


def stage_newton(cx: StepContext, t, ys, qg):
    """The stage equations ``Z = h A F(ys + Z)`` of the step from ``(t, ys)`` solved by
    simplified Newton from ``Z = 0``: ``(Z, iterations, err)``, ``err`` the last scaled increment,
    -1 where a stage could not be evaluated.

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
        it, _, _, err = st
        return (it < cx.integ.newton_max) & (err > cx.newton_tol)

    def body(st):
        it, Z, Minv, _ = st
        fb = jax.vmap(lambda ti, yi: rhs(cx.integ, cx.ps, ti, yi, qg))(ts, jnp.concatenate([ys + Z, y_fd]))
        J0 = jnp.where(it == 0, ((fb[s + 1 :] - fb[s]) / dy[:, None]).T, 0.0)
        J0 = jnp.where(jnp.isfinite(J0), J0, 0.0)
        Minv = jnp.where(it == 0, jnp.linalg.inv(eye - h * jnp.kron(A, J0)), Minv)
        dZ = -(Minv @ (Z - h * (A @ fb[:s])).reshape(-1)).reshape(Z.shape)
        err = jnp.max(jnp.abs(dZ) / scale)
        finite = jnp.isfinite(err)
        # err = -1 marks a non-finite stage (the loop could not be closed): stop.
        return it + 1, jnp.where(finite, Z + dZ, Z), Minv, jnp.where(finite, err, -1.0)

    it, Z, _, err = jax.lax.while_loop(cond_fn, body, (0, Z0, eye, jnp.asarray(jnp.inf, Z0.dtype)))
    return Z, it, err


def step_status(cx: StepContext, err, pos_ok, y_new):
    """The ``DynStatus`` of one step: the loop not closed, the stages not converged (to
    ``1e3`` times the tolerance), a non-finite state, an input out of the stroke, or OK."""
    dof = cx.integ.model.mechanism.dof
    conv = (err >= 0) & (err <= 1e3 * cx.newton_tol)
    finite = jnp.all(jnp.isfinite(y_new))
    out_of_stroke = jnp.any(y_new[:dof] < cx.lo) | jnp.any(y_new[:dof] > cx.hi)
    return jnp.where(
        (err < 0) | ~pos_ok, DynStatus.POSITION,
        jnp.where(~conv, DynStatus.NOT_CONVERGED,
                  jnp.where(~finite, DynStatus.NONFINITE,
                            jnp.where(out_of_stroke, DynStatus.STROKE_END, DynStatus.OK))))


def integration_step(cx: StepContext, carry, k):
    """Step `k` of the scan: ``carry = (y, q, status, t_stop)`` advanced by one implicit
    Runge-Kutta step where the run is still OK; the step's state and coordinates (NaN when
    not accepted) and its Newton iterations as the scan's output."""
    integ = cx.integ
    dof = integ.model.mechanism.dof
    y, q, status, t_stop = carry
    t = cx.t0 + k * cx.h
    stop = jax.lax.stop_gradient
    qg = stop(q)
    ys = stop(y)
    Z_star, it, err = stage_newton(cx, t, ys, qg)
    # The converged stages attached to their arguments by the implicit rule on
    # G(Z*, args) = 0: dZ = -G_Z^{-1} G_args dargs (a custom JVP rather than
    # jax.lax.custom_root, which traces the linearization of G, third derivatives of the
    # positions, on every call, differentiated or not).
    G = functools.partial(stage_residual, integ, cx.A_np, cx.c_np)
    Z_star = stop(Z_star)
    Z = implicit_solution(G, Z_star, jnp.all(jnp.isfinite(Z_star)), (y, qg, cx.p, t, cx.h), checkpoint=True)
    y_new = y + cx.d @ Z
    q_new, pos_ok = close_loop(integ.model.mechanism, y_new[:dof], cx.p, qg, integ.close_iters, integ.options)
    new_status = step_status(cx, err, pos_ok, y_new)
    running = status == DynStatus.OK
    accept = running & ((new_status == DynStatus.OK) | (new_status == DynStatus.STROKE_END))
    y_next = jnp.where(accept, y_new, y)
    q_next = jnp.where(accept, q_new, q)
    status_next = jnp.where(running, new_status, status).astype(jnp.int32)
    t_stop = jnp.where(accept, t + cx.h, t_stop)
    return (y_next, q_next, status_next, t_stop), (jnp.where(accept, y_new, jnp.nan), jnp.where(accept, q_new, jnp.nan), it)


def integrate(integ: Integrator, p, t0, h, y0, q0, lo, hi) -> Run:
    """The forward-dynamics program of ``forward_dynamics`` (traceable; jit it with `integ`
    static): ``integ.steps`` fixed steps from ``y0 = (u, u_dot, [i])`` at ``t0`` with step
    ``h`` (s), ``q0`` the solved coordinates at ``t0``, the run stopped outside ``[lo, hi]``
    (``(dof,)`` each).  Each step is ``integration_step``.

    **Returns** a ``Run``: ``(ys (steps+1, n), qs (steps+1, m), status, t_stop, newton (steps,))``.
    """
    newton_tol = newton_tolerance(y0.dtype) if integ.newton_tol is None else integ.newton_tol
    A_np, c_np, d_np = _tableau(integ.method)
    A, c, d = (jnp.asarray(x, y0.dtype) for x in (A_np, c_np, d_np))
    ps = jax.tree_util.tree_map(jax.lax.stop_gradient, p)
    cx = StepContext(integ=integ, A_np=A_np, c_np=c_np, A=A, c=c, d=d, p=p, ps=ps, t0=t0, h=h, lo=lo, hi=hi,
                     newton_tol=newton_tol, fd_step=float(jnp.finfo(y0.dtype).eps) ** 0.5)
    init = (y0, q0, jnp.asarray(DynStatus.OK, jnp.int32), t0)
    # The step under jax.checkpoint: without it, reverse mode differentiated again (forward
    # or reverse over reverse) lost half of second derivatives through the scan on jax
    # 0.10.2 (tests/test_hinge.py); reverse mode recomputes a step instead of storing it.
    (_, _, status, t_stop), (ys, qs, its) = jax.lax.scan(jax.checkpoint(functools.partial(integration_step, cx), prevent_cse=False),
                                                         init, jnp.arange(integ.steps, dtype=y0.dtype))
    return Run(jnp.concatenate([y0[None], ys]), jnp.concatenate([q0[None], qs]), status, t_stop, its)


_integrate_jit = jit(integrate, static_argnums=0)


def _checked(mech, u0, u_dot0, guess, h, t0, stroke):
    """The arguments of one run, checked and shaped before anything is traced: `u0`,
    `u_dot0` ``(dof,)`` (a number for one input, or a mapping by input name), `guess`
    ``(m,)``, `h` and `t0` numbers, `stroke` ``(lo, hi)`` with each bound a number or
    ``(dof,)``.  ``ValueError`` naming the argument for any other shape."""
    dof, m = mech.dof, len(mech.coords)

    def state(x, name, as_array, size, kind):
        shape = np.shape(x) if not isinstance(x, Mapping) else None
        x = as_array(mech, x, name)
        if x.ndim != 1:
            raise ValueError(f"{mech.name}: {name} must have shape ({size},) ({kind}; one run starts from one "
                             f"state), got shape {shape if shape is not None else x.shape}")
        return x

    u0 = state(u0, "u0", as_inputs, dof, f"inputs {mech.inputs}")
    ud0 = state(u_dot0, "u_dot0", as_inputs, dof, f"inputs {mech.inputs}")
    guess = state(guess, "guess", as_coords, m, f"coordinates {mech.coords}")
    for name, x in (("h", h), ("t0", t0)):
        if np.ndim(x) != 0:
            raise ValueError(f"{mech.name}: {name} must be a number (s), got shape {np.shape(x)}")
    if stroke is not None:
        if len(stroke) != 2:
            raise ValueError(f"{mech.name}: stroke must be a pair (lo, hi), got {len(stroke)} entries")
        for name, b in zip(("lo", "hi"), stroke):
            if np.shape(b) not in ((), (dof,)):
                raise ValueError(f"{mech.name}: stroke {name} must be a number or have shape ({dof},), got shape {np.shape(b)}")
    return u0, ud0, guess


def run_actuators(mech, motor, voltage, motor_input, actuators) -> list:
    """The run's stateful actuators, ``[(input index, actuator), ...]``, the motor first (on
    `motor_input`, default the first input; `voltage`, when given, replacing its own), then
    `actuators` by input name.  ``ValueError`` for an unknown input or an object that is not
    a ``StatefulActuator``."""
    acts = []
    if motor is not None:
        if motor_input is not None and motor_input not in mech.inputs:
            raise ValueError(f"motor_input {motor_input!r} is not an input; inputs are {list(mech.inputs)}")
        k_in = 0 if motor_input is None else mech.inputs.index(motor_input)
        acts.append((k_in, motor if voltage is None else dataclasses.replace(motor, voltage=voltage)))
    for name, act in (actuators or {}).items():
        if name not in mech.inputs:
            raise ValueError(f"actuators: {name!r} is not an input; inputs are {list(mech.inputs)}")
        if not all(hasattr(act, a) for a in ("n_states", "initial_state", "force", "rate")):
            raise ValueError(f"actuators[{name!r}]: {type(act).__name__} is not a StatefulActuator "
                             f"(n_states, initial_state, force, rate)")
        acts.append((mech.inputs.index(name), act))
    return acts


def initial_state(acts, has_motor: bool, u0, ud0, current0, pj, dtype):
    """The state vector at the start, ``(u0, u_dot0, states...)``: the motor's current
    `current0` (A) when `has_motor` (it is first in `acts`), every other actuator's
    ``initial_state(pj)``."""
    parts = [u0.astype(dtype), ud0.astype(dtype)]
    for i, (_, act) in enumerate(acts):
        if act.n_states == 0:
            continue
        x0 = jnp.asarray(current0, dtype) if (i == 0 and has_motor) else jnp.asarray(act.initial_state(pj), dtype)
        parts.append(jnp.reshape(x0, (act.n_states,)))
    return jnp.concatenate(parts)


def stroke_bounds(stroke, dof: int, dtype):
    """``(lo, hi)``, each ``(dof,)``: the inputs' stroke (``(-inf, inf)`` without one)."""
    if stroke is None:
        lo = jnp.full((dof,), -jnp.inf, dtype)
        hi = jnp.full((dof,), jnp.inf, dtype)
    else:
        lo, hi = (jnp.broadcast_to(jnp.asarray(b, dtype), (dof,)) for b in stroke)
    return lo, hi


def forward_dynamics(model: Model, p: Mapping, u0, u_dot0, guess, *, h, steps: int, t0=0.0, method: str = "radau5",
                     motor: DCMotor | None = None, voltage=None, current0=0.0, motor_input: str | None = None,
                     actuators: Mapping | None = None, load: Callable | None = None, stroke=None, options: SolverOptions = SolverOptions(),
                     newton_tol: float | None = None, newton_max: int = 12, close_iters: int = 5) -> Trajectory:
    """Integrate the equations of motion in the inputs, with fixed steps (one design).

    ``M(u) u_ddot + h(u, u_dot, t) = tau_load + tau_motor`` where ``M`` is ``mass_matrix``
    and ``h`` the inverse-dynamics force at zero input acceleration (for one input
    ``h = (1/2) M'(u) u_dot^2 - Q``); with an inductive motor the state also holds the
    current, ``L di/dt = v - R i - n K w``.  Every stage closes the loop (a fixed number of
    Newton steps from the step's start, attached to ``(u, p)`` by ``implicit.implicit_positions``),
    and the stage equations ``Z = h A F(y + Z)`` are solved by simplified Newton (one
    iteration matrix per step, from a finite-difference Jacobian) and attached to their
    arguments by a custom JVP (the implicit function theorem on the stage equations:
    ``dZ = -G_Z^{-1} G_args dargs``).  No derivative goes through an iteration, and the
    whole run is differentiable, forward and reverse mode, in ``p``, ``u0``, ``u_dot0``
    and ``h``: see ``docs/forward_dynamics_gradients.md`` and the notebook
    ``notebooks/forward_dynamics_gradients.ipynb`` (a final angle's gradient in a mass,
    a length and the motor voltage, checked against finite differences).

    **Arguments**

    - `p`: parameters; `u0`, `u_dot0`: initial inputs and rates ``(dof,)`` (for one input
      a number too; or ``{input name: value}``); `guess`: coordinates ``(m,)`` near the
      initial position (picks the branch).  One run starts from one state: no batch.
    - `h`: step (s); `steps`: number of steps (static); `t0`: start time (s); numbers.
    - `method`: one of ``METHODS``.
    - `motor`: a ``DCMotor`` on input `motor_input` (default the first); `voltage`: spec of
      its voltage, a parameter name, a number, or ``fn(t, p) -> V``; `current0` (A).  The
      parameters the motor's specs name, and a voltage's name, belong in `p` alongside the
      model's (``Model.parameters``) without being declared anywhere else.
    - `actuators`: ``{input name: actuator}``, further ``StatefulActuator``s (an
      ``OilCylinder``...), each on its input, with states of their own started at their
      ``initial_state(p)``; their parameters join `p` like the motor's.
    - `load`: extra generalized force at the inputs (N m or N), ``fn(q, u, p, v, t) ->
      (dof,)``, the convention of every load (``Moment``, ``PointForce``): `q`, `u`, `p`
      and the rates `v` (coordinates' and inputs', ``v.theta2``) by name, `t` in s; e.g. a
      controller or a prescribed torque (``dict(p)`` gives the mapping the library's
      functions take).
    - `stroke`: ``(lo, hi)``, each a number or ``(dof,)``: the run stops with
      ``STROKE_END`` when an input leaves it.
    - `newton_tol`: stage-Newton tolerance on the scaled increment (default
      ``newton_tolerance(dtype)``: ``4096 eps``); `newton_max`: its budget.
    - `close_iters`: Newton steps that close the loop at each stage from the step's start
      (the step must be small enough for them to converge; a failure is reported).
    - `options`: ``SolverOptions`` of the initial position solve and of every loop closure.

    **Raises** ``ValueError`` naming the argument for a shape other than these, before
    anything is traced.

    **Returns** a ``Trajectory``.  A run that reaches a singular or unassemblable position,
    a failed step or the stroke end stops there with its ``DynStatus``; later rows are NaN.
    """
    mech = model.mechanism
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    if motor is not None and voltage is None and motor.voltage is None:
        raise ValueError("a motor needs a voltage: a parameter name, a number or fn(t, p) -> V")
    if int(steps) < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    acts = run_actuators(mech, motor, voltage, motor_input, actuators)
    u0, ud0, guess = _checked(mech, u0, u_dot0, guess, h, t0, stroke)
    dtype = jnp.result_type(u0, ud0, guess, float)
    pj = prepare_params(model, p, dtype, tuple(n for _, a in acts for n in parameter_names(a)))
    y0 = initial_state(acts, motor is not None, u0, ud0, current0, pj, dtype)
    # The jitted batch solve (compiled once per mechanism and options); a dict of scalars
    # is a batch of shape ().
    sol = solve(mech, {k: u0.astype(dtype)[i] for i, k in enumerate(mech.inputs)}, mechanism_params(model, pj),
                guess.astype(dtype), options=options)
    lo, hi = stroke_bounds(stroke, mech.dof, dtype)
    integ = Integrator(model, method, int(steps), load, tuple(acts), int(close_iters),
                       None if newton_tol is None else float(newton_tol), int(newton_max), options)
    ys, qs, status, t_stop, its = _integrate_jit(integ, pj, jnp.asarray(t0, dtype), jnp.asarray(h, dtype), y0, sol.q, lo, hi)
    status = jnp.where(sol.status == Status.CONVERGED, status, DynStatus.POSITION).astype(jnp.int32)
    dof = mech.dof
    t = jnp.asarray(t0, dtype) + jnp.asarray(h, dtype) * jnp.arange(int(steps) + 1, dtype=dtype)
    n_motor = acts[0][1].n_states if motor is not None else 0
    return Trajectory(t=t, u=ys[:, :dof], u_dot=ys[:, dof:2 * dof], current=ys[:, 2 * dof:2 * dof + n_motor], q=qs,
                      status=status, t_stop=t_stop, newton=its, states=ys[:, 2 * dof:])

