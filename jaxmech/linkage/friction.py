"""A linkage's joint friction as the user writes it (``Linkage(friction=...)``): which pins,
sliders and slots carry friction, with which coefficient, pin radius and viscous damping,
read into the static ``dynamics.friction.JointFriction`` and the values of its parameters.

``friction={"all": {"mu": 0.1, "radius": "5 mm"}, "B": {"mu": 0.2, "radius": "8 mm"},
"block_B": {"mu": 0.15, "damping": 2.0}, "width": 1e-3}``: ``"all"`` every pin, slider and
slot (a slider or a slot takes its ``mu`` and ignores ``radius``); a joint by its name
(``Linkage.joints``: ``"B"``, ``"block_B on ground"``, ``"P in arm"``) or its short key (a
slider's block, a slot's pin) overrides ``"all"`` key by key.  Per entry: `mu` the Coulomb
coefficient (-), `radius` the pin's radius (m, or a string with a unit), `damping` the
viscous coefficient (N m s/rad at a pin, N s/m in a guide).  ``width``: the regularised
sign's band as a fraction of each joint's largest speed (``dynamics.friction``).

The parameters (``Linkage.params``, so sweeps and designs vary them): ``mu_<key>``,
``rpin_<key>`` for a pin, ``cv_<key>`` where damping is given; ``<key>`` the pin's point
(``B_rocker`` where pins share a point), the slider's block, the slot's pin.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from ..dynamics.friction import FrictionJoint, JointFriction
from ..dynamics.inverse import Holding, holding
from ..dynamics.joints import Prismatic, Revolute, Slot, joint_name
from ..names import did_you_mean, near_hint
from .values import read_number

__all__ = ["read_friction", "friction_key", "linkage_holding"]

FIELDS = {"mu": "-", "radius": "m", "damping": None}


def friction_key(joint) -> str:
    """The suffix of a joint's friction parameters: a pin's point, a slider's block, a slot's pin."""
    name = joint_name(joint)
    head = name.split(" on ")[0].split(" in ")[0]
    return re.sub(r"\W", "_", head)


def _entry(lk_name: str, key: str, spec) -> dict:
    if not isinstance(spec, Mapping):
        raise ValueError(f"{lk_name}: friction[{key!r}] must be a table like {{\"mu\": 0.1, \"radius\": \"5 mm\"}}, got {spec!r}")
    unknown = [k for k in spec if k not in FIELDS]
    if unknown:
        raise ValueError(f"{lk_name}: friction[{key!r}]: unknown key(s) {unknown}; the keys are {list(FIELDS)}"
                         f"{near_hint(unknown, FIELDS)}")
    return dict(spec)


def _values(lk_name: str, key: str, j, spec: dict) -> dict:
    """``{field: value}`` of one joint's friction, checked (SI)."""
    pin = isinstance(j, Revolute)
    if "radius" in spec and not pin and key != "all":
        raise ValueError(f"{lk_name}: friction[{key!r}]: {joint_name(j)!r} is a slider or slot: it has no pin radius; leave radius out")
    unit = "N m s/rad" if pin else "N s/m"
    out = {f: read_number(spec[f], FIELDS[f] or unit, f"friction[{key!r}].{f}") for f in ("mu", "damping") if f in spec}
    if pin and "mu" in spec:
        if "radius" not in spec:
            raise ValueError(f"{lk_name}: friction at pin {joint_name(j)!r} needs its radius= (m, or '5 mm')")
        out["radius"] = read_number(spec["radius"], "m", f"friction[{key!r}].radius")
    for f, v in out.items():
        if v < 0:
            raise ValueError(f"{lk_name}: friction[{key!r}].{f} must not be negative, got {v}")
    return out


def read_friction(lk_name: str, model, friction: Mapping | None, taken) -> tuple:
    """``(JointFriction or None, {parameter: value})`` from ``Linkage(friction=...)`` (module
    docstring); `taken` the linkage's other parameter names (a clash is refused)."""
    if not isinstance(friction, Mapping) and friction is not None:
        raise ValueError(f"{lk_name}: friction must be a table like {{\"all\": {{\"mu\": 0.1, \"radius\": \"5 mm\"}}}}, "
                         f"got {friction!r}")
    if not friction:
        return None, {}
    spec = dict(friction)
    width = spec.pop("width", 1e-3)
    joints = [j for j in model.joints if isinstance(j, (Revolute, Prismatic, Slot))]
    by_name = {**{friction_key(j): j for j in joints}, **{joint_name(j): j for j in joints}}
    for k in spec:
        if k != "all" and k not in by_name:
            raise ValueError(f"{lk_name}: friction: {k!r} is not a pin, slider or slot (nor 'all' or 'width'); "
                             f"{did_you_mean(k, ['all', 'width', *by_name], 'the keys')}")
    common = _entry(lk_name, "all", spec.get("all", {}))
    own = {by_name[k]: (k, _entry(lk_name, k, v)) for k, v in spec.items() if k != "all"}
    entries, values = [], {}
    for j in joints:
        key, mine = own.get(j, ("all", {}))
        merged = {**({k: v for k, v in common.items() if k != "radius" or isinstance(j, Revolute)}), **mine}
        vals = _values(lk_name, key, j, merged)
        if not vals:
            continue
        names = {f: f"{prefix}_{friction_key(j)}" for f, prefix in (("mu", "mu"), ("radius", "rpin"), ("damping", "cv"))}
        vals.setdefault("mu", 0.0)
        if isinstance(j, Revolute):
            vals.setdefault("radius", 0.0)
        entries.append(FrictionJoint(joint_name(j), names["mu"], names["radius"] if isinstance(j, Revolute) else None,
                                     names["damping"] if "damping" in vals else None))
        values.update({names[f]: v for f, v in vals.items()})
    clash = [n for n in values if n in taken]
    if clash:
        raise ValueError(f"{lk_name}: friction parameter(s) {clash} clash with the linkage's own; rename the link or parameter")
    return JointFriction(tuple(entries), float(read_number(width, "-", "friction.width"))), values


def linkage_holding(lk, u, p: Mapping | None = None, *, t=0.0, options=None) -> Holding:
    """``Linkage.holding``: statics with joint friction at the inputs ``u (N,)`` or ``(N,
    dof)`` (solved in the order given, from the drawing): the effort driving the linkage
    on (``up.tau``), the one holding it back (``back.tau``), every joint's reaction with
    each, and where it is self-locking (``dynamics.inverse.Holding``)."""
    if lk.friction is None:
        raise ValueError(f"{lk.name}: holding needs joint friction: Linkage(friction={{'all': {{'mu': 0.1, 'radius': '5 mm'}}}})")
    kw = {} if options is None else {"options": options}
    sol = lk.solve(u, p, **kw)
    return holding(lk.model, lk._stroke(u, "u"), lk._p(p), sol.q, lk.friction, t=t, **kw)

