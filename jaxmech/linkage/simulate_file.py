"""A linkage file's ``[simulate]`` table: forward dynamics from the file (``jaxmech simulate``;
``docs/linkage_files.md``, "Forward dynamics").

```toml
[simulate]
duration = "1 s"          # the run's time (s); steps = ceil(duration / step)
step = "1 ms"             # the integrator's fixed step (s)
u0 = "30deg"              # the driven input at the start (rad or m; default: the drawing's)
u_dot0 = "0 rpm"          # its rate at the start (rad/s or m/s; default 0)
friction_speed = 2.0      # with [friction]: the speed scale of friction's sign (required there)
torque = "1.5 N m"        # a constant effort on the driven input (N m, or N for a slider or an
                          # actuator) -- or a motor:
[simulate.motor]          # DCMotor: L di/dt = V - R i - n K w_m, torque at the input n K i
R_a = "2 ohm"             # armature resistance
K_m = "0.5 N m/A"         # torque (back-EMF) constant
L_a = "20 mH"             # armature inductance (optional: without it the current is algebraic)
ratio = 1                 # gear ratio motor speed / input speed (optional, default 1)
voltage = "6 V"           # the constant supply voltage
current0 = "0 A"          # the current at the start (optional, needs L_a)
```

Neither ``torque`` nor ``[simulate.motor]``: free motion under gravity, springs, dampers,
the file's loads.  The motor's numbers and the torque are parameters of the run (``R_a``,
``K_m``, ``L_a``, ``ratio``, ``voltage``, ``torque``): ``--set`` changes them as it changes the
linkage's, and ``Linkage.forward_dynamics`` takes them in `p` (``run_simulation``).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from ..actuators import DCMotor, Spec, resolve
from ..dynamics.joints import Prismatic, Revolute, joint_name
from ..names import near_hint
from ..units import split_quantity
from .friction import friction_key
from .values import read_number

__all__ = ["read_simulate", "run_simulation", "simulation_columns", "friction_joints"]

SIMULATE_KEYS = ("duration", "step", "u0", "u_dot0", "friction_speed", "torque", "motor")
#: ``[simulate.motor]``'s keys and their SI units (``current0`` is a state, not a parameter).
MOTOR_KEYS = {"R_a": "ohm", "K_m": "N m/A", "L_a": "H", "ratio": "-", "voltage": "V", "current0": "A"}
EXAMPLE = '[simulate] duration = "1 s", step = "1 ms"'


@dataclasses.dataclass(frozen=True)
class ConstantEffort:
    """A constant generalized force on one input (N m on a crank, N on a slider or an
    actuator), the parameter spec `effort`: a memoryless ``StatefulActuator`` (no state), so
    that the value is a parameter of the run (one compiled program for every value)."""

    effort: Spec = "torque"
    n_states: ClassVar[int] = 0

    def initial_state(self, p):
        return jnp.zeros((0,))

    def force(self, state, position, speed, t, p):
        return resolve(self.effort, p)

    def rate(self, state, position, speed, t, p):
        return jnp.zeros((0,))


@dataclasses.dataclass(frozen=True)
class Simulation:
    """A ``[simulate]`` table read (SI): `steps` of `step` (s) from input `u0` (None: the
    drawing's) at rate `u_dot0`; `drive` ``"motor"``, ``"torque"`` or ``"none"``; the `motor`
    (a ``DCMotor`` whose specs name `values`' keys) and its `current0` (A); `values`: the
    run's own parameters (the motor's numbers, ``torque``) and `units` their SI units;
    `friction_speed`: ``Linkage.forward_dynamics``'s (a number, ``{joint: W}`` or None)."""

    duration: float
    step: float
    steps: int
    u0: float | None = None
    u_dot0: float = 0.0
    drive: str = "none"
    motor: DCMotor | None = None
    current0: float = 0.0
    values: Mapping = dataclasses.field(default_factory=dict)
    units: Mapping = dataclasses.field(default_factory=dict)
    friction_speed: float | Mapping | None = None


def _unknown(table: Mapping, keys, where: str) -> None:
    bad = [k for k in table if k not in keys]
    if bad:
        raise ValueError(f"unknown {where} key(s) {bad}; it takes {', '.join(keys)}{near_hint(bad, tuple(keys))}")


def _time(table: Mapping, key: str, given) -> float:
    """`given` (the command line's, SI or with a unit) or ``table[key]``: a positive time (s)."""
    if given is None and key not in table:
        raise ValueError(f"[simulate] needs {key} (s, e.g. {key} = \"{'1 s' if key == 'duration' else '1 ms'}\"), "
                         f"or give --{key}")
    value = read_number(table[key] if given is None else given, "s", f"[simulate] {key}" if given is None else f"--{key}")
    if not value > 0.0:
        raise ValueError(f"[simulate] {key} must be a positive time (s), got {table.get(key, given)!r}")
    return value


def read_simulate(table: Mapping | None, lk, *, duration=None, step=None) -> Simulation:
    """The ``[simulate]`` table `table` of the linkage `lk` (None: the file has none, and
    the command line's `duration` and `step` must both be given; they replace the table's).
    ``ValueError`` naming the key and the fix."""
    if table is None:
        if duration is None or step is None:
            raise ValueError(f"no [simulate] table: add one ({EXAMPLE}, and a drive: [simulate.motor] or torque; "
                             "docs/linkage_files.md), or give --duration and --step")
        table = {}
    _unknown(table, SIMULATE_KEYS, "[simulate]")
    mech = lk.mechanism
    if mech.dof != 1:
        raise ValueError(f"jaxmech simulate runs a linkage with one driven input; this one has {mech.dof} "
                         f"({list(mech.inputs)}): run it in Python (Linkage.forward_dynamics)")
    unit = "m" if mech.inputs[0] in mech.lengths else "rad"
    h, t_end = _time(table, "step", step), _time(table, "duration", duration)
    steps = max(1, math.ceil(t_end / h - 1e-9))
    u0 = None if "u0" not in table else read_number(table["u0"], unit, "[simulate] u0")
    u_dot0 = read_number(table.get("u_dot0", 0.0), unit + "/s", "[simulate] u_dot0")
    if "motor" in table and "torque" in table:
        raise ValueError("[simulate] drives the input by [simulate.motor] or by torque, not both: leave one out")
    out = dict(duration=t_end, step=h, steps=steps, u0=u0, u_dot0=u_dot0,
               friction_speed=_friction_speed(table, lk))
    if "torque" in table:
        effort = "N m" if unit == "rad" else "N"
        out.update(drive="torque", values={"torque": read_number(table["torque"], effort, "[simulate] torque")},
                   units={"torque": effort})
    elif "motor" in table:
        out.update(_motor(table["motor"]))
    clash = [k for k in out.get("values", {}) if k in lk.params]
    if clash:
        raise ValueError(f"[simulate]: the linkage has parameter(s) {clash} too; rename them in the drawing")
    return Simulation(**out)


def _motor(table) -> dict:
    """``Simulation``'s motor fields from ``[simulate.motor]``."""
    if not isinstance(table, Mapping):
        raise ValueError('[simulate] motor must be a table: [simulate.motor] with R_a = "2 ohm", K_m = "0.5 N m/A", '
                         'voltage = "12 V"')
    _unknown(table, MOTOR_KEYS, "[simulate.motor]")
    missing = [k for k in ("R_a", "K_m", "voltage") if k not in table]
    if missing:
        raise ValueError(f"[simulate.motor] needs {', '.join(missing)} ({', '.join(MOTOR_KEYS[k] for k in missing)}); "
                         'e.g. R_a = "2 ohm", K_m = "0.5 N m/A", voltage = "12 V"')
    values = {k: read_number(v, MOTOR_KEYS[k], f"[simulate.motor] {k}") for k, v in table.items()}
    for k, ok, what in (("R_a", lambda x: x > 0, "positive"), ("L_a", lambda x: x > 0, "positive"),
                        ("K_m", lambda x: x != 0, "non-zero"), ("ratio", lambda x: x != 0, "non-zero")):
        if k in values and not ok(values[k]):
            raise ValueError(f"[simulate.motor] {k} must be {what} ({MOTOR_KEYS[k]}), got {table[k]!r}")
    if "current0" in values and "L_a" not in values:
        raise ValueError("[simulate.motor] current0 needs an inductance L_a: without it the current follows the "
                         "voltage at once; give L_a or leave current0 out")
    current0 = values.pop("current0", 0.0)
    motor = DCMotor("R_a", "K_m", inductance="L_a" if "L_a" in values else None,
                    ratio="ratio" if "ratio" in values else 1.0, voltage="voltage")
    return dict(drive="motor", motor=motor, current0=current0, values=values, units={k: MOTOR_KEYS[k] for k in values})


def friction_joints(lk) -> dict:
    """``{joint name or friction key: joint}`` of the joints that carry friction."""
    named = {fj.joint for fj in lk.friction.joints}
    joints = [j for j in lk.model.joints if joint_name(j) in named]
    return {**{friction_key(j): j for j in joints}, **{joint_name(j): j for j in joints}}


def _has_unit(value) -> bool:
    try:
        return isinstance(value, str) and bool(split_quantity(value)[1])
    except ValueError:  # not a number: read_number says so, naming the key
        return False


def _friction_speed(table: Mapping, lk):
    """``friction_speed``: required with joint friction, refused without; a number (or a
    string with the unit every friction joint shares) or ``{joint: W}`` each in its unit."""
    given = table.get("friction_speed")
    if getattr(lk, "friction", None) is None:
        if given is not None:
            raise ValueError("[simulate] friction_speed is the speed scale of joint friction's sign: this linkage has no "
                             "[friction]; leave it out")
        return None
    joints = friction_joints(lk)
    if given is None:
        raise ValueError("[simulate] needs friction_speed with [friction]: the speed scale of friction's sign, about the "
                         "largest joint speed expected (rad/s at a pin, m/s in a guide), e.g. friction_speed = 2.0, or "
                         f"a table per joint {{ {next(iter(joints))} = 2.0 }}")
    unit = lambda j: "rad/s" if isinstance(j, Revolute) else "m/s"  # noqa: E731
    if isinstance(given, Mapping):
        bad = [k for k in given if k not in joints]
        if bad:
            raise ValueError(f"[simulate] friction_speed: {bad} carry no friction; the joints with friction are "
                             f"{sorted({friction_key(j) for j in joints.values()})}{near_hint(bad, tuple(joints))}")
        out = {k: read_number(v, unit(joints[k]), f"[simulate] friction_speed.{k}") for k, v in given.items()}
    else:
        units = {unit(j) for j in joints.values()}
        if len(units) > 1 and _has_unit(given):
            raise ValueError(f"[simulate] friction_speed = {given!r}: pins (rad/s) and guides (m/s) carry friction here; "
                             "give a bare number for both, or a table per joint")
        out = read_number(given, units.pop() if len(units) == 1 else "-", "[simulate] friction_speed")
    for k, v in (out.items() if isinstance(out, dict) else [("", out)]):
        if not v > 0.0:
            raise ValueError(f"[simulate] friction_speed{'.' + k if k else ''} must be positive, got {v}")
    return out


def run_simulation(lk, sim: Simulation, params: Mapping | None = None):
    """``Linkage.forward_dynamics`` of `lk` as `sim` says, with `params` (the linkage's and
    the run's own parameters changed: ``--set``); returns ``(Trajectory, p)``, `p` every
    parameter of the run (the linkage's and `sim.values`, changed by `params`)."""
    given = {**sim.values, **(params or {})}
    drive = {}
    if sim.drive == "motor":
        drive = dict(motor=sim.motor, current0=sim.current0)
    elif sim.drive == "torque":
        drive = dict(actuators={lk.mechanism.inputs[0]: ConstantEffort("torque")})
    tr = lk.forward_dynamics(h=sim.step, steps=sim.steps, u0=sim.u0, u_dot0=sim.u_dot0, p=given,
                             friction_speed=sim.friction_speed, **drive)
    return tr, {**lk.params, **given}


def _column(name: str) -> str:
    return re.sub(r"\W+", "_", name).strip("_")


def simulation_columns(lk, sim: Simulation, tr, p: Mapping) -> dict:
    """The run as table columns ``NAME[UNIT]`` (SI): `t`; the input with its rate and
    acceleration; every coordinate with its rate and acceleration; the motor's current
    (A); the drive's effort on the input (``effort_<input>``, N m or N: ``n K i``, the
    constant torque, 0 in free motion); every joint's reaction (``F_<joint>_x``,
    ``F_<joint>_y``, a slider's ``M_<joint>``: ``Trajectory.dynamics``, joint friction
    included where the run has it); ``status[-]``: 0 up to the last valid state, the run's ``Status`` after."""
    mech = lk.mechanism
    unit = {n: "m" if n in mech.lengths else "rad" for n in (*mech.inputs, *mech.coords)}
    pf = {k: float(v) for k, v in p.items()}
    res = tr.dynamics(lk.model, pf)
    rows = lambda x: np.asarray(x, float)  # noqa: E731
    u, ud, udd = rows(tr.u), rows(tr.u_dot), rows(tr.u_ddot)
    q, qd, qdd = rows(tr.q), rows(tr.q_dot), rows(res.q_ddot)
    cols = {"t[s]": rows(tr.t)}
    for series, names in (((u, ud, udd), mech.inputs), ((q, qd, qdd), mech.coords)):
        for k, name in enumerate(names):
            for x, suffix, per in zip(series, ("", "_dot", "_ddot"), ("", "/s", "/s^2")):
                cols[f"{name}{suffix}[{unit[name]}{per}]"] = x[:, k]
    name = mech.inputs[0]
    effort = np.zeros_like(u[:, 0])
    if sim.drive == "motor":
        motor = sim.motor
        if motor.inductance is None:
            effort = rows(motor.steady_torque(pf["voltage"], ud[:, 0], pf))
            current = rows(motor.steady_current(effort, pf))
        else:
            current = rows(tr.current)[:, 0]
            effort = rows(motor.torque(current, pf))
        cols["current[A]"] = current
    elif sim.drive == "torque":
        effort = effort + pf["torque"]
    cols[f"effort_{_column(name)}[{'N' if unit[name] == 'm' else 'N m'}]"] = np.where(np.isfinite(u[:, 0]), effort, np.nan)
    for j in lk.model.joints:
        col, force = _column(joint_name(j)), np.asarray(res.joints[joint_name(j)])
        cols[f"F_{col}_x[N]"], cols[f"F_{col}_y[N]"] = force.real, force.imag
        if isinstance(j, Prismatic):
            cols[f"M_{col}[N m]"] = rows(res.joint_moments[joint_name(j)])
    cols["status[-]"] = np.where(np.all(np.isfinite(u), axis=1), 0, int(tr.status)).astype(np.int64)
    return cols
