"""Springs and dampers as elements of a linkage: read from ``Linkage(springs=...,
torsion_springs=..., gas_springs=..., dampers=..., rotary_dampers=...)`` or from the same
tables of a linkage file, and turned into the model's loads.

A two-point element (a linear spring, a gas spring, a linear damper) is an ``Axial`` load
between two points of the drawing: a tension ``T`` (N, positive pulls its ends together)
from its length ``L`` and rate ``dL/dt``.  A rotational element (a torsion spring, a
rotary damper) is a ``Moment`` between two bodies (two links, or a link and ground): ``M``
(N m) on the second body and ``-M`` on the first, from the rotation of the second relative
to the first.  As loads of the model they enter inverse dynamics, statics, equilibrium and
every joint's reaction like any other; their numbers are named parameters of the linkage,
so that sweeps and designs vary them:

| element | law | parameters |
|---|---|---|
| spring | ``T = F0 + k (L - L0)`` | ``k_`` N/m, ``L0_`` m, ``F0_`` N |
| torsion spring | ``M = -kt (phi_b - phi_a - phi0)`` | ``kt_`` N m/rad, ``phi0_`` rad |
| gas spring | push ``F = F0`` (constant) | ``F0_`` N |
| gas spring, polytropic | push ``F = F0 (Lg / (Lg - (L0 - L)))^n`` | ``F0_`` N, ``L0_`` m, ``Lg_`` m, ``n_`` - |
| damper | ``T = c dL/dt`` | ``c_`` N s/m |
| rotary damper | ``M = -ct (omega_b - omega_a)`` | ``ct_`` N m s/rad |

``phi_a``, ``phi_b`` are the angles of the two bodies' frames (ground's is 0); ``phi0_``'s
value in ``Linkage.params`` is their difference in the drawing plus the spring's free angle.
A gas spring's polytropic law is the gas column's: ``Lg`` the length of gas (volume over
the rod's area) at the length ``L0`` where it pushes with ``F0``; compressed by
``x = L0 - L`` it holds ``Lg - x``; ``n = 1`` isothermal, ``1.4`` adiabatic (air).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import NamedTuple

import jax.numpy as jnp

from ..actuators import LinearSpring, Spec, resolve
from ..dynamics.model import Axial, Moment
from ..mechanism.mechanism import Vars
from ..names import did_you_mean, near_hint
from .terms import angle_value
from .values import read_names, read_number

__all__ = ["ARGUMENTS", "Element", "STORING", "DISSIPATING", "read_elements", "element_parameters", "element_loads",
           "load_name", "drawing_values"]

GROUND = "ground"

#: ``Linkage`` argument (and linkage file table) -> element kind.
ARGUMENTS = {"springs": "spring", "torsion_springs": "torsion_spring", "gas_springs": "gas_spring", "dampers": "damper",
             "rotary_dampers": "rotary_damper"}
#: The keys each kind takes.
KEYS = {"spring": ("between", "on", "k", "free_length", "preload"), "torsion_spring": ("at", "links", "k", "free_angle"),
        "gas_spring": ("between", "on", "force", "length", "gas_length", "n"), "damper": ("between", "on", "c"),
        "rotary_damper": ("at", "links", "c")}
#: The kinds that store energy, and those that dissipate it (``Linkage.power``).
STORING = ("spring", "torsion_spring", "gas_spring")
DISSIPATING = ("damper", "rotary_damper")


class Element(NamedTuple):
    """One spring or damper of a linkage (static, hashable: part of its ``Topology``).

    - `kind`: ``"spring"``, ``"torsion_spring"``, ``"gas_spring"``, ``"damper"`` or
      ``"rotary_damper"``; `name`: the user's (its parameters are ``k_<name>``...).
    - `points`: a two-point element's ends ``(a, b)``; ``()`` for a rotational one.
    - `bodies`: the bodies carrying the ends ``(a, b)``, or the two bodies a rotational
      element acts between (its moment on the second, minus it on the first).
    - `polytropic`: a gas spring with a pressure law (False: a constant force).
    """

    kind: str
    name: str
    points: tuple
    bodies: tuple
    polytropic: bool = False


class Elements(NamedTuple):
    """A linkage's elements as read (``read_elements``): their `specs` and the values of
    their parameters (a torsion spring's ``phi0_`` its free angle from the drawing, until
    ``drawing_values`` adds the drawing's relative angle)."""

    specs: tuple
    values: dict


@dataclasses.dataclass(frozen=True)
class GasSpring:
    """A gas spring's tension (N, an ``Axial`` law; negative: it pushes its ends apart):
    ``T = -F0`` for a constant force (`gas_length` None), else the polytropic gas column's
    ``T = -F0 (Lg / (Lg - (L0 - L)))^n``.  Specs: `force` F0 (N, the push at ``L0``),
    `length0` L0 (m), `gas_length` Lg (m), `n` (-).  NaN once the column is used up
    (``L <= L0 - Lg``: bottomed out)."""

    force: Spec = "F0"
    length0: Spec | None = None
    gas_length: Spec | None = None
    n: Spec | None = None

    def __call__(self, length, rate, p, t):
        push = resolve(self.force, p)
        if self.gas_length is None:
            return -push + 0.0 * length
        lg = resolve(self.gas_length, p)
        left = lg + length - resolve(self.length0, p)
        return -push * jnp.where(left > 0, lg / jnp.where(left > 0, left, 1.0), jnp.nan) ** resolve(self.n, p)


@dataclasses.dataclass(frozen=True)
class LinearDamper:
    """A linear damper's tension (N, an ``Axial`` law): ``T = c dL/dt``, resisting the rate
    of change of its length.  Spec: `coefficient` c (N s/m)."""

    coefficient: Spec = "c"

    def __call__(self, length, rate, p, t):
        return resolve(self.coefficient, p) * rate


def element_parameters(e: Element) -> tuple[str, ...]:
    """The names of an element's parameters (see the module docstring)."""
    n = e.name
    return {"spring": (f"k_{n}", f"L0_{n}", f"F0_{n}"), "torsion_spring": (f"kt_{n}", f"phi0_{n}"),
            "gas_spring": (f"F0_{n}", f"L0_{n}", f"Lg_{n}", f"n_{n}") if e.polytropic else (f"F0_{n}",),
            "damper": (f"c_{n}",), "rotary_damper": (f"ct_{n}",)}[e.kind]


def load_name(e: Element) -> str:
    """The name of an element's load in the model: ``"spring s1"``, ``"torsion spring t1"``."""
    return f"{e.kind.replace('_', ' ')} {e.name}"


# --------------------------------------------------------------------------- loads
def _axial_law(e: Element):
    n = e.name
    if e.kind == "spring":
        return LinearSpring(stiffness=f"k_{n}", length0=f"L0_{n}", preload=f"F0_{n}")
    if e.kind == "damper":
        return LinearDamper(f"c_{n}")
    if e.polytropic:
        return GasSpring(f"F0_{n}", f"L0_{n}", f"Lg_{n}", f"n_{n}")
    return GasSpring(f"F0_{n}")


def _rate(angle, v):
    """The time derivative (rad/s) of an angle given as signed names: the velocities `v` of
    the coordinates and inputs among them (the parameters' are zero)."""
    return sum((s * v[name] for s, name in angle if name in v), 0.0)


def _rotational(e: Element, theta, lookup) -> Moment:
    """A torsion spring's or rotary damper's ``Moment`` on its second body (minus it on the
    first), working on the second body's angle less the first's."""
    th_a, th_b = theta(e.bodies[0]), theta(e.bodies[1])

    def relative(q, u, p):
        look = lookup(q, u, p)
        return angle_value(th_b, look) - angle_value(th_a, look)

    n = e.name
    if e.kind == "torsion_spring":
        def moment(q, u, p, v, t):
            return -p[f"kt_{n}"] * (relative(q, u, p) - p[f"phi0_{n}"])
    else:
        def moment(q, u, p, v, t):
            return -p[f"ct_{n}"] * (_rate(th_b, v) - _rate(th_a, v))
    return Moment(relative, moment, name=load_name(e), body=tuple(e.bodies))


def element_loads(elements, theta, lookup) -> list:
    """The model's loads of a linkage's `elements`: an ``Axial`` per two-point element, a
    ``Moment`` per rotational one.  `theta(body)`: a body's angle as signed names (ground
    none); `lookup(q, u, p)`: a name -> value function over coordinates, inputs and
    parameters (``topology``'s)."""
    loads = []
    for e in elements:
        if e.points:
            loads.append(Axial(e.points[0], e.points[1], _axial_law(e), name=load_name(e), bodies=tuple(e.bodies)))
        else:
            loads.append(_rotational(e, theta, lookup))
    return loads


def drawing_values(model, elements: Elements, guess, u0, vals: Mapping) -> dict:
    """The elements' parameter values for a drawing: a torsion spring's ``phi0_`` is its
    free angle plus its two bodies' relative angle in the drawing (the model's own angle
    function at the drawing's coordinates `guess` and inputs `u0`, with the drawing's
    parameter values `vals`)."""
    mech = model.mechanism
    out = dict(elements.values)
    q, u, p = Vars(dict(zip(mech.coords, map(float, guess)))), Vars(dict(zip(mech.inputs, map(float, u0)))), Vars(dict(vals))
    angles = {ld.name: ld.angle for ld in model.loads if isinstance(ld, Moment)}
    for e in elements.specs:
        if e.kind == "torsion_spring":
            out[f"phi0_{e.name}"] += float(angles[load_name(e)](q, u, p))
    return out


# --------------------------------------------------------------------------- reading
class _Drawing(NamedTuple):
    """What reading an element needs of the drawing: the linkage's name for messages, the
    points (complex, m), the links' points and the ground points."""

    name: str
    points: dict
    links: dict
    ground: tuple


def _owners(d: _Drawing, x: str) -> list:
    """The bodies that carry point `x` (ground first)."""
    return ([GROUND] if x in d.ground else []) + [k for k, pts in d.links.items() if x in pts]


def _ends(d: _Drawing, spec: Mapping, what: str):
    """``(points, bodies)`` of a two-point element: ``between`` two points, each carried by
    its only body or by the one ``on`` names."""
    if "between" not in spec:
        raise ValueError(f"{d.name}: {what} needs between = [a, b], the two points it joins")
    pts = read_names(spec["between"], f"{what}.between")
    if len(pts) != 2 or pts[0] == pts[1] or any(x not in d.points for x in pts):
        raise ValueError(f"{d.name}: {what}.between names two different points of the drawing, got {spec['between']!r}"
                         f"{near_hint(pts, d.points)}")
    if abs(d.points[pts[0]] - d.points[pts[1]]) == 0.0:
        raise ValueError(f"{d.name}: {what}: points {pts[0]!r} and {pts[1]!r} are at one place in the drawing; "
                         "an element between them has no direction (draw them apart)")
    on = read_names(spec["on"], f"{what}.on") if "on" in spec else (None, None)
    if len(on) != 2:
        raise ValueError(f"{d.name}: {what}.on names the two bodies carrying its ends (a link or 'ground' each), got {spec['on']!r}")
    bodies = []
    for x, body in zip(pts, on):
        owners = _owners(d, x)
        if body is None and len(owners) != 1:
            raise ValueError(f"{d.name}: {what}: point {x!r} is on {owners}; say which carries the end: "
                             f"on = [body at {pts[0]!r}, body at {pts[1]!r}]")
        if body is not None and body not in owners:
            raise ValueError(f"{d.name}: {what}.on: {body!r} does not carry point {x!r}, which is on {owners}; "
                             f"{did_you_mean(body, owners, 'bodies')}")
        bodies.append(owners[0] if body is None else body)
    return pts, tuple(bodies)


def _pair(d: _Drawing, spec: Mapping, what: str) -> tuple:
    """The two bodies a rotational element acts between: the two that the pin ``at`` joins,
    or ``links = [a, b]`` (a link and 'ground' for one to the frame)."""
    if ("at" in spec) == ("links" in spec):
        raise ValueError(f"{d.name}: {what} needs at = a pin (the two links it joins) or links = [a, b] (a link and "
                         "'ground' for one to the frame), one of them")
    if "at" in spec:
        x = spec["at"]
        if x not in d.points:
            raise ValueError(f"{d.name}: {what}.at: {x!r} is not a point; {did_you_mean(str(x), d.points, 'points')}")
        bodies = _owners(d, x)
        if len(bodies) != 2:
            raise ValueError(f"{d.name}: {what}.at: the point {x!r} joins {bodies}, not two bodies; "
                             "give the two it acts between: links = [a, b]")
        return tuple(bodies)
    bodies = read_names(spec["links"], f"{what}.links")
    known = [GROUND, *d.links]
    for b in bodies:
        if b not in known:
            raise ValueError(f"{d.name}: {what}.links: {b!r} is not a link or 'ground'; {did_you_mean(b, known, 'links')}")
    if len(bodies) != 2 or bodies[0] == bodies[1]:
        raise ValueError(f"{d.name}: {what}.links names two different bodies (a link and 'ground' for the frame), got {spec['links']!r}")
    return tuple(bodies)


def _not_negative(spec: Mapping, key: str, unit: str, what: str, default=None) -> float:
    """``spec[key]`` in `unit`, refused when negative (a stiffness, a damping: a negative one
    would put energy in), or missing without a `default`."""
    if key not in spec and default is not None:
        return default
    if key not in spec:
        raise ValueError(f"{what} needs {key} (in {unit})")
    x = read_number(spec[key], unit, f"{what}.{key}")
    if x < 0:
        raise ValueError(f"{what}.{key} must not be negative, got {spec[key]!r}")
    return x


def _spring(d: _Drawing, n: str, spec: Mapping, what: str):
    pts, bodies = _ends(d, spec, what)
    drawn = abs(d.points[pts[0]] - d.points[pts[1]])
    free = read_number(spec.get("free_length", drawn), "m", f"{what}.free_length")
    if free <= 0:
        raise ValueError(f"{what}.free_length must be positive, got {spec['free_length']!r}")
    values = {f"k_{n}": _not_negative(spec, "k", "N/m", what), f"L0_{n}": free,
              f"F0_{n}": read_number(spec.get("preload", 0.0), "N", f"{what}.preload")}
    return Element("spring", n, pts, bodies), values


def _gas_spring(d: _Drawing, n: str, spec: Mapping, what: str):
    pts, bodies = _ends(d, spec, what)
    if "force" not in spec:
        raise ValueError(f"{what} needs force (N, its push; at length= where it has a gas_length)")
    values = {f"F0_{n}": read_number(spec["force"], "N", f"{what}.force")}
    if "gas_length" not in spec:
        extra = [k for k in ("length", "n") if k in spec]
        if extra:
            raise ValueError(f"{what}: {extra} need gas_length (m, the gas column at length=); without it the force is constant")
        return Element("gas_spring", n, pts, bodies), values
    lg = read_number(spec["gas_length"], "m", f"{what}.gas_length")
    length = read_number(spec.get("length", abs(d.points[pts[0]] - d.points[pts[1]])), "m", f"{what}.length")
    if lg <= 0 or length <= 0:
        raise ValueError(f"{what}: gas_length and length must be positive, got {lg} and {length} m")
    if lg + abs(d.points[pts[0]] - d.points[pts[1]]) - length <= 0:
        raise ValueError(f"{what}: the drawing compresses the gas spring past its gas_length ({lg} m from length {length} m); "
                         "give a longer gas_length or a shorter length")
    values.update({f"L0_{n}": length, f"Lg_{n}": lg, f"n_{n}": _not_negative(spec, "n", "-", what, 1.0)})
    return Element("gas_spring", n, pts, bodies, True), values


def _torsion_spring(d: _Drawing, n: str, spec: Mapping, what: str):
    values = {f"kt_{n}": _not_negative(spec, "k", "N m/rad", what),
              f"phi0_{n}": read_number(spec.get("free_angle", 0.0), "rad", f"{what}.free_angle")}
    return Element("torsion_spring", n, (), _pair(d, spec, what)), values


def _damper(d: _Drawing, n: str, spec: Mapping, what: str):
    pts, bodies = _ends(d, spec, what)
    return Element("damper", n, pts, bodies), {f"c_{n}": _not_negative(spec, "c", "N s/m", what)}


def _rotary_damper(d: _Drawing, n: str, spec: Mapping, what: str):
    return Element("rotary_damper", n, (), _pair(d, spec, what)), {f"ct_{n}": _not_negative(spec, "c", "N m s/rad", what)}


_READERS = {"spring": _spring, "torsion_spring": _torsion_spring, "gas_spring": _gas_spring, "damper": _damper,
            "rotary_damper": _rotary_damper}


def read_elements(name: str, points: Mapping, links: Mapping, ground, given: Mapping) -> Elements:
    """The springs and dampers of a linkage, checked against its drawing.

    **Arguments**: `name` (for messages); `points` ``{point: complex (m)}``; `links`
    ``{link: [points]}`` (slider blocks included, actuators not: an element's end is on a
    link or on ground); `ground` the ground points; `given` ``{argument: {element: spec}}``
    for the arguments of ``ARGUMENTS`` (None or absent: none).

    **Raises** ``ValueError`` naming the element and what to give: an unknown key, a point
    or link not in the drawing, an end carried by several bodies without ``on``, a missing
    or negative stiffness or damping, a name used twice."""
    d = _Drawing(name, dict(points), dict(links), tuple(ground))
    specs, values, seen = [], {}, {}
    for arg, kind in ARGUMENTS.items():
        for n, spec in dict(given.get(arg) or {}).items():
            what = f"{arg}[{n!r}]"
            if not isinstance(n, str) or not n.isidentifier():
                raise ValueError(f"{name}: {what}: an element's name is a Python identifier (letters, digits, _): "
                                 "its parameters are named after it (k_<name>)")
            if n in seen:
                raise ValueError(f"{name}: {what}: the name {n!r} is taken by {seen[n]}; give each element its own name")
            if not isinstance(spec, Mapping):
                raise ValueError(f"{name}: {what}: give a table of keys ({', '.join(KEYS[kind])}), got {spec!r}")
            unknown = [k for k in spec if k not in KEYS[kind]]
            if unknown:
                raise ValueError(f"{name}: {what}: unknown key(s) {unknown}; it takes {', '.join(KEYS[kind])}"
                                 f"{near_hint(unknown, KEYS[kind])}")
            seen[n] = what
            try:
                element, vals = _READERS[kind](d, n, spec, what)
            except ValueError as err:  # said once in the linkage's name
                raise ValueError(f"{name}: {str(err).removeprefix(f'{name}: ')}") from None
            specs.append(element)
            values.update(vals)
    return Elements(tuple(specs), values)
