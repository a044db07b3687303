"""The model spec: rigid bodies and loads on a mechanism, and the model's parameters.

A ``Model`` adds to a ``Mechanism`` its rigid ``Body``s (pose functions and mass
properties; massless links are not bodies) and its loads (``PointForce``, ``Moment``,
``Gravity``, ``Axial`` two-point elements such as springs and SMA wires, ``Potential``).
Everything in a model is static structure (names, functions, parameter specs); every
number comes from the parameters ``p``, so one compiled function serves every design.
The model's own parameters (masses, load coefficients) and its actuators' are declared on
it, not on the mechanism; one ``p`` mapping carries them all, merged by name.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import jax.numpy as jnp

from ..actuators import Spec, parameter_names, resolve
from ..mechanism.mechanism import Mechanism, check_parameters
from .joints import GROUND, JOINT_TYPES, Actuator, Layout, joint_name, layout

__all__ = [
    "Body",
    "PointForce",
    "Moment",
    "Gravity",
    "Axial",
    "Potential",
    "Model",
    "geometry",
    "masses",
    "prepare_params",
    "mechanism_params",
    "point_of",
    "angle_of",
]

PointSpec = str | Callable  # name of a mechanism point, or fn(q, u, p) -> complex
AngleSpec = str | Callable  # name of a coordinate or input, or fn(q, u, p) -> real


@dataclasses.dataclass(frozen=True, eq=False)
class Body:
    """A rigid body: centre of mass, orientation and mass properties.

    **Arguments**

    - `position`: centre of mass ``r_G`` (m, complex ``x + i y``): a mechanism point name or
      ``fn(q, u, p) -> complex``.
    - `mass`: ``m`` (kg), a spec (parameter name, number or ``fn(p)``).
    - `angle`: body angle ``phi`` (rad, CCW): a coordinate/input name or ``fn(q, u, p)``;
      ``None`` for a point mass.
    - `inertia`: ``J`` about the centre of mass (kg m^2), a spec; needs an `angle`.
    - `name`: for messages.
    """

    position: PointSpec
    mass: Spec
    angle: AngleSpec | None = None
    inertia: Spec = 0.0
    name: str = "body"


@dataclasses.dataclass(frozen=True, eq=False)
class PointForce:
    """A force ``F`` (N, complex ``Fx + i Fy``) applied at a point.

    - `point`: mechanism point name or ``fn(q, u, p) -> complex`` (m).
    - `force`: ``fn(q, u, p, v, t) -> complex``; ``v`` holds the velocities of every
      coordinate and input by name (``v.theta2`` in rad/s), ``t`` the time (s).
      Example, lift normal to a chord at angle ``-delta``:
      ``lambda q, u, p, v, t: p.qS_Cl * q.delta * 1j * cis(-q.delta)``.
    """

    point: PointSpec
    force: Callable
    name: str = "force"
    body: str | None = None  #: the body it acts on (needed for joint reactions)


@dataclasses.dataclass(frozen=True, eq=False)
class Moment:
    """A pure moment ``M`` (N m, positive in the sense of increasing `angle`).

    - `angle`: the angle it works on: a body angle ``fn(q, u, p)``, or the name of a
      coordinate or input, which makes ``M`` a generalized force on that coordinate (the
      power term ``M * coord_dot``, e.g. an aerodynamic hinge moment ``M_AC * delta_dot``).
    - `moment`: ``fn(q, u, p, v, t) -> real``.
    - `body`: for joint reactions, the body it acts on (its reaction on ground), or a pair
      ``(a, b)``: ``M`` on b and ``-M`` on a (a torsion spring between two links); `angle`
      must then be b's angle (less a's).
    """

    angle: AngleSpec
    moment: Callable
    name: str = "moment"
    body: str | tuple[str, str] | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Gravity:
    """Uniform gravity on every body: force ``m g direction`` at its centre of mass.

    - `g`: spec (m/s^2), default the parameter ``"g"``.
    - `direction`: unit complex direction, default ``-1j`` (down).
    """

    g: Spec = "g"
    direction: complex = -1j
    name: str = "gravity"


@dataclasses.dataclass(frozen=True, eq=False)
class Axial:
    """A two-point element (spring, SMA wire, cylinder, damper) between points `a` and `b`.

    - `a`, `b`: point names or ``fn(q, u, p)``.
    - `law`: ``law(length, rate, p, t) -> tension`` (N, positive pulls the ends together);
      every ``jaxmech.actuators`` axial law (``LinearSpring``, ``SMAWire``,
      ``HydraulicCylinder``) is one.  Its virtual power is ``-T dL``.
    - `bodies`: for joint reactions, the bodies ``(A, B)`` that carry `a` and `b`.
    """

    a: PointSpec
    b: PointSpec
    law: Callable
    name: str = "axial"
    bodies: tuple[str, str] | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Potential:
    """A potential energy ``V`` (J): ``energy(q, u, p, t) -> real``; its force is ``-dV/dx``."""

    energy: Callable
    name: str = "potential"


_LOADS = (PointForce, Moment, Gravity, Axial, Potential)


@dataclasses.dataclass(frozen=True, eq=False)
class Model:
    """A mechanism with bodies and loads (static; hashable by identity for jit).

    **Arguments**

    - `mechanism`: the ``Mechanism``.
    - `bodies`: sequence of ``Body``.
    - `loads`: sequence of ``PointForce``, ``Moment``, ``Gravity``, ``Axial``, ``Potential``.
    - `params`: the model's own parameters: masses, inertias, load coefficients, anything
      no constraint uses.  They are not the mechanism's: the mechanism declares only what
      its constraints and points need.  Bodies and loads may use the mechanism's
      parameters too (a chord length), by name.
    - `actuators`: actuators the model is driven or loaded with (a ``DCMotor``); each
      declares the parameters its specs name (``actuators.parameter_names``), as does
      every actuator used as an ``Axial`` law.
    - `joints`: optional ``Revolute``, ``Prismatic``, ``Slot`` and ``Actuator`` joints between
      the bodies (by ``Body.name``, or ``"ground"``): with them, inverse dynamics and statics
      give every joint's reaction from the per-body Newton-Euler equations
      (``dynamics.joints``).  Every moving link is then a body (massless ones with mass 0),
      every body has an angle, every input drives one joint, and every load but gravity
      says which body it acts on (``body=``; ``Potential`` loads cannot be placed).
    - `program_key`: what identifies this model's compiled programs across processes (a
      ``Linkage`` sets it from its topology, so a new process loads them from the store);
      None (the default): the model is known by its parts, so one made of the library's
      bodies, loads and joints over a mechanism is stored too, and one holding a function
      of your own (a load's callback) is not.

    A model's parameters (``parameters``) are the mechanism's, then its own, then its
    actuators', merged by name: one ``p`` mapping carries them all, and each function
    takes from it what it uses.

    **Raises** ``ValueError`` for an unknown point, coordinate or parameter name, a body
    with inertia but no angle, or a clash: a parameter declared both by the mechanism and
    in `params`, or a parameter named like a coordinate or input.
    """

    mechanism: Mechanism
    bodies: Sequence[Body] = ()
    loads: Sequence = ()
    params: Sequence[str] = ()
    actuators: Sequence = ()
    joints: Sequence = ()
    program_key: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(self.joints))
        object.__setattr__(self, "bodies", tuple(self.bodies))
        object.__setattr__(self, "loads", tuple(self.loads))
        object.__setattr__(self, "params", (self.params,) if isinstance(self.params, str) else tuple(self.params))
        object.__setattr__(self, "actuators", tuple(self.actuators))
        mech = self.mechanism
        names = mech.coords + mech.inputs
        for n in self.params:
            if not isinstance(n, str) or not n.isidentifier():
                raise ValueError(f"params: {n!r} is not a valid name (use Python identifiers)")
            if n in mech.params:
                raise ValueError(f"params: {n!r} is declared by both the mechanism {mech.name!r} and the model; "
                                 f"declare it once (the model uses the mechanism's parameters by name)")
        if len(set(self.params)) != len(self.params):
            raise ValueError(f"params: duplicate names in {self.params}")
        for n in self.parameters:
            if n in names:
                raise ValueError(f"parameter {n!r} has the name of a coordinate or input of {mech.name!r}; rename it")
        known = self.parameters

        def check_point(spec, what):
            if isinstance(spec, str) and spec not in mech.points:
                raise ValueError(f"{what}: unknown point {spec!r}; {mech.name} defines points {list(mech.points)}")
            if not isinstance(spec, str) and not callable(spec):
                raise ValueError(f"{what}: a point is a point name or fn(q, u, p) -> complex")

        def check_angle(spec, what):
            if isinstance(spec, str) and spec not in names:
                raise ValueError(f"{what}: unknown coordinate or input {spec!r}; known: {list(names)}")

        def check_spec(spec, what):
            if isinstance(spec, str) and spec not in known:
                raise ValueError(f"{what}: unknown parameter {spec!r}; the model's parameters are {list(known)} "
                                 f"(declare a model parameter in Model(params=...))")

        for b in self.bodies:
            if not isinstance(b, Body):
                raise ValueError(f"bodies: expected Body, got {type(b).__name__}")
            check_point(b.position, f"body {b.name!r}")
            check_spec(b.mass, f"body {b.name!r} mass")
            check_spec(b.inertia, f"body {b.name!r} inertia")
            if b.angle is None and not (isinstance(b.inertia, (int, float)) and b.inertia == 0):
                raise ValueError(f"body {b.name!r}: an inertia needs an angle (give angle=...)")
            if b.angle is not None:
                check_angle(b.angle, f"body {b.name!r}")
        for ld in self.loads:
            if not isinstance(ld, _LOADS):
                raise ValueError(f"loads: expected one of {[c.__name__ for c in _LOADS]}, got {type(ld).__name__}")
            if isinstance(ld, PointForce):
                check_point(ld.point, f"load {ld.name!r}")
            elif isinstance(ld, Moment):
                check_angle(ld.angle, f"load {ld.name!r}")
            elif isinstance(ld, Axial):
                check_point(ld.a, f"load {ld.name!r}")
                check_point(ld.b, f"load {ld.name!r}")
            elif isinstance(ld, Gravity):
                check_spec(ld.g, f"load {ld.name!r}")
        if self.joints:
            self._check_joints(check_point, check_angle)

    def _check_joints(self, check_point, check_angle):
        mech = self.mechanism
        names = [b.name for b in self.bodies]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"{mech.name}: bodies {dup} share a name; joints name bodies, so give each body its own name=")
        if GROUND in names:
            raise ValueError(f"{mech.name}: {GROUND!r} names the fixed frame; give the body another name")
        for b in self.bodies:
            if b.angle is None:
                raise ValueError(f"{mech.name}: body {b.name!r} needs angle= for joint reactions (a rigid body turns)")
        for j in self.joints:
            if not isinstance(j, JOINT_TYPES):
                raise ValueError(f"joints: expected one of {[c.__name__ for c in JOINT_TYPES]}, got {type(j).__name__}")
            what = f"joint {joint_name(j)!r}"
            for pt in (j.points if isinstance(j, Actuator) else (j.point,)):
                check_point(pt, what)
            if getattr(j, "angle", None) is not None:
                check_angle(j.angle, what)
            if getattr(j, "center", None) is not None:
                check_point(j.center, what)
        known = set(names) | {GROUND}
        for ld in self.loads:
            where_ = ld.bodies if isinstance(ld, Axial) else getattr(ld, "body", None)
            if isinstance(ld, Gravity):
                continue
            if isinstance(ld, Potential):
                raise ValueError(f"load {ld.name!r}: a Potential has no point of application, so the joint reactions "
                                 f"cannot place it; give it as a PointForce, Moment or Axial with body=")
            if where_ is None:
                raise ValueError(f"load {ld.name!r}: say which body it acts on ({'bodies=(A, B)' if isinstance(ld, Axial) else 'body='}) "
                                 f"so that the joint reactions can place it; bodies are {names}")
            for b in ((where_,) if isinstance(where_, str) else tuple(where_)):
                if b not in known:
                    raise ValueError(f"load {ld.name!r}: unknown body {b!r}; bodies are {names} and {GROUND!r}")
        self.layout  # noqa: B018 - checks that the reactions are determined, eagerly

    @functools.cached_property
    def layout(self) -> Layout | None:
        """The static shape of the Newton-Euler system of the joint reactions (None without
        joints); raises ``ValueError`` when the joints do not determine them."""
        if not self.joints:
            return None
        return layout(tuple(b.name for b in self.bodies), self.joints, self.mechanism.inputs, self.mechanism.name)

    @property
    def parameters(self) -> tuple[str, ...]:
        """Every parameter name of the model: the mechanism's, its own (`params`), then those
        its actuators and actuator laws declare, once each."""
        laws = [ld.law for ld in self.loads if isinstance(ld, Axial)]
        acts = [n for a in (*self.actuators, *laws) for n in parameter_names(a)]
        return tuple(dict.fromkeys(self.mechanism.params + self.params + tuple(acts)))

    def check_params(self, p: Mapping, extra: Sequence[str] = ()) -> None:
        """Eager checks of a parameter mapping against ``parameters`` (and the `extra` names
        a call adds: a motor's, a voltage's); raises ``ValueError`` naming the parameter.

        Names: none missing, none unknown.  Values where concrete: finite, and the
        mechanism's own checks (positive lengths) on its parameters.
        """
        mech = self.mechanism
        names = tuple(dict.fromkeys(self.parameters + tuple(extra)))
        check_parameters(mech.name, p, names, mech.lengths, mech.signed, whose="this model's")


def point_of(mech: Mechanism, spec, q, u, p):
    if isinstance(spec, str):
        return mech.point(spec, q, u, p)
    return jnp.asarray(spec(mech.vars_q(q), mech.vars_u(u), mech.vars_p(p)))


def angle_of(mech: Mechanism, spec, q, u, p):
    if isinstance(spec, str):
        if spec in mech.coords:
            return q[mech.coords.index(spec)]
        return u[mech.inputs.index(spec)]
    return jnp.asarray(spec(mech.vars_q(q), mech.vars_u(u), mech.vars_p(p)))


class Geometry(NamedTuple):
    """Every pose the loads and inertia need at one state (``geometry``), lists of arrays (a
    pytree, for nested jvp; unpacks like the 5-tuple it replaces): the bodies' centres of
    mass `r_g` (complex, m) and angles `phi` (rad), the points of the ``PointForce`` loads
    (complex, m), the angles of the ``Moment`` loads (rad) and the lengths of the ``Axial``
    loads (m), each in the model's load order."""

    r_g: list
    phi: list
    load_points: list
    load_angles: list
    axial_lengths: list


def geometry(model: Model, q, u, p) -> Geometry:
    """Every pose the loads and inertia need at one state: a ``Geometry`` ``(r_G, phi, load
    points, load angles, axial lengths)`` (for nested jvp)."""
    mech = model.mechanism
    rg = [point_of(mech, b.position, q, u, p) for b in model.bodies]
    ph = [angle_of(mech, b.angle, q, u, p) if b.angle is not None else jnp.zeros((), q.dtype) for b in model.bodies]
    lp, la, ll = [], [], []
    for ld in model.loads:
        if isinstance(ld, PointForce):
            lp.append(point_of(mech, ld.point, q, u, p))
        elif isinstance(ld, Moment):
            la.append(angle_of(mech, ld.angle, q, u, p))
        elif isinstance(ld, Axial):
            ll.append(jnp.abs(point_of(mech, ld.a, q, u, p) - point_of(mech, ld.b, q, u, p)))
    return Geometry(rg, ph, lp, la, ll)


def masses(model: Model, p):
    """``([m_k], [J_k])`` of the bodies (kg, kg m^2) for parameters ``p``."""
    return [resolve(b.mass, p) for b in model.bodies], [resolve(b.inertia, p) for b in model.bodies]



def prepare_params(model: Model, p, dtype, extra: Sequence[str] = ()):
    """Checked parameters as arrays of ``dtype``: the model's and the call's `extra` names."""
    model.check_params(p, extra)
    return {k: jnp.asarray(p[k], dtype) for k in dict.fromkeys(model.parameters + tuple(extra))}


def mechanism_params(model: Model, p):
    """The mechanism's share of a checked model parameter mapping (for its position solves)."""
    return {k: p[k] for k in model.mechanism.params}

