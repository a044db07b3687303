"""Actuator laws: DC motor, screw jack, hydraulic cylinder, linear spring, SMA wire.

Each actuator is a small frozen dataclass whose fields are *specs* of parameters, not
numbers: a spec is a parameter name (``"R_a"``, looked up in ``p``), a Python number (a
constant), or a function ``fn(p) -> value`` of the parameter namespace.  Numbers that a
design may change therefore stay in ``p`` and are differentiable; the actuator object
itself is static (hashable, safe as a jit static argument) and captures no arrays.

Two-point elements (``LinearSpring``, ``SMAWire``, ``HydraulicCylinder``) are *axial
laws*: calling one as ``law(length, rate, p, t)`` gives the tension (N, positive pulls
its two ends together), which is what ``jaxmech.dynamics.Axial`` expects.

**Stateful actuators** (``StatefulActuator``: ``DCMotor``, ``OilCylinder``) act on one
input of a model in forward dynamics and may carry states of their own (a motor's
current, a cylinder's chamber pressure) that are integrated with the motion.  They are
found by name in ``REGISTRY``: a new one is one module in this package and one line there.

Sign conventions: torques and speeds of a motor are on the same axis, positive together
(motoring: ``torque * speed > 0``).  Units SI throughout (V, A, ohm, H, N m/A, m, Pa, K).
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple, Protocol, Union

import jax.numpy as jnp

from ..mechanism.mechanism import Vars

__all__ = [
    "Spec",
    "resolve",
    "spec_names",
    "parameter_names",
    "command",
    "StatefulActuator",
    "REGISTRY",
    "get_actuator",
    "OilCylinder",
    "DCMotor",
    "ScrewJack",
    "HydraulicCylinder",
    "LinearSpring",
    "SMAWire",
]

#: A parameter spec: a parameter name, a constant, or ``fn(p) -> value``.
Spec = Union[str, float, int, Callable[[Vars], Any]]


def resolve(spec: Spec, p: Mapping):
    """Value of a parameter spec for the parameters ``p`` (a mapping or ``Vars``).

    **Raises** ``ValueError`` for an unknown parameter name (eagerly, before tracing).
    """
    if spec is None:
        return None
    if isinstance(spec, str):
        try:
            return p[spec]
        except KeyError:
            raise ValueError(f"unknown parameter {spec!r}; known parameters: {', '.join(p) or '(none)'}") from None
    if callable(spec):
        return spec(p if isinstance(p, Vars) else Vars(p))
    return spec


def spec_names(*specs) -> tuple[str, ...]:
    """The parameter names among ``specs`` (those given as strings), in order, once each."""
    return tuple(dict.fromkeys(s for s in specs if isinstance(s, str)))


def parameter_names(actuator) -> tuple[str, ...]:
    """The parameters an actuator declares: every name its specs give, in field order.

    A motor built as ``DCMotor("R_a", "K_m")`` declares ``R_a`` and ``K_m``: a model that
    uses it accepts them in ``p`` without listing them anywhere else.  A name the
    mechanism or the model declares too is the same parameter (merged by name).
    ``()`` for ``None`` or an object that is not an actuator dataclass.  An actuator whose
    specs are not all used in every configuration says which are by a ``used_specs()``
    method (``SMAWire``: the transformation temperatures only with a temperature).
    """
    if actuator is None or not dataclasses.is_dataclass(actuator):
        return ()
    if hasattr(actuator, "used_specs"):
        return spec_names(*actuator.used_specs())
    return spec_names(*(getattr(actuator, f.name) for f in dataclasses.fields(actuator)))


def command(spec, t, p):
    """Value of a time-dependent command spec (a voltage, a flow) at time ``t`` (s): a
    parameter name, a number, or ``fn(t, p) -> value`` (``p`` as a ``Vars``)."""
    if isinstance(spec, str):
        return resolve(spec, p)
    if callable(spec):
        return spec(t, p if isinstance(p, Vars) else Vars(p))
    return spec


class StatefulActuator(Protocol):
    """What forward dynamics needs of an actuator acting on one input (``forward_dynamics
    (..., actuators={input_name: actuator})``).

    - ``n_states``: number of its own states (static int; 0 for a memoryless actuator).
    - ``initial_state(p) -> (n_states,)``: the states at the start of a run.
    - ``force(state, position, speed, t, p)``: generalized force on the input (N m or N,
      positive in the input's positive sense) at the input's position and speed.
    - ``rate(state, position, speed, t, p) -> (n_states,)``: the states' time derivatives.

    Every number comes from specs resolved in ``p`` (``parameter_names`` lists them), so an
    actuator is static (hashable) and one compiled run serves every design.
    """

    n_states: int

    def initial_state(self, p): ...

    def force(self, state, position, speed, t, p): ...

    def rate(self, state, position, speed, t, p): ...


#: Stateful actuators by name: ``name -> (module, class)``, imported on first use.  A new
#: actuator is one module of this package and one line here.
REGISTRY = {
    "dc_motor": ("jaxmech.actuators", "DCMotor"),
    "oil_cylinder": ("jaxmech.actuators.oil_cylinder", "OilCylinder"),
}


def get_actuator(name: str) -> type:
    """The actuator class registered as ``name``; ``ValueError`` listing the names otherwise."""
    if name not in REGISTRY:
        raise ValueError(f"unknown actuator {name!r}; known actuators: {', '.join(REGISTRY)}")
    module, attr = REGISTRY[name]
    return getattr(importlib.import_module(module), attr)


def __getattr__(name):  # the registered actuators as attributes of this package (lazy: no cycle)
    for module, attr in REGISTRY.values():
        if attr == name and module != __name__:
            return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --------------------------------------------------------------------------- DC motor
@dataclasses.dataclass(frozen=True)
class DCMotor:
    """Permanent-magnet DC motor, optionally through a gear of ratio ``ratio``.

    Armature: ``L di/dt = v - R i - K w_m``, motor torque ``T_m = K i``; at the driven
    input (after the gear, lossless) ``T = ratio K i`` and ``w_m = ratio w``.

    **Arguments** (specs)

    - `resistance`: armature resistance ``R`` (ohm).
    - `constant`: torque / back-EMF constant ``K`` (N m/A = V s/rad).
    - `inductance`: armature inductance ``L`` (H); ``None`` treats the current as
      algebraic (``L = 0``), which removes the stiff electrical mode.
    - `ratio`: gear ratio motor speed / input speed (dimensionless), default 1.
    - `voltage`: command spec (a parameter name, a number or ``fn(t, p) -> V``) when the
      motor drives a forward-dynamics run (``StatefulActuator``; ``forward_dynamics``'s
      `voltage` argument sets it).  Its state is the current with an inductance, none without.
    """

    resistance: Spec = "R_a"
    constant: Spec = "K_m"
    inductance: Spec | None = None
    ratio: Spec = 1.0
    voltage: Spec | Callable | None = None

    def _rkn(self, p):
        return resolve(self.resistance, p), resolve(self.constant, p), resolve(self.ratio, p)

    def steady_voltage(self, torque, speed, p):
        """Voltage (V) that holds ``torque`` (N m, at the input) at ``speed`` (rad/s) in
        steady current: ``v = R T / (n K) + n K w``."""
        R, K, n = self._rkn(p)
        return R * torque / (n * K) + n * K * speed

    def steady_current(self, torque, p):
        """Current (A) for ``torque`` (N m at the input): ``i = T / (n K)``."""
        _, K, n = self._rkn(p)
        return torque / (n * K)

    def steady_torque(self, voltage, speed, p):
        """Torque at the input (N m) at ``voltage`` and ``speed`` with ``L di/dt = 0``:
        ``T = n K (v - n K w) / R`` (the motor's linear speed-torque line)."""
        R, K, n = self._rkn(p)
        return n * K * (voltage - n * K * speed) / R

    def torque(self, current, p):
        """Torque at the input (N m) for armature ``current`` (A): ``n K i``."""
        _, K, n = self._rkn(p)
        return n * K * current

    # ---- StatefulActuator
    @property
    def n_states(self) -> int:
        return 0 if self.inductance is None else 1

    def initial_state(self, p):
        """Zero current (A); ``forward_dynamics(current0=...)`` starts elsewhere."""
        return jnp.zeros((self.n_states,))

    def force(self, state, position, speed, t, p):
        """Torque at the input (N m) at the commanded voltage: steady current without an
        inductance, ``n K i`` with one."""
        if self.inductance is None:
            return self.steady_torque(command(self.voltage, t, p), speed, p)
        return self.torque(state[0], p)

    def rate(self, state, position, speed, t, p):
        """``(di/dt,)`` with an inductance, ``()`` without."""
        if self.inductance is None:
            return jnp.zeros((0,))
        return jnp.stack([self.current_rate(state[0], command(self.voltage, t, p), speed, p)])

    def current_rate(self, current, voltage, speed, p):
        """``di/dt`` (A/s) = ``(v - R i - n K w) / L`` (needs an inductance)."""
        if self.inductance is None:
            raise ValueError("DCMotor.current_rate needs an inductance; this motor has inductance=None")
        R, K, n = self._rkn(p)
        return (voltage - R * current - n * K * speed) / resolve(self.inductance, p)


# --------------------------------------------------------------------------- screw jack
class ScrewThread(NamedTuple):
    """A screw's thread at parameters ``p`` (``ScrewJack._get``): `lead` (m per turn), mean
    diameter `d_m` (m), friction coefficient `f` (-), and ``sec`` of the thread half angle."""

    lead: Any
    d_m: Any
    f: Any
    sec: Any


@dataclasses.dataclass(frozen=True)
class ScrewJack:
    """Power screw (square or trapezoidal/Acme thread), collar friction neglected.

    With axial load ``F``, lead ``l``, mean diameter ``d_m``, thread friction ``f`` and
    (for a trapezoidal thread) the half thread angle ``alpha`` (``sec = 1/cos alpha``):

        T_raise = F d_m/2 (l + pi f d_m sec) / (pi d_m - f l sec)
        T_lower = F d_m/2 (pi f d_m sec - l) / (pi d_m + f l sec)

    ``T_lower < 0`` means the screw back-drives (not self-locking).  **Arguments** (specs):
    `lead` (m per turn), `mean_diameter` (m), `friction` (-), `thread_angle` (half angle,
    rad; 0 for a square thread).
    """

    lead: Spec = "lead"
    mean_diameter: Spec = "d_m"
    friction: Spec = "f"
    thread_angle: Spec = 0.0

    def _get(self, p) -> ScrewThread:
        l, dm, f = resolve(self.lead, p), resolve(self.mean_diameter, p), resolve(self.friction, p)
        sec = 1.0 / jnp.cos(resolve(self.thread_angle, p))
        return ScrewThread(l, dm, f, sec)

    def raise_torque(self, force, p):
        """Torque (N m) to raise (move against) axial load ``force`` (N)."""
        l, dm, f, sec = self._get(p)
        return force * dm / 2 * (l + jnp.pi * f * dm * sec) / (jnp.pi * dm - f * l * sec)

    def lower_torque(self, force, p):
        """Torque (N m) to lower (move with) axial load ``force`` (N); negative if it back-drives."""
        l, dm, f, sec = self._get(p)
        return force * dm / 2 * (jnp.pi * f * dm * sec - l) / (jnp.pi * dm + f * l * sec)

    def efficiency(self, p):
        """Raising efficiency ``F l / (2 pi T_raise)`` (-)."""
        l, *_ = self._get(p)
        return l / (2 * jnp.pi * self.raise_torque(1.0, p))

    def self_locking(self, p):
        """True where the screw holds its load with no torque (``pi f d_m sec > l``)."""
        l, dm, f, sec = self._get(p)
        return jnp.pi * f * dm * sec > l


# --------------------------------------------------------------------------- hydraulic cylinder
@dataclasses.dataclass(frozen=True)
class HydraulicCylinder:
    """Double-acting cylinder: extending force ``p_cap A_cap - p_rod (A_cap - A_rod)``.

    **Arguments** (specs): `bore` and `rod` diameters (m); `cap_pressure` and
    `rod_pressure` (Pa, gauge).  As an axial law it pushes: tension = -force.
    """

    bore: Spec = "bore"
    rod: Spec = "rod"
    cap_pressure: Spec = "p_cap"
    rod_pressure: Spec = 0.0

    def areas(self, p):
        """``(A_cap, A_annulus)`` in m^2."""
        D, d = resolve(self.bore, p), resolve(self.rod, p)
        a_cap = jnp.pi * D**2 / 4
        return a_cap, a_cap - jnp.pi * d**2 / 4

    def force(self, p, cap_pressure=None, rod_pressure=None):
        """Extending force (N); pressures default to the specs."""
        a_cap, a_ann = self.areas(p)
        pc = resolve(self.cap_pressure, p) if cap_pressure is None else cap_pressure
        pr = resolve(self.rod_pressure, p) if rod_pressure is None else rod_pressure
        return pc * a_cap - pr * a_ann

    def cap_pressure_for(self, force, p, rod_pressure=None):
        """Cap-side pressure (Pa) that gives the extending ``force`` (N)."""
        a_cap, a_ann = self.areas(p)
        pr = resolve(self.rod_pressure, p) if rod_pressure is None else rod_pressure
        return (force + pr * a_ann) / a_cap

    def __call__(self, length, rate, p, t):
        """Axial law: tension (N) = -extending force."""
        return -self.force(p)


# --------------------------------------------------------------------------- linear spring
@dataclasses.dataclass(frozen=True)
class LinearSpring:
    """Linear spring: tension ``T = preload + k (L - L0)`` (N), energy
    ``preload (L - L0) + k (L - L0)^2 / 2`` (J).  Specs: `stiffness` k (N/m),
    `length0` L0 (m, where the tension equals the preload), `preload` (N)."""

    stiffness: Spec = "k"
    length0: Spec = "L0"
    preload: Spec = 0.0

    def tension(self, length, p):
        return resolve(self.preload, p) + resolve(self.stiffness, p) * (length - resolve(self.length0, p))

    def energy(self, length, p):
        e = length - resolve(self.length0, p)
        return resolve(self.preload, p) * e + 0.5 * resolve(self.stiffness, p) * e**2

    def __call__(self, length, rate, p, t):
        return self.tension(length, p)


# --------------------------------------------------------------------------- SMA wire
@dataclasses.dataclass(frozen=True)
class SMAWire:
    """Shape-memory-alloy wire, linear-elastic branch below the transformation stresses.

    Strain is measured from the free length ``L_free = L0 (1 + prestrain)``, where the
    prestrain is the (recoverable) transformation strain (negative: a commanded
    contraction).  Stress ``sigma = E(xi) strain`` with the Young's modulus mixed linearly
    by martensite fraction, ``E = xi E_M + (1 - xi) E_A``.  The fraction is given directly
    (`fraction` spec), or from a wire `temperature` on heating by the Liang-Rogers cosine
    ``xi = (1 + cos(pi (T - A_s)/(A_f - A_s))) / 2`` between ``A_s`` and ``A_f``.
    A user constitutive law replaces all of this: ``law(strain, p) -> stress`` (Pa).

    Tension ``T = area * sigma`` (N), clipped at zero when `slack` (a wire cannot push).

    **Arguments** (specs): `area` (m^2), `length0` (m), `E_M`, `E_A` (Pa), `prestrain` (-),
    `fraction` (-) or `temperature` (K) with `A_s`, `A_f` (K); `law`; `slack`.

    **Raises** ``ValueError`` if neither `fraction` nor `temperature` is given (and no law).
    """

    area: Spec = "A_w"
    length0: Spec = "L0"
    E_M: Spec = "E_M"
    E_A: Spec = "E_A"
    prestrain: Spec = 0.0
    fraction: Spec | None = None
    temperature: Spec | None = None
    A_s: Spec = "A_s"
    A_f: Spec = "A_f"
    law: Callable | None = None
    slack: bool = True

    def __post_init__(self):
        if self.law is None and self.fraction is None and self.temperature is None:
            raise ValueError("SMAWire: give a martensite `fraction` or a wire `temperature` (or a constitutive `law`)")
        if self.law is not None and not callable(self.law):
            raise ValueError("SMAWire: `law` must be a function law(strain, p) -> stress in Pa")

    def used_specs(self) -> tuple:
        """The specs this wire reads (see ``parameter_names``)."""
        if self.law is not None:
            return self.area, self.length0, self.prestrain
        heat = (self.temperature, self.A_s, self.A_f) if self.fraction is None else (self.fraction,)
        return self.area, self.length0, self.E_M, self.E_A, self.prestrain, *heat

    def martensite_fraction(self, p):
        """Martensite fraction ``xi`` in [0, 1] (-)."""
        if self.fraction is not None:
            return resolve(self.fraction, p)
        T, a_s, a_f = resolve(self.temperature, p), resolve(self.A_s, p), resolve(self.A_f, p)
        s = jnp.clip((T - a_s) / (a_f - a_s), 0.0, 1.0)
        return 0.5 * (1.0 + jnp.cos(jnp.pi * s))

    def modulus(self, p):
        """Young's modulus ``xi E_M + (1 - xi) E_A`` (Pa)."""
        xi = self.martensite_fraction(p)
        return xi * resolve(self.E_M, p) + (1.0 - xi) * resolve(self.E_A, p)

    def strain(self, length, p):
        """``L / (L0 (1 + prestrain)) - 1`` (-)."""
        return length / (resolve(self.length0, p) * (1.0 + resolve(self.prestrain, p))) - 1.0

    def stress(self, strain, p):
        """Stress (Pa) from the user law, or the linear branch ``E(xi) strain``."""
        if self.law is not None:
            return self.law(strain, p if isinstance(p, Vars) else Vars(p))
        return self.modulus(p) * strain

    def tension(self, length, p):
        T = resolve(self.area, p) * self.stress(self.strain(length, p), p)
        return jnp.maximum(T, 0.0) if self.slack else T

    def __call__(self, length, rate, p, t):
        return self.tension(length, p)
