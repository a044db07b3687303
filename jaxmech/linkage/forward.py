"""Forward dynamics of a ``Linkage``: its model (bodies, joints, gravity, loads, springs
and dampers) driven by a DC motor, stateful actuators or a torque or force law, integrated
by ``dynamics.forward_dynamics`` from the drawing or from a given input
(``linkage_forward_dynamics``, which is ``Linkage.forward_dynamics``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax
import numpy as np

from ..actuators import parameter_names
from ..dynamics.forward import Trajectory, forward_dynamics

__all__ = ["actuator_parameters", "linkage_forward_dynamics"]


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


def linkage_forward_dynamics(lk, *, h, steps: int, u0=None, u_dot0=0.0, p: Mapping | None = None, motor=None, voltage=None,
                             current0=0.0, actuators: Mapping | None = None, load: Callable | None = None, **settings) -> Trajectory:
    """``Linkage.forward_dynamics``: forward dynamics (``jaxmech.forward_dynamics``) of the
    linkage `lk` with its bodies, gravity, loads, springs and dampers, from the drawing (or
    from inputs `u0`, reached by continuation on the drawing's assembly mode) at rates
    `u_dot0`, `steps` steps of `h` (s), driven by `motor` (a ``DCMotor`` on the first input,
    its `voltage` and initial `current0`), `actuators` (``{input: StatefulActuator}``) or
    a `load` law ``fn(q, u, p, v, t) -> (dof,)`` (N m or N on each input).

    `p`: the linkage's parameters to change (``Linkage.params``) and the values of the
    names the motor and actuators declare (``actuator_parameters``: ``R_a``, ``K_m``,
    ``V``...).  `settings`: ``forward_dynamics``'s `t0`, `method`, `stroke`,
    `motor_input`, `close_iters`, `newton_tol`, `newton_max`, `options`.

    **Returns** a ``Trajectory``, differentiable in `p` (``jax.grad``, ``jax.jacfwd``);
    ``Trajectory.dynamics(lk.model, p)`` adds the effort and every joint's reaction.
    **Raises** ``ValueError`` for a linkage with joint friction (not in forward dynamics
    yet), a parameter the linkage, the motor and the actuators do not know, a missing motor
    parameter, or an unknown setting."""
    if getattr(lk, "friction", None) is not None:  # refused, not silently left out (as a scene does)
        raise ValueError(f"{lk.name}: forward dynamics has no joint friction yet; build the linkage without friction= "
                         "to run it (or use Linkage.inverse_dynamics with friction along a drive law)")
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
                            current0=current0, actuators=actuators, load=load, **settings)
