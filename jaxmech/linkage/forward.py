"""Forward dynamics of a ``Linkage``: its model (bodies, joints, gravity, loads, springs
and dampers, joint friction) driven by a DC motor, stateful actuators or a torque or force
law, integrated by ``dynamics.forward_dynamics`` from the drawing or from a given input
(``linkage_forward_dynamics``, which is ``Linkage.forward_dynamics``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax
import numpy as np

from ..actuators import parameter_names
from ..dynamics.forward import Trajectory, forward_dynamics
from ..dynamics.joints import joint_name
from .friction import friction_key

__all__ = ["linkage_forward_dynamics"]


def actuator_parameters(motor, voltage, actuators) -> tuple[str, ...]:
    """The names the run's motor (its specs and a voltage given by name) and actuators
    declare: they join the linkage's parameters in `p`."""
    names = [*parameter_names(motor), *(n for a in dict(actuators or {}).values() for n in parameter_names(a))]
    if isinstance(voltage, str):
        names.append(voltage)
    elif motor is not None and voltage is None and isinstance(motor.voltage, str):
        names.append(motor.voltage)
    return tuple(dict.fromkeys(names))


def _start(lk, u0, values: Mapping):
    """The inputs ``(dof,)`` and coordinates ``(m,)`` at the start: the drawing's, or at
    `u0` reached by continuation from the drawing (its assembly mode kept)."""
    if u0 is None:
        return lk.input_at_drawing, lk.guess
    u0 = np.asarray(u0, float).reshape(-1)
    dof = lk.mechanism.dof
    if u0.shape != (dof,):
        raise ValueError(f"{lk.name}: u0 must be a number or have shape ({dof},) (inputs {list(lk.mechanism.inputs)}), "
                         f"got shape {np.shape(u0)}")
    plain = {k: np.asarray(jax.lax.stop_gradient(v)) for k, v in values.items()}
    sol = lk.solve(u0[None, :], p=plain)
    return u0, np.asarray(sol.q[0])


def _friction_speed(lk, speed):
    """`friction_speed` as ``dynamics.forward_dynamics`` takes it: a number, or one per
    friction joint from ``{joint name or key: W}`` (every joint with friction given)."""
    if not isinstance(speed, Mapping) or getattr(lk, "friction", None) is None:
        return speed
    keys = {joint_name(j): friction_key(j) for j in lk.model.joints}
    out = []
    for fj in lk.friction.joints:
        given = [k for k in (fj.joint, keys[fj.joint]) if k in speed]
        if not given:
            raise ValueError(f"{lk.name}: friction_speed has no speed scale for {keys[fj.joint]!r} ({fj.joint!r})")
        out.append(speed[given[0]])
    unknown = [k for k in speed if k not in {*(fj.joint for fj in lk.friction.joints),
                                             *(keys[fj.joint] for fj in lk.friction.joints)}]
    if unknown:
        raise ValueError(f"{lk.name}: friction_speed: {unknown} carry no friction; the joints with friction are "
                         f"{[keys[fj.joint] for fj in lk.friction.joints]}")
    return out


def linkage_forward_dynamics(lk, *, h, steps: int, u0=None, u_dot0=0.0, p: Mapping | None = None, motor=None, voltage=None,
                             current0=0.0, actuators: Mapping | None = None, load: Callable | None = None, friction_speed=None,
                             **settings) -> Trajectory:
    """``Linkage.forward_dynamics``: forward dynamics (``jaxmech.forward_dynamics``) of the
    linkage `lk` with its bodies, gravity, loads, springs, dampers and joint friction, from
    the drawing (or from inputs `u0`, reached by continuation on the drawing's assembly
    mode) at rates `u_dot0`, `steps` steps of `h` (s), driven by `motor` (a ``DCMotor`` on
    the first input, its `voltage` and initial `current0`), `actuators` (``{input:
    StatefulActuator}``) or a `load` law ``fn(q, u, p, v, t) -> (dof,)`` (N m or N on each
    input).

    **Joint friction** (``Linkage(friction=...)``): the friction law of inverse dynamics
    (``dynamics.friction``: ``mu r |F|`` at a pin, ``mu |N|`` in a guide, times the sign
    ``tanh(w / (width W))``, plus ``c w``) acts at every state of the run.  A forward run
    does not know its joints' speeds before it runs, so `friction_speed` gives the scale
    ``W``: a number (rad/s at a pin, m/s in a guide, e.g. the largest speed expected) or
    ``{joint name or key: W}``.  Each evaluation of the accelerations solves the
    accelerations and the friction loads together (friction depends on the joints' forces,
    which depend on the accelerations): Newton's method from the frictionless solution,
    attached to the state and parameters by the implicit function theorem, so the run
    stays differentiable in every parameter, ``mu_<key>``, ``rpin_<key>``, ``cv_<key>``
    among them (``dynamics.forward_friction``).  Where friction's Newton does not converge
    (friction jams the linkage) the run stops with ``Status.FRICTION`` and
    ``Trajectory.message()`` says so.  The trajectory keeps the run's friction and its
    speed scale (``Trajectory.friction``, ``friction_speed``), so ``Trajectory.dynamics``
    applies the same law at the run's states: the effort ``tau`` with friction (the
    motor's, actuators' and `load`'s generalized force that the run's accelerations
    balance) and every joint's reaction with its friction load (``joint_friction``).

    `p`: the linkage's parameters to change (``Linkage.params``) and the values of the
    names the motor and actuators declare (``actuator_parameters``: ``R_a``, ``K_m``,
    ``V``...).  `settings`: ``forward_dynamics``'s `t0`, `method`, `stroke`,
    `motor_input`, `close_iters`, `newton_tol`, `newton_max`, `options`.

    **Returns** a ``Trajectory``, differentiable in `p` (``jax.grad``, ``jax.jacfwd``);
    ``Trajectory.dynamics(lk.model, p)`` adds the effort and every joint's reaction.
    **Raises** ``ValueError`` for a parameter the linkage, the motor and the actuators do
    not know, a missing motor parameter, an unknown setting, or joint friction without its
    `friction_speed`."""
    given = dict(p or {})
    extra = actuator_parameters(motor, voltage, actuators)
    missing = [k for k in extra if k not in given]
    unknown = [k for k in given if k not in extra and k not in lk.params]
    bad = [k for k in settings if k not in ("t0", "method", "stroke", "motor_input", "close_iters", "newton_tol", "newton_max",
                                             "options")]
    for what, names in (("give the motor's and actuators' parameters", missing), ("unknown parameter(s)", unknown),
                        ("forward_dynamics got unknown argument(s)", bad)):
        if names:
            raise ValueError(f"{lk.name}: {what} {names}; see Linkage.params and jaxmech.forward_dynamics")
    values = {**lk.params, **given}
    start_u, guess = _start(lk, u0, {k: values[k] for k in lk.mechanism.params})
    return forward_dynamics(lk.model, values, start_u, u_dot0, guess, h=h, steps=steps, motor=motor, voltage=voltage,
                            current0=current0, actuators=actuators, load=load, friction=getattr(lk, "friction", None),
                            friction_speed=_friction_speed(lk, friction_speed), **settings)
