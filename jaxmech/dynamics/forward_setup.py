"""What a forward-dynamics run needs before and after its compiled program: its arguments
checked and shaped (``checked_arguments``), its actuators, initial state and stroke bounds,
and the words for how it ended (``stop_message``: the real cause of a stop, with the fix)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from ..solver.inputs import as_coords, as_inputs
from .friction import friction_speeds
from ..solver.status import Status, status_message

__all__ = ["checked_arguments", "run_actuators", "friction_speeds", "initial_state", "stroke_bounds", "StopCause",
           "stop_message"]


def checked_arguments(mech, u0, u_dot0, guess, h, t0, stroke):
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


@dataclasses.dataclass(frozen=True)
class StopCause:
    """What a run's message needs to name a stop's cause (plain numbers, read after the run).

    - `status`: the run's ``Status``; `t_stop`: time of its last valid state (s).
    - `h`: the step (s); `close_iters`: the loop closure's Newton steps per stage;
      `newton_max`: the stage Newton's budget.
    - `closable`: whether the loop closes (a full position solve, converged and below the
      condition limit) at the input one Euler step past the last valid state;
      `cond`: the loop Jacobian's condition number there (1-norm, scaled; inf where no
      position was found).
    """

    status: int
    t_stop: float
    h: float
    close_iters: int
    newton_max: int
    closable: bool
    cond: float


def stop_message(cause: StopCause) -> str:
    """Why a run stopped, in words, with the fix where there is one.

    A ``POSITION`` stop is a toggle (or an unassemblable pose) only where the loop cannot
    be closed one step on (the position solve fails there or its Jacobian's condition is
    past the limit); where it can, the step outran the closure's fixed Newton budget: the
    message names `h` and `close_iters` and says to lower one or raise the other."""
    code = Status(int(cause.status))
    at = f"at t = {cause.t_stop:.6g} s"
    if code == Status.POSITION and cause.closable:
        return (f"the loop closure did not converge in close_iters={cause.close_iters} Newton steps within the step "
                f"h={cause.h:.3g} s {at}, although the position one step on is well conditioned (condition number "
                f"{cause.cond:.3g}): the step is too large for the closure's budget; use a smaller h or a larger close_iters")
    if code == Status.POSITION:
        return (f"{status_message(code)} {at} (the loop's Jacobian condition number one step on: {cause.cond:.3g}); "
                f"a smaller h will not pass it")
    if code == Status.NOT_CONVERGED:
        return (f"an implicit step did not converge in newton_max={cause.newton_max} stage-Newton iterations with the step "
                f"h={cause.h:.3g} s {at}: use a smaller h (or a larger newton_max)")
    if code == Status.CONVERGED:
        return "ok: integrated to the end"
    return f"{status_message(code)} {at}"
