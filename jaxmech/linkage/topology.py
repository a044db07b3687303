"""A linkage's topology to its equations: the joint graph, a spanning tree from ground, one
complex loop per closing joint, and the ``Mechanism`` and ``Model`` that carry them.

Bodies are the graph's nodes (ground, the links, the slider blocks, the actuators), joints
its edges (a pin at a point that several bodies list, a slider's guide, a pin in a slot).
A breadth-first spanning tree from ground reaches every body through one joint, its
*entry*: every point of a body is then the entry's position plus one link vector,
``len_E_P e^{i (theta_body + ang_D_E_P)}`` (E the entry, D its first other point; theta runs
from the first listed point to the second as drawn: ``_Builder.frame``).  Each joint outside
the tree closes one loop: its position reached from one side minus from the other is zero,
``E - N + 1`` complex loops (Euler), the fewest equations the linkage can be written with,
with the paths' common part cancelled.

Everything here is static: names and term lists, no number.  The drawing's numbers are the
parameters (``len_*``, ``ang_*``, ground points ``x_*``/``y_*``, masses ``m_*``...), so every
drawing of one topology shares the same ``Mechanism`` and ``Model`` objects (``build`` is
cached) and the same compiled programs.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from collections import deque

from ..dynamics.joints import Actuator, Prismatic, Revolute, Slot
from ..dynamics.model import Body, Gravity, Model, Moment, PointForce
from ..mechanism.mechanism import Mechanism
from .elements import element_loads, element_parameters
from .mass import centre_function, shape_properties
from .terms import Term, angle_value, negate, value
from .terms import lookup as _lookup

__all__ = ["Topology", "Built", "build", "GROUND"]

GROUND = "ground"


@dataclasses.dataclass(frozen=True)
class Topology:
    """The static part of a linkage (hashable): what a compiled program depends on.

    - `links`: ``((name, (point, ...)), ...)``, slider blocks included; `ground`: the fixed
      points; `actuators`: ``((name, (a, b)), ...)``.
    - `sliders`: ``((block, guide body), ...)``; the block slides at its first point.
    - `slots`: ``((pin, slotted body, centre point or ""), ...)``: ``""`` a straight slot.
    - `drivers`: driven link (crank angle about its ground pivot), slider block (travel) or
      actuator (length) names.
    - `gravity`: the unit direction of gravity; `forces`: ``((point, body), ...)`` constant
      forces; `moments`: links with a constant moment; `loads`: the user's own loads;
      `extra`: the user's own model parameter names; `elements`: springs and dampers
      (``elements.Element``), loads of the model with parameters of their own.
    """

    name: str
    points: tuple[str, ...]
    links: tuple[tuple[str, tuple[str, ...]], ...]
    ground: tuple[str, ...]
    actuators: tuple[tuple[str, tuple[str, str]], ...] = ()
    sliders: tuple[tuple[str, str], ...] = ()
    slots: tuple[tuple[str, str, str], ...] = ()
    drivers: tuple[str, ...] = ()
    gravity: complex = -1j
    forces: tuple[tuple[str, str], ...] = ()
    moments: tuple[str, ...] = ()
    loads: tuple = ()
    extra: tuple[str, ...] = ()
    mass_shapes: tuple = ()
    elements: tuple = ()


@dataclasses.dataclass(frozen=True)
class _Edge:
    kind: str  # "revolute", "prismatic", "slot"
    a: str  # revolute: first body; prismatic: guide; slot: slotted body
    b: str  # revolute: second body; prismatic: block; slot: the pin's body
    point: str  # the joint's point (the block's sliding point, the pin)


@dataclasses.dataclass(frozen=True, eq=False)
class Built:
    """What ``build`` makes of a topology.

    - `mechanism`, `model`: the ``Mechanism`` (loop equations in named coordinates) and the
      ``Model`` (bodies, joints, loads) shared by every drawing of the topology.
    - `loops`: ``((name, terms), ...)`` the loop equations as terms (``terms.show``).
    - `recipes`: ``{parameter: recipe}``: how each geometric parameter follows from a drawing
      (``("x"|"y", point)``, ``("len", entry, point)``, ``("ang", direction, entry, point)``,
      ``("frame", body, entry, point)``, ``("guide"|"slot", name, body)``, ``("radius", pin,
      centre)``); `coords`, `inputs`: ``{name: recipe}`` at the drawing.
    - `frames`: per body, the two points its angle is measured between, as drawn: a link's
      (an actuator's) first listed point and its second, whatever point the tree enters it
      through; a block's ``(entry, None)`` (its angle is its guide's).
    - `virtual`: ``{virtual point: (body, what)}``: centres of mass, guide and slot bases.
    - `joints`: per moving link, the points that join it to another body (mass defaults).
    """

    mechanism: Mechanism
    model: Model
    loops: tuple
    recipes: dict
    coords: dict
    inputs: dict
    frames: dict
    virtual: dict
    joints: dict
    blocks: dict
    edges: tuple


class _Builder:
    """The spanning tree and the terms of every position, in one pass over a topology."""

    def __init__(self, top: Topology):
        self.top = top
        self.links = dict(top.links)
        self.acts = dict(top.actuators)
        self.blocks = dict(top.sliders)  # block -> guide
        self.slots = {p: (body, centre) for p, body, centre in top.slots}
        self.bodies = [GROUND] + list(self.links) + list(self.acts)
        owned = {GROUND: tuple(top.ground), **self.links, **self.acts}
        self.members = {x: [b for b in self.bodies if x in owned[b]] for x in top.points}
        self.recipes: dict = {}
        self.derived: dict = {}  # {angle: (len_E_P1, len_E_P2, ang_P1_E_P2)}: a plate's angle at P1 (``frame``)
        self.virtual: dict = {}
        self._check()
        self.edges = self._edges()
        self.parent = self._tree()

    # ----------------------------------------------------------------- graph
    def _check(self):
        top = self.top
        for x, ms in self.members.items():
            if not ms:
                raise ValueError(f"{top.name}: point {x!r} belongs to no link and is not a ground point; list it in a link or drop it")
        for act in self.acts:
            if act not in top.drivers:
                raise ValueError(f"{top.name}: actuator {act!r} is not a driver; an actuator's length is an input "
                                 "(list it in driver=), a passive element is a load")
        for d in top.drivers:
            if d not in self.links and d not in self.acts:
                raise ValueError(f"{top.name}: driver {d!r} is not a link, a slider or an actuator")
            if d in self.links and d not in self.blocks:
                pivots = [x for x in self.links[d] if GROUND in self.members[x]]
                if len(pivots) != 1:
                    raise ValueError(f"{top.name}: driver {d!r} turns about its ground pivot, but it has {len(pivots)} ground "
                                     "points; a crank has exactly one (give its pivot in ground=)")
        for link, pts in self.links.items():
            if len(pts) < 2 and link not in self.blocks:
                raise ValueError(f"{top.name}: link {link!r} has {len(pts)} point(s); a link joins at least two (or is a slider block)")

    def _edges(self):
        edges = []
        for x in self.top.points:
            ms = [b for b in self.members[x]]
            pin_of_slot = x in self.slots
            if pin_of_slot:
                ms = [b for b in ms if b != self.slots[x][0]]
            edges += [_Edge("revolute", ms[0], b, x) for b in ms[1:]]
        for block, guide in self.top.sliders:
            edges.append(_Edge("prismatic", guide, block, self.links[block][0]))
        for pin, (slotted, _) in self.slots.items():
            bodies = [b for b in self.members[pin] if b != slotted]
            if not bodies:
                raise ValueError(f"{self.top.name}: the pin {pin!r} of the slot in {slotted!r} belongs to no other link")
            edges.append(_Edge("slot", slotted, bodies[0], pin))
        return tuple(edges)

    def _tree(self):
        parent = {GROUND: None}
        queue = deque([GROUND])
        while queue:
            a = queue.popleft()
            for e in self.edges:
                if a not in (e.a, e.b):
                    continue
                other = e.b if e.a == a else e.a
                if other not in parent:
                    parent[other] = e
                    queue.append(other)
        lost = [b for b in self.bodies if b not in parent]
        if lost:
            raise ValueError(f"{self.top.name}: {lost} not connected to ground by any joint")
        return parent

    # ----------------------------------------------------------------- frames
    def motion_of(self, body: str) -> str:
        """The name of a body's own motion: a block's travel, any other body's angle."""
        return f"s_{body}" if body in self.blocks else f"theta_{body}"

    @functools.lru_cache(maxsize=None)  # noqa: B019 - one builder per topology, kept by build's cache
    def theta(self, body: str) -> tuple:
        """A body's angle as a signed sum of names (ground: none)."""
        if body == GROUND:
            return ()
        if body in self.blocks:
            guide = self.blocks[body]
            name = f"ang_guide_{body}"
            self.recipes[name] = ("guide", body, guide)
            return self.theta(guide) + ((1, name),)
        return ((1, self.motion_of(body)),)

    @functools.lru_cache(maxsize=None)  # noqa: B019
    def entry(self, body: str) -> str:
        e = self.parent[body]
        if e.kind == "revolute" or (e.kind == "prismatic" and body == e.b) or (e.kind == "slot" and body == e.b):
            return e.point
        if e.kind == "prismatic":
            return self._virtual(f"{e.point}_on_{body}", body, ("at", e.point))
        centre = self.slots[e.point][1]
        return centre if centre else self._virtual(f"{e.point}_on_{body}", body, ("at", e.point))

    def listed(self, body: str) -> tuple:
        """A link's or an actuator's points in the order the drawing lists them."""
        return self.acts.get(body) or self.links.get(body, ())

    @functools.lru_cache(maxsize=None)  # noqa: B019
    def entered_elsewhere(self, body: str) -> bool:
        """Whether the tree enters a link (an actuator) elsewhere than at its first listed
        point: its link vectors then carry a minus sign (``theta`` runs from ``P1`` to ``P2``)."""
        pts = self.listed(body)
        return body not in self.blocks and len(pts) >= 2 and self.entry(body) != pts[0]

    @functools.lru_cache(maxsize=None)  # noqa: B019
    def frame(self, body: str) -> tuple:
        """The body's angle plus, entered through a third point ``E``, the plate's angle
        ``ang_P2_P1_E`` at ``P1`` from ``P2`` to ``E``, derived from its sides (``derived``)."""
        if not self.entered_elsewhere(body) or body in self.acts or self.entry(body) == self.listed(body)[1]:
            return self.theta(body)
        (p1, p2, *_), e = self.listed(body), self.entry(body)
        name, la, lb, a = f"ang_{p2}_{p1}_{e}", f"len_{e}_{p1}", f"len_{e}_{p2}", f"ang_{p1}_{e}_{p2}"
        self.recipes[la], self.recipes[lb], self.recipes[a] = ("len", e, p1), ("len", e, p2), ("ang", p1, e, p2)
        self.derived[name] = (la, lb, a)
        return self.theta(body) + ((1, name),)

    def direction(self, body: str):
        if body in self.blocks:
            return None
        others = [x for x in self.listed(body) if x != self.entry(body)]
        return others[0]

    def _virtual(self, name, body, what):
        if name in self.members:
            raise ValueError(f"{self.top.name}: the point name {name!r} is taken by the linkage itself; rename that point")
        self.virtual[name] = (body, what)
        return name

    # ----------------------------------------------------------------- positions
    @functools.lru_cache(maxsize=None)  # noqa: B019
    def entry_terms(self, body: str) -> tuple:
        e = self.parent[body]
        if e.kind == "revolute":
            return self.pos(e.a if e.b == body else e.b, e.point)
        along, base_body, base = self._joint_vector(e)
        if body == e.b:
            return self.pos(base_body, base) + (along,)
        return self.pos(e.b, e.point) + negate((along,))

    def _joint_vector(self, e: _Edge):
        """``(vector, body, base point)``: a prismatic or slot joint puts its point at the base
        point of `body` plus the vector."""
        if e.kind == "prismatic":
            base = self._virtual(f"{e.point}_on_{e.a}", e.a, ("at", e.point))
            return Term(1, self.motion_of(e.b), self.theta(e.b)), e.a, base
        centre = self.slots[e.point][1]
        if centre:
            self.recipes[f"R_{e.point}"] = ("radius", e.point, centre)
            return Term(1, f"R_{e.point}", ((1, f"psi_{e.point}"),)), e.a, centre
        base = self._virtual(f"{e.point}_on_{e.a}", e.a, ("at", e.point))
        self.recipes[f"ang_slot_{e.point}"] = ("slot", e.point, e.a)
        return Term(1, f"s_{e.point}", self.theta(e.a) + ((1, f"ang_slot_{e.point}"),)), e.a, base

    @functools.lru_cache(maxsize=None)  # noqa: B019
    def pos(self, body: str, x: str) -> tuple:
        """Terms of point `x` of `body` (real or virtual)."""
        if body == GROUND:
            self.recipes[f"x_{x}"] = ("x", x)
            self.recipes[f"y_{x}"] = ("y", x)
            return (Term(1, xy=(f"x_{x}", f"y_{x}")),)
        entry = self.entry(body)
        base = self.entry_terms(body)
        if x == entry:
            return base
        sign = -1 if self.entered_elsewhere(body) else 1
        if body in self.acts:
            return base + (Term(sign, body, self.theta(body)),)
        length = f"len_{entry}_{x}"
        self.recipes[length] = ("len", entry, x)
        d = self.direction(body)
        if d == x:
            return base + (Term(sign, length, self.frame(body)),)
        ang = f"ang_{d}_{entry}_{x}" if d is not None else f"ang_{body}_{entry}_{x}"
        self.recipes[ang] = ("ang", d, entry, x) if d is not None else ("frame", body, entry, x)
        return base + (Term(sign, length, self.frame(body) + ((1, ang),)),)

    def closing(self, e: _Edge) -> tuple:
        if e.kind == "revolute":
            left, right = self.pos(e.a, e.point), self.pos(e.b, e.point)
        else:
            along, base_body, base = self._joint_vector(e)
            left, right = self.pos(base_body, base) + (along,), self.pos(e.b, e.point)
        k = 0
        while k < min(len(left), len(right)) and left[k] == right[k]:
            k += 1
        return left[k:] + negate(right[k:])


def hash_text(text: str) -> str:
    """SHA-256 of a text (hex)."""
    return hashlib.sha256(text.encode()).hexdigest()


def _joint_names(b: _Builder) -> dict:
    """Each edge's name: a pin by its point (``"B:rocker"`` where several pins share it), a
    slider ``"block on guide"``, a slot ``"pin in body"``."""
    names, count = {}, {}
    for e in b.edges:
        if e.kind == "revolute":
            count[e.point] = count.get(e.point, 0) + 1
    for e in b.edges:
        if e.kind == "revolute":
            names[e] = e.point if count[e.point] == 1 else f"{e.point}:{e.b}"
        elif e.kind == "prismatic":
            names[e] = f"{e.b} on {e.a}"
        else:
            names[e] = f"{e.point} in {e.a}"
    return names


def _coordinates(b: _Builder) -> tuple[list, list]:
    top = b.top
    coords = [b.motion_of(body) for body in b.links if body not in top.drivers]
    coords += [f"theta_{act}" for act in b.acts]
    coords += [f"psi_{pin}" if centre else f"s_{pin}" for pin, (_, centre) in b.slots.items()]
    inputs = [d if d in b.acts else b.motion_of(d) for d in top.drivers]
    return coords, inputs


def _depth(b: _Builder, body: str) -> int:
    k = 0
    while b.parent[body] is not None:
        e = b.parent[body]
        body = e.a if e.b == body else e.b
        k += 1
    return k


def _mechanism(b: _Builder, loops, coords, inputs) -> Mechanism:
    top = b.top
    values = _lookup(coords, inputs, b.derived)
    point_terms = {}
    for x in top.points:
        home = min(b.members[x], key=lambda body: _depth(b, body))
        point_terms[x] = b.pos(home, x)
    shapes = _shapes(b)
    centres = {}
    for link in b.links:
        if link in shapes and shapes[link][2]:  # the centre of mass follows the joints
            kind, ring = shapes[link][0], tuple(b.pos(link, x) for x in shapes[link][1])
            centres[f"G_{link}"] = (kind, ring, link)
        else:
            point_terms[f"G_{link}"] = b.pos(link, b._virtual(f"G_{link}", link, ("com",)))
    loop_terms = tuple(loops)

    def constraints(q, u, p):
        look = values(q, u, p)
        return {name: value(terms, look) for name, terms in loop_terms}

    def point(terms):
        return lambda q, u, p: value(terms, values(q, u, p))

    def centre(kind, ring, link):
        return centre_function(kind, ring, b.entry_terms(link), b.theta(link), values)

    params = tuple(b.recipes)
    virtual_len = {n for n, r in b.recipes.items() if r[0] == "len" and r[2] in b.virtual}
    lengths = [n for n in params if n.startswith(("len_", "x_", "y_", "R_"))]
    lengths += [n for n in coords + inputs if n.startswith("s_") or n in b.acts]
    signed = [n for n in params if n.startswith(("x_", "y_")) or n in virtual_len]
    return Mechanism(coords=tuple(coords), inputs=tuple(inputs), params=params, lengths=tuple(lengths), signed=tuple(signed),
                     constraints=constraints if loops else None,
                     points={**{k: point(v) for k, v in point_terms.items()}, **{k: centre(*v) for k, v in centres.items()}},
                     name=top.name)


def _shapes(b: _Builder) -> dict:
    """``{link: (kind, corners, centre derived, inertia derived)}`` (``Topology.mass_shapes``)."""
    return {link: (kind, corners, c, j) for link, kind, corners, c, j in b.top.mass_shapes}


def _inertia(b: _Builder, mech: Mechanism, link: str):
    """A link's inertia spec: ``J_<link>``, or where it follows from the joints
    (``Topology.mass_shapes``) ``fn(p)``, the uniform shape's of mass ``m_<link>`` through
    the joints' positions in the link's own frame (any pose gives them: the positions of
    one link's points differ by its body-fixed vectors whatever the coordinates)."""
    shapes = _shapes(b)
    if link not in shapes or not shapes[link][3]:
        return f"J_{link}"
    kind, corners = shapes[link][0], shapes[link][1]
    ring = tuple(b.pos(link, x) for x in corners)
    values = _lookup(mech.coords, mech.inputs, b.derived)
    rest = dict.fromkeys(mech.coords + mech.inputs, 0.0)

    def inertia(p):
        look = values(rest, rest, p)
        return shape_properties(kind, [value(t, look) for t in ring], p[f"m_{link}"])[1]

    return inertia


def _model(b: _Builder, mech: Mechanism, names: dict) -> Model:
    top = b.top
    values = _lookup(mech.coords, mech.inputs, b.derived)

    def angle_spec(body):
        th = b.theta(body)
        if len(th) == 1 and th[0][0] == 1 and th[0][1] in mech.coords + mech.inputs:
            return th[0][1]
        return lambda q, u, p: angle_value(th, values(q, u, p))

    bodies = [Body(f"G_{link}", f"m_{link}", angle=angle_spec(link), inertia=_inertia(b, mech, link), name=link) for link in b.links]
    joints = []
    for e in b.edges:
        if e.a in b.acts or e.b in b.acts:
            continue  # an actuator's pins: its force acts on the links directly
        if e.kind == "revolute":
            drive = f"theta_{e.b}" if e.a == GROUND and e.b in top.drivers and e.b not in b.blocks else None
            joints.append(Revolute(e.point, (e.a, e.b), name=names[e], input=drive))
        elif e.kind == "prismatic":
            drive = f"s_{e.b}" if e.b in top.drivers else None
            joints.append(Prismatic(e.point, (e.a, e.b), angle_spec(e.b), name=names[e], input=drive))
        else:
            centre = b.slots[e.point][1]
            if centre:
                joints.append(Slot(e.point, (e.a, e.b), center=centre, name=names[e]))
            else:
                th = b.theta(e.a) + ((1, f"ang_slot_{e.point}"),)
                joints.append(Slot(e.point, (e.a, e.b), angle=lambda q, u, p, th=th: angle_value(th, values(q, u, p)), name=names[e]))
    for act, (pa, pb) in b.acts.items():
        owner = lambda x: [m for m in b.members[x] if m != act][0]  # noqa: E731
        joints.append(Actuator((pa, pb), (owner(pa), owner(pb)), input=act, name=act))
    loads = [Gravity("g", direction=top.gravity)]
    for x, body in top.forces:
        loads.append(PointForce(x, lambda q, u, p, v, t, x=x: p[f"Fx_{x}"] + 1j * p[f"Fy_{x}"], name=f"force at {x}", body=body))
    for link in top.moments:
        loads.append(Moment(angle_spec(link), lambda q, u, p, v, t, link=link: p[f"M_{link}"], name=f"moment on {link}", body=link))
    loads += element_loads(top.elements, b.theta, values) + list(top.loads)
    derived = {link for link, (_, _, _, j) in _shapes(b).items() if j}
    own = [f"{k}_{link}" for link in b.links for k in ("m", "J") if k == "m" or link not in derived] + ["g"]
    own += [f"F{c}_{x}" for x, _ in top.forces for c in "xy"] + [f"M_{link}" for link in top.moments]
    own += [n for e in top.elements for n in element_parameters(e)]
    own += [n for n in top.extra if n not in own]
    # Every function of the model is written here from the topology (covered by the stored
    # programs' source hash), so the topology identifies it; a user's own loads do not.
    key = None if top.loads or mech.program_key is None else f"linkage {mech.program_key} {hash_text(repr(top))}"
    return Model(mech, bodies=bodies, loads=loads, params=tuple(own), joints=joints, program_key=key)


def _joints(b: _Builder) -> dict:
    """Per moving link, the points that join it to another body."""
    return {link: tuple(x for x in pts if len(b.members[x]) > 1 or x in b.slots) for link, pts in b.links.items()}


def link_joints(top: Topology) -> dict:
    """``Built.joints`` of a topology without building its programs: per moving link, the
    points that join it to another body (what its default mass properties span)."""
    return _joints(_Builder(top))


@functools.lru_cache(maxsize=64)
def build(top: Topology) -> Built:
    """The ``Mechanism`` and ``Model`` of a topology, and how its parameters follow from a
    drawing (cached: every drawing of one topology shares them, and so their compiled
    programs).  Raises ``ValueError`` for a linkage that is not connected, or whose drivers
    leave it with another number of degrees of freedom than none."""
    b = _Builder(top)
    names = _joint_names(b)
    tree = set(b.parent.values())
    loops = [(f"loop {names[e]}", b.closing(e)) for e in b.edges if e not in tree]
    coords, inputs = _coordinates(b)
    if 2 * len(loops) != len(coords):
        free = len(coords) - 2 * len(loops)
        raise ValueError(
            f"{top.name}: {len(loops)} independent loops give {2 * len(loops)} equations for {len(coords)} unknown "
            f"coordinates {coords} with the drivers {list(top.drivers)}: the linkage has {free:+d} degree(s) of freedom "
            f"left {'(add a driver or a joint)' if free > 0 else '(it is over-constrained: remove a link or a driver)'}")
    mech = _mechanism(b, loops, coords, inputs)
    model = _model(b, mech, names)
    # a body's angle is measured from the first point of its frame to the second: a link's
    # (an actuator's) first listed point to its second; a block's entry (its angle the guide's)
    frames = {body: (b.entry(body), None) if body in b.blocks else tuple(b.listed(body)[:2]) for body in b.bodies if body != GROUND}
    coord_recipes = {b.motion_of(body): ("travel",) if body in b.blocks else ("angle", body) for body in list(b.links) + list(b.acts)}
    coord_recipes.update({act: ("length", *pts) for act, pts in b.acts.items()})
    for pin, (_, centre) in b.slots.items():
        coord_recipes[f"psi_{pin}" if centre else f"s_{pin}"] = ("arc", pin, centre) if centre else ("travel",)
    joints = _joints(b)
    return Built(mechanism=mech, model=model, loops=tuple(loops), recipes=dict(b.recipes),
                 coords={n: coord_recipes[n] for n in coords}, inputs={n: coord_recipes[n] for n in inputs},
                 frames=frames, virtual=dict(b.virtual), joints=joints, blocks=dict(b.blocks), edges=b.edges)
