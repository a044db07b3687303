"""Forward dynamics: ``M(u) u_ddot + h(u, u_dot, t) = tau`` integrated in the inputs with an
implicit Runge-Kutta method (Radau IIA by default, L-stable for a stiff motor inductance),
the loop closed inside every stage, differentiable end to end.

``h = (1/2) M' u_dot^2 - Q`` for one input: the inverse-dynamics force at zero input
acceleration (``virtual_power.generalized_forces``).  The steps are ``forward_steps``'s;
this module runs them as chunks of one compiled program (``CHUNK`` steps each, so a new
duration compiles nothing new) and gathers the ``Trajectory``; see ``forward_dynamics``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..actuators import DCMotor, parameter_names
from ..solver.options import SolverOptions
from ..solver.positions import solve
from ..solver.status import Status
from .forward_setup import (StopCause, checked_arguments, friction_speeds, initial_state, run_actuators, stop_message,
                            stroke_bounds)
from .friction import friction_parameters
from .forward_steps import (METHODS, Chunk, Integrator, Run, StepCarry, integrate, integrate_chunk, newton_tolerance, rhs,
                            stage_residual, coordinate_rates)
from .model import Model, mechanism_params, prepare_params
from ..solver.xla import jit

__all__ = ["METHODS", "CHUNK", "Trajectory", "Integrator", "newton_tolerance", "rhs", "stage_residual", "Run",
           "integrate", "integrate_chunk", "StepCarry", "Chunk", "gathered", "forward_dynamics"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Forward-dynamics result (a pytree; leading axis = the ``steps + 1`` time points).

    - `t` (s), `u` ``(N+1, dof)`` (rad or m), `u_dot` (rad/s or m/s), `q` ``(N+1, m)``.
    - `current`: motor current ``(N+1, 1)`` (A) with an inductive motor, else ``(N+1, 0)``.
    - `status`: ``Status`` of the run (scalar); `t_stop`: time of the last valid state.
      Rows after a stop are NaN; with ``STROKE_END`` the first state past the end is kept.
      ``message()`` says why it stopped, with the fix.
    - `newton`: simplified-Newton iterations of each step ``(N,)`` (0 after a stop).
    - `states`: every actuator's states ``(N+1, k)`` in the order of the run's actuators
      (the motor first): a motor's current (A), a cylinder's pressure (Pa)...
    - `u_ddot` ``(N+1, dof)``: the inputs' accelerations (rad/s^2 or m/s^2) from the
      equations of motion at each state; `q_dot` ``(N+1, m)``: the coordinates' rates.
    - `h` (s), `closable` and `cond`: the step, and the stop's diagnosis (``StopCause``).
    - `friction`, `friction_speed`: the run's joint friction (a ``JointFriction`` or None)
      and its sign's speed scale ``W`` per friction joint (static): what
      ``dynamics(model, p)`` applies at the run's states.
    - ``dynamics(model, p)``: the coordinates' accelerations, the driving effort and every
      joint's reaction along the run (an ``InverseDynamics``), with the run's friction.
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
    u_ddot: jax.Array
    q_dot: jax.Array
    h: jax.Array
    closable: jax.Array
    cond: jax.Array
    close_iters: int = dataclasses.field(metadata=dict(static=True), default=5)
    newton_max: int = dataclasses.field(metadata=dict(static=True), default=12)
    friction: object = dataclasses.field(metadata=dict(static=True), default=None)
    friction_speed: tuple = dataclasses.field(metadata=dict(static=True), default=())

    def message(self) -> str:
        """Why the run ended, in words (``stop_message``): a ``POSITION`` stop names the step
        `h` and `close_iters` where the loop closes one step on (the step outran the
        closure's budget: lower `h` or raise `close_iters`), a toggle only where it does not."""
        return stop_message(StopCause(int(self.status), float(self.t_stop), float(self.h), self.close_iters,
                                      self.newton_max, bool(self.closable), float(self.cond)))

    def dynamics(self, model: Model, p: Mapping, *, options: SolverOptions = SolverOptions()):
        """Inverse dynamics at every state of the run (``forward_along.trajectory_dynamics``):
        an ``InverseDynamics`` with the coordinates' accelerations ``q_ddot``, the driving
        effort ``tau`` (the actuators' and the `load`'s generalized force on each input,
        N m or N) and every joint's reaction ``joints`` (N, complex), NaN after a stop.  A
        run with joint friction applies it here too (its ``friction`` at its
        ``friction_speed``): the reactions with friction, ``joint_friction`` each joint's
        load, and ``tau`` the effort with friction balancing the run's accelerations."""
        from .forward_along import trajectory_dynamics

        return trajectory_dynamics(model, self, p, options=options)



#: Steps per compiled chunk of ``forward_dynamics``: a run of any length is
#: ``ceil(steps / CHUNK)`` calls of one program (a new duration compiles nothing new); the
#: last chunk's steps past the run's end are skipped, not computed.
CHUNK = 128


class ChunkedRun(NamedTuple):
    """``run_chunks``'s result: the final `carry`, the states `ys` ``(steps+1, n)`` and
    coordinates `qs` ``(steps+1, m)``, the iterations `newton` ``(steps,)``, the states'
    rates `rates` ``(steps+1, n)`` (``f(t, y)``: the inputs' accelerations at
    ``[dof:2 dof]``) and the coordinates' rates `q_dot` ``(steps+1, m)``."""

    carry: StepCarry
    ys: jax.Array
    qs: jax.Array
    newton: jax.Array
    rates: jax.Array
    q_dot: jax.Array


def chunk_with_rates(integ: Integrator, p, t0, h, k0, n, carry: StepCarry, lo, hi):
    """``integrate_chunk`` and the coordinates' rates at the chunk's start and each of its
    states: ``(Chunk, q_dot (steps + 1, m))``."""
    out = integrate_chunk(integ, p, t0, h, k0, n, carry, lo, hi)
    mech = integ.model.mechanism
    ys, qs = jnp.concatenate([carry.y[None], out.ys]), jnp.concatenate([carry.q[None], out.qs])
    return out, jax.vmap(lambda y, q: coordinate_rates(mech, y, q, p))(ys, qs)


_chunk_jit = jit(chunk_with_rates, static_argnums=0)


def run_chunks(integ: Integrator, p, t0, h, steps: int, init: StepCarry, bounds) -> ChunkedRun:
    """`steps` steps from `init` as calls of the compiled chunk (``integ.steps`` steps
    each), the state carried from one to the next: the same numbers as one scan (each
    step's time is ``t0 + k h`` with its global index `k`).  Step `steps` runs too, only
    to read the last state's rate.  `bounds`: ``(lo, hi)``."""
    dtype, carry, parts = init.y.dtype, init, []
    for k0 in range(0, steps + 1, integ.steps):
        out = _chunk_jit(integ, p, t0, h, jnp.asarray(k0, dtype), jnp.asarray(steps, dtype), carry, *bounds)
        parts.append(out)
        carry = out[0].carry
    # Gathered on the host where nothing is traced: concatenating a new number of chunks
    # on the device would compile small programs for each new duration.
    xp = jnp if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((parts, init, p))) else np
    cat = lambda rows, first=(): xp.concatenate([*first, *rows])[: steps + 1]  # noqa: E731
    chunks = [c for c, _ in parts]
    return ChunkedRun(carry, cat([c.ys for c in chunks], [init.y[None]]), cat([c.qs for c in chunks], [init.q[None]]),
                      cat([c.newton for c in chunks])[:steps], cat([c.rate for c in chunks]),
                      cat([qd[1:] for _, qd in parts], [parts[0][1][:1]]))


def stop_diagnosis(model: Model, carry: StepCarry, h, p, options: SolverOptions):
    """``(closable, cond)`` one explicit Euler step past the last valid state (``StopCause``):
    whether a full position solve closes the loop there (converged, below the condition
    limit) and the loop Jacobian's condition number it finds.  The same compiled solve as
    the run's first position; no gradient."""
    mech, stop = model.mechanism, jax.lax.stop_gradient
    dof = mech.dof
    u_next = stop(carry.y[:dof] + h * carry.y[dof:2 * dof])
    ps = {k: stop(v) for k, v in mechanism_params(model, p).items()}
    sol = solve(mech, {k: u_next[i] for i, k in enumerate(mech.inputs)}, ps, stop(carry.q), options=options)
    return sol.status == Status.CONVERGED, sol.cond


def gathered(run: ChunkedRun, dof: int, n_motor: int, t, h, diagnosis: Mapping) -> Trajectory:
    """The ``Trajectory`` of a chunked run: its states split into inputs, rates, the
    motor's current and the actuators' states, at times `t`; `diagnosis`: the stop's
    fields (``closable``, ``cond``, ``close_iters``, ``newton_max``)."""
    ys = run.ys
    # host rows (run_chunks) back to device arrays by device_put: a copy (jnp.asarray would
    # compile a staging program for each new length)
    put = lambda x: jax.device_put(x) if isinstance(x, np.ndarray) else x  # noqa: E731
    return Trajectory(t=put(t), u=put(ys[:, :dof]), u_dot=put(ys[:, dof:2 * dof]), current=put(ys[:, 2 * dof:2 * dof + n_motor]),
                      q=put(run.qs), status=run.carry.status, t_stop=run.carry.t_stop, newton=put(run.newton),
                      states=put(ys[:, 2 * dof:]), u_ddot=put(run.rates[:, dof:2 * dof]), q_dot=put(run.q_dot), h=h, **diagnosis)


def forward_dynamics(model: Model, p: Mapping, u0, u_dot0, guess, *, h, steps: int, t0=0.0, method: str = "radau5",
                     motor: DCMotor | None = None, voltage=None, current0=0.0, motor_input: str | None = None,
                     actuators: Mapping | None = None, load: Callable | None = None, stroke=None, options: SolverOptions = SolverOptions(),
                     newton_tol: float | None = None, newton_max: int = 12, close_iters: int = 5, friction=None, friction_speed=None) -> Trajectory:
    """Integrate the equations of motion in the inputs, with fixed steps (one design).

    ``M(u) u_ddot + h(u, u_dot, t) = tau_load + tau_motor`` where ``M`` is ``mass_matrix``
    and ``h`` the inverse-dynamics force at zero input acceleration (for one input
    ``h = (1/2) M'(u) u_dot^2 - Q``); with an inductive motor the state also holds the
    current, ``L di/dt = v - R i - n K w``.  Every stage closes the loop (a fixed number of
    Newton steps from the step's start, attached to ``(u, p)`` by ``implicit.implicit_positions``),
    and the stage equations ``Z = h A F(y + Z)`` are solved by simplified Newton (one
    iteration matrix per step, from a finite-difference Jacobian) and attached to their
    arguments by a custom JVP (the implicit function theorem on the stage equations:
    ``dZ = -G_Z^{-1} G_args dargs``).  No derivative goes through an iteration: the run is
    differentiable, forward and reverse mode, in ``p``, ``u0``, ``u_dot0`` and ``h`` (see
    ``docs/forward_dynamics_gradients.md``).

    **Arguments**

    - `p`: parameters; `u0`, `u_dot0`: initial inputs and rates ``(dof,)`` (for one input
      a number too; or ``{input name: value}``); `guess`: coordinates ``(m,)`` near the
      initial position (picks the branch).  One run starts from one state: no batch.
    - `h`: step (s); `steps`: number of steps, not compiled in (the run is repeated
      calls of one compiled chunk of ``CHUNK`` steps); `t0`: start time (s); numbers.
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
    - `newton_tol`, `newton_max`: the stage Newton's tolerance on the scaled increment
      (default ``newton_tolerance(dtype)``, ``4096 eps``) and budget; `close_iters`: Newton
      steps closing the loop at each stage from the step's start (the step must be small
      enough for them).
    - `options`: ``SolverOptions`` of the initial position solve and of every loop closure.
    - `friction`, `friction_speed`: a ``JointFriction`` and its sign's speed scale ``W`` (``dynamics.forward_friction``).

    **Raises** ``ValueError`` naming the argument for another shape, before any tracing.

    **Returns** a ``Trajectory`` (``Trajectory.dynamics`` adds the effort and every joint's
    reaction).  A run stops at a singular or unassemblable position, a failed step or the
    stroke's end with its ``Status`` (later rows NaN); ``Trajectory.message()`` names
    the cause (the step against ``close_iters`` where the loop closes one step on).
    """
    mech = model.mechanism
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    if motor is not None and voltage is None and motor.voltage is None:
        raise ValueError("a motor needs a voltage: a parameter name, a number or fn(t, p) -> V")
    if int(steps) < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    acts = run_actuators(mech, motor, voltage, motor_input, actuators)
    u0, ud0, guess = checked_arguments(mech, u0, u_dot0, guess, h, t0, stroke)
    integ = Integrator(model, method, CHUNK, load, tuple(acts), int(close_iters), None if newton_tol is None else float(newton_tol),
                       int(newton_max), options, friction, friction_speeds(friction, friction_speed))
    dtype = jnp.result_type(u0, ud0, guess, float)
    pj = prepare_params(model, p, dtype, tuple(n for _, a in acts for n in parameter_names(a)) + friction_parameters(model, friction))
    y0 = initial_state(acts, motor is not None, u0, ud0, current0, pj, dtype)
    # The jitted batch solve (compiled once per mechanism and options); a dict of scalars is a batch of shape ().
    sol = solve(mech, {k: u0.astype(dtype)[i] for i, k in enumerate(mech.inputs)}, mechanism_params(model, pj),
                guess.astype(dtype), options=options)
    t0, h, ok = jnp.asarray(t0, dtype), jnp.asarray(h, dtype), sol.status == Status.CONVERGED
    init = StepCarry(y0, sol.q, jnp.where(ok, Status.CONVERGED, Status.POSITION).astype(jnp.int32), t0, ok)
    run = run_chunks(integ, pj, t0, h, int(steps), init, stroke_bounds(stroke, mech.dof, dtype))
    closable, cond = stop_diagnosis(model, run.carry, h, pj, options)
    n_motor = acts[0][1].n_states if motor is not None else 0
    xp = np if isinstance(run.ys, np.ndarray) else jnp  # on the host where the run was gathered there (run_chunks)
    return gathered(run, mech.dof, n_motor, xp.asarray(t0) + xp.asarray(h) * xp.arange(int(steps) + 1, dtype=dtype), h,
                    dict(closable=closable, cond=cond, close_iters=int(close_iters), newton_max=int(newton_max),
                         friction=friction, friction_speed=integ.friction_speed))
