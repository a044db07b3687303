"""Joints between the bodies of a ``Model``: what carries the reactions that the per-body
Newton-Euler equations solve for (``reactions.joint_reactions``).

A joint joins two bodies, named as the model's ``Body.name`` or ``"ground"``, in the order
``(a, b)``: its reaction is **the force that body a exerts on body b** (N, global frame,
complex ``Fx + i Fy``; b exerts the opposite on a).  Joint types and their unknowns:

- ``Revolute``: a pin at a point; 2 unknowns (the force).
- ``Prismatic``: body b translates along a guide line fixed to body a; 2 unknowns: the
  normal force ``N n`` (``n`` the guide's left normal) and a moment ``M`` (N m, CCW on b).
- ``Slot``: a pin of body b in a straight or circular slot of body a; 1 unknown: the normal
  force (along the slot's normal: its left normal, or the radius for a circular slot).
- ``Actuator``: a driven two-force member between a point of body a and a point of body b
  (a hydraulic cylinder, a screw jack); its length is an input, its force is the effort on
  that input: ``tau e`` on b and ``-tau e`` on a, ``e`` the unit vector from a's point to b's.

A ``Revolute`` or ``Prismatic`` with ``input=`` is driven: the input is the joint's relative
angle ``phi_b - phi_a`` (or its travel along the guide), and the drive's torque (force) on
that input acts on b, its opposite on a.  Every input of a model with joints is driven by
exactly one joint, so that the equations are square: 3 per body, one unknown per drive.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..mechanism.structure import block_order

__all__ = ["Revolute", "Prismatic", "Slot", "Actuator", "JOINT_TYPES", "GROUND", "Layout", "layout", "joint_name"]

GROUND = "ground"

PointSpec = str | Callable  # a mechanism point name, or fn(q, u, p) -> complex
AngleSpec = str | Callable  # a coordinate or input name, or fn(q, u, p) -> real


@dataclasses.dataclass(frozen=True, eq=False)
class Revolute:
    """A pin joining bodies ``a`` and ``b`` at `point` (a mechanism point name or
    ``fn(q, u, p) -> complex``, m).  `input`: the input (relative angle ``phi_b - phi_a``,
    rad) this joint is driven by, if any.  `name`: defaults to the point's name."""

    point: PointSpec
    bodies: tuple[str, str]
    name: str | None = None
    input: str | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Prismatic:
    """Body ``b`` sliding on a straight guide of body ``a`` through `point` (a point of b on
    the guide line, m) at `angle` (the guide's direction, rad CCW, global, at the current
    pose: a coordinate name or ``fn(q, u, p)``).  `input`: the travel along the guide (m)
    this joint is driven by, if any."""

    point: PointSpec
    bodies: tuple[str, str]
    angle: AngleSpec
    name: str | None = None
    input: str | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Slot:
    """A pin of body ``b`` at `point` running in a slot of body ``a``: straight at `angle`
    (rad CCW, global, at the current pose), or circular about `center` (a point of a).
    One unknown, the force normal to the slot (no friction)."""

    point: PointSpec
    bodies: tuple[str, str]
    angle: AngleSpec | None = None
    center: PointSpec | None = None
    name: str | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Actuator:
    """A driven two-force member from ``points[0]`` (on body ``a``) to ``points[1]`` (on body
    ``b``), whose length (m) is the mechanism input `input`: its force ``tau`` (N, positive
    pushing the ends apart) is that input's effort.  Its reaction is ``tau e`` (the force on
    b, ``e`` the unit vector from the first point to the second)."""

    points: tuple[PointSpec, PointSpec]
    bodies: tuple[str, str]
    input: str
    name: str | None = None


JOINT_TYPES = (Revolute, Prismatic, Slot, Actuator)


def joint_name(joint) -> str:
    """A joint's name: its own, else its point's (an actuator: its input's)."""
    if joint.name is not None:
        return joint.name
    if isinstance(joint, Actuator):
        return joint.input
    if isinstance(joint.point, str):
        return joint.point
    raise ValueError(f"a {type(joint).__name__} whose point is a function needs a name=")


@dataclasses.dataclass(frozen=True)
class Layout:
    """The static shape of a model's Newton-Euler system.

    - `bodies`: the moving bodies' names, in rows ``3k, 3k+1, 3k+2`` (x force, y force,
      moment about the centre of mass).
    - `columns`: per joint name, its unknowns' columns (2, 2, 1 or 0).
    - `efforts`: per input (in the mechanism's order), its effort's column.
    - `order`: block lower-triangular solving order of the system (``structure.block_order``).
    """

    bodies: tuple[str, ...]
    columns: dict
    efforts: tuple[int, ...]
    order: tuple
    size: int


def _unknowns(joint) -> int:
    return {Revolute: 2, Prismatic: 2, Slot: 1, Actuator: 0}[type(joint)]


def layout(bodies: tuple[str, ...], joints, inputs: tuple[str, ...], owner: str = "model") -> Layout:
    """The Newton-Euler system's layout for moving `bodies`, `joints` and the mechanism's
    `inputs`; raises ``ValueError`` when it is not square or not determined (with counts)."""
    index = {b: k for k, b in enumerate(bodies)}
    columns, col, drives, touches = {}, 0, {}, []
    for j in joints:
        name = joint_name(j)
        if name in columns:
            raise ValueError(f"{owner}: two joints are named {name!r}; give each a distinct name=")
        for b in j.bodies:
            if b != GROUND and b not in index:
                raise ValueError(f"{owner}: joint {name!r} joins unknown body {b!r}; bodies are {list(bodies)} and {GROUND!r}")
        if j.bodies[0] == j.bodies[1]:
            raise ValueError(f"{owner}: joint {name!r} joins body {j.bodies[0]!r} to itself")
        n = _unknowns(j)
        columns[name] = tuple(range(col, col + n))
        touches += [(name, c) for c in columns[name]]
        col += n
        if isinstance(j, Slot) and (j.angle is None) == (j.center is None):
            raise ValueError(f"{owner}: slot {name!r} needs either angle= (straight) or center= (circular)")
        drive = getattr(j, "input", None)
        if drive is not None:
            if drive not in inputs:
                raise ValueError(f"{owner}: joint {name!r} is driven by {drive!r}, which is not an input; inputs are {list(inputs)}")
            if drive in drives:
                raise ValueError(f"{owner}: input {drive!r} drives two joints ({drives[drive]!r} and {name!r})")
            drives[drive] = name
    undriven = [i for i in inputs if i not in drives]
    if undriven:
        raise ValueError(f"{owner}: input(s) {undriven} drive no joint: give input= to the joint (or actuator) each drives")
    efforts = tuple(range(col, col + len(inputs)))
    size = col + len(inputs)
    if size != 3 * len(bodies):
        raise ValueError(
            f"{owner}: the joint reactions are not determined: {len(bodies)} moving bodies give {3 * len(bodies)} "
            f"Newton-Euler equations for {size} unknowns ({col} joint components, {len(inputs)} drive efforts); "
            "every moving link (massless ones too) must be a body, and every joint listed once")
    pattern = np.zeros((size, size), bool)
    by_name = {joint_name(j): j for j in joints}
    for name, cols in columns.items():
        j = by_name[name]
        for b in j.bodies:
            if b != GROUND:
                pattern[3 * index[b]: 3 * index[b] + 3, list(cols)] = True
    for i, c in zip(inputs, efforts):
        j = by_name[drives[i]]
        for b in j.bodies:
            if b != GROUND:
                pattern[3 * index[b]: 3 * index[b] + 3, c] = True
    order = block_order(pattern)
    if order is None:
        raise ValueError(f"{owner}: the joint reactions are not determined (the joints leave a body's equations without unknowns)")
    return Layout(bodies=tuple(bodies), columns=columns, efforts=efforts, order=order, size=size)
