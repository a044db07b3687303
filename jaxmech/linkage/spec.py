"""``Linkage``: a planar linkage as an engineer draws it, joints at coordinates and links
through them, turned into the engine's ``Mechanism`` (loop equations) and ``Model``
(bodies, joints, loads) with the drawing as parameters, guess and assembly mode."""

from __future__ import annotations

import cmath
import dataclasses
from collections.abc import Mapping, Sequence

import jax
import numpy as np

from ..dynamics.inverse import InverseDynamics, inverse_dynamics
from ..dynamics.joints import joint_name
from ..kinematics import Motion, Samples, check_samples, drive_rates, motion
from ..names import closest, did_you_mean, near_hint
from ..continuation.solve import solve_stroke
from ..solver.options import SolverOptions
from .friction import linkage_holding, read_friction
from .elements import drawing_values, read_elements
from .mass import derived_shapes, link_mass_properties
from .power import linkage_power
from .terms import show
from .topology import GROUND, Built, Topology, build, link_joints
from .values import read_names as _names
from .values import read_number as _number
from .values import read_point as _point
from .values import wrap_angle as _wrap

__all__ = ["Linkage"]

#: Points on the way from the drawing's input to a stroke's first input (the stroke starts
#: on the drawing's assembly mode: it is reached by continuation, not by a jump).
APPROACH = 24


class Linkage:
    """A planar linkage from its drawing: points at coordinates, links through them.

    **Arguments**

    - `points`: ``{name: (x, y)}`` (m; a string may carry a unit, ``"280mm"``): every
      joint, ground pivot and tracer point.
    - `links`: ``{name: points}`` (a list or ``"A B C"``): a binary link joins two points, a
      plate three or more; a point listed by several links (or by a link and `ground`) is a
      revolute joint, a point of one link only is a tracer on it.
    - `ground`: the points fixed to the frame (ground pivots, guides' and slots' anchors).
    - `driver`: what is driven, one name per degree of freedom: a link turning about its
      ground pivot (input ``theta_<link>``, its angle in rad from its first listed point
      to its second, as every link's), a slider block (``s_<block>``,
      its travel from the drawing in m), an actuator (its name: its length in m).
    - `sliders`: ``{block: {"on": guide, "angle": direction}}``: the link `block` (or, given
      a point name, a massless block at that point) slides along a straight guide fixed to
      the body `guide` (default ground) through its first point, at `angle` (rad, or
      ``"30deg"``, global in the drawing; or ``"through": point`` of the guide).
    - `slots`: ``{pin: {"on": body, "center": point or (x, y)}}`` a pin in a circular slot of
      `body` (default ground), or ``{"on": body, "angle": direction or "through": point}`` straight.
    - `actuators`: ``{name: (a, b)}``: a linear actuator (hydraulic cylinder, screw jack)
      pinned at points `a` and `b`; its length is an input (list it in `driver`).
    - `mass` ``{link: kg}``; `inertia` ``{link: kg m^2}`` about the centre of mass; `centre`
      ``{link: point or (x, y)}``.  Defaults: a link without mass is massless; a centre of
      mass and an inertia not given are the uniform bar's (two joints: the midpoint and
      ``m L^2 / 12``) or the uniform plate's spanned by the link's joints, and they are
      *derived*: functions of the joints' positions, so they follow the link's lengths and
      angles wherever a sweep or a design changes them (the model has no ``J_<link>`` for
      a derived inertia, and no centre-of-mass parameters for a derived centre).  A centre
      or an inertia given here is a parameter of its own (``len_<joint>_G_<link>`` and
      ``ang_...``, ``J_<link>``) and stays where it is put.
    - `gravity`: ``g`` in m/s^2 pointing down (-y), or a vector ``(gx, gy)``; None: none.
    - `forces`: ``{point: (Fx, Fy)}`` constant forces (N), or ``{point: {"force": (Fx, Fy),
      "on": link}}`` where the point joins several links; `moments`: ``{link: M}`` (N m, CCW).
    - `springs` ``{name: {"between": (a, b), "k": N/m, "free_length": m, "preload": N}}``,
      `torsion_springs` ``{name: {"at": pin or "links": (a, b), "k": N m/rad, "free_angle":
      rad}}``, `gas_springs` ``{name: {"between": (a, b), "force": N, "gas_length": m,
      "length": m, "n": -}}``, `dampers` ``{name: {"between": (a, b), "c": N s/m}}``,
      `rotary_dampers` ``{name: {"at": pin or "links": (a, b), "c": N m s/rad}}``: springs
      and dampers, loads with parameters of their own (``k_<name>``...: see
      ``jaxmech.linkage.elements`` and ``docs/springs_and_dampers.md``).
    - `friction` ``{"all" or joint: {"mu": -, "radius": m, "damping": ...}}``: Coulomb
      friction and viscous damping at pins, sliders and slots (``mu_<key>``, ``rpin_<key>``,
      ``cv_<key>``: ``jaxmech.linkage.friction``); ``holding`` gives statics with it.
    - `loads`, `params`: loads of your own (``PointForce``, ``Moment``, ``Axial`` with
      ``body=``) and the values of the parameters they use.
    - `name`: for messages and files.

    Every length and fixed angle of the drawing is a named parameter (``Linkage.params``:
    ``x_O4``, ``len_A_B``, ``ang_B_A_P``, ``m_crank``...), every loop's assembly mode is the
    drawing's (the sign of each loop's Jacobian determinant), and the drawing is the guess:
    a new drawing of the same topology compiles nothing new.
    """

    def __init__(self, points: Mapping, links: Mapping, ground=(), *, driver=(), sliders: Mapping | None = None,
                 slots: Mapping | None = None, actuators: Mapping | None = None, mass: Mapping | None = None,
                 inertia: Mapping | None = None, centre: Mapping | None = None, gravity=None,
                 forces: Mapping | None = None, moments: Mapping | None = None, springs: Mapping | None = None,
                 torsion_springs: Mapping | None = None, gas_springs: Mapping | None = None, dampers: Mapping | None = None,
                 rotary_dampers: Mapping | None = None, loads: Sequence = (), params: Mapping | None = None, name: str = "linkage",
                 friction: Mapping | None = None):
        self.name = str(name)
        if not isinstance(points, Mapping) or not points:
            raise ValueError(f"{self.name}: points must be a mapping {{name: (x, y)}}")
        self.points = {n: _point(v, f"points[{n!r}]") for n, v in points.items()}
        _names(tuple(self.points), "points")
        links, ground = self._read_links(links, ground)
        block_of = self._read_sliders(links, sliders)
        slot_specs = self._read_slots(links, ground, slots)
        acts = self._read_actuators(actuators)
        drivers = _names(driver, "driver")
        if not drivers:
            raise ValueError(f"{self.name}: say what is driven: driver= a crank link, a slider or an actuator")
        drivers = tuple(f"block_{d}" if d in self.points and f"block_{d}" in block_of else d for d in drivers)
        for d in (d for d in drivers if d not in links and d not in acts):
            raise ValueError(f"{self.name}: driver {d!r} is not a link, a slider or an actuator; {did_you_mean(d, [*links, *acts], 'links')}")
        self.mass_spec = self._masses(links, mass, inertia, centre)
        g_vec = None if gravity is None else (complex(0, -_number(gravity, "m/s^2", "gravity")) if np.ndim(gravity) == 0 else _point(gravity, "gravity", "m/s^2"))
        self.g = 0.0 if g_vec is None else abs(g_vec)
        force_specs = self._read_forces(links, forces)
        self.moment_values = {k: _number(v, "N m", f"moments[{k!r}]") for k, v in dict(moments or {}).items()}
        for k in self.moment_values:
            if k not in links:
                raise ValueError(f"{self.name}: moments: {k!r} is not a link; {did_you_mean(k, links, 'links')}")
        self.elements = read_elements(self.name, self.points, links, ground, dict(
            springs=springs, torsion_springs=torsion_springs, gas_springs=gas_springs, dampers=dampers, rotary_dampers=rotary_dampers))
        self.extra = {k: float(v) for k, v in dict(params or {}).items()}
        self.links = links
        self.ground = ground
        self.topology = Topology(
            # the name is not the user's: every drawing of one topology shares compiled programs
            name="linkage", points=tuple(self.points), links=tuple((k, tuple(v)) for k, v in links.items()),
            ground=tuple(ground), actuators=tuple(acts.items()), sliders=tuple(block_of.items()), slots=tuple(slot_specs),
            drivers=drivers, gravity=(-1j if g_vec is None or abs(g_vec) == 0 else g_vec / abs(g_vec)),
            forces=tuple(force_specs), moments=tuple(self.moment_values), loads=tuple(loads), extra=tuple(self.extra),
            elements=self.elements.specs)
        try:
            # the links whose centre of mass and inertia follow from their joints, by the
            # shape the drawing gives them
            shapes = derived_shapes(self.mass_spec, link_joints(self.topology), self.links, self.points)
            self.topology = dataclasses.replace(self.topology, mass_shapes=shapes)
            self.built: Built = build(self.topology)
        except ValueError as err:  # said in the linkage's own name
            text = str(err)
            raise ValueError(f"{self.name}: {text.removeprefix('linkage: ')}") from None
        self._values = self._drawing_values()
        self.friction, values = read_friction(self.name, self.model, friction, self._values)
        self._values.update(values)

    # ----------------------------------------------------------------- reading the drawing
    def _read_links(self, links, ground):
        """``(links {name: [points]}, ground [points])``, every point checked against the
        drawing's and listed once."""
        links = {str(k): list(_names(v, f"links[{k!r}]")) for k, v in dict(links).items()}
        ground = list(_names(ground, "ground"))
        for k, pts in [*links.items(), ("ground", ground)]:
            for x in pts:
                if x not in self.points:
                    raise ValueError(f"{self.name}: {k} names point {x!r}, which is not in points; {did_you_mean(x, self.points, 'points')}")
            if len(set(pts)) != len(pts):
                raise ValueError(f"{self.name}: {k} lists a point twice: {pts}")
        if GROUND in links:
            raise ValueError(f"{self.name}: 'ground' is the frame; give its points as ground=")
        return links, ground

    def _read_sliders(self, links, sliders) -> dict:
        """``{slider block: guide}`` (a slider on a point gets a block link ``block_<point>``,
        added to `links`); every guide's angle (rad) into ``slider_angles``."""
        self.slider_angles = {}
        block_of = {}
        for key, spec in dict(sliders or {}).items():
            spec = {"on": spec} if isinstance(spec, str) else dict(spec)
            if key in links:
                block = key
            elif key in self.points:
                block = f"block_{key}"
                links[block] = [key]
            else:
                raise ValueError(f"{self.name}: sliders: {key!r} is neither a link nor a point; {did_you_mean(key, [*links, *self.points])}")
            guide = spec.get("on", GROUND)
            if guide != GROUND and guide not in links:
                raise ValueError(f"{self.name}: sliders[{key!r}]: guide {guide!r} is not a link or 'ground'; {did_you_mean(guide, links, 'links')}")
            if "through" in spec:
                self.slider_angles[block] = self._towards(links[block][0], spec["through"], f"sliders[{key!r}]")
            elif "angle" in spec:
                self.slider_angles[block] = _number(spec["angle"], "rad", f"sliders[{key!r}].angle")
            else:
                raise ValueError(f"{self.name}: sliders[{key!r}] needs the guide's angle= (rad or '30deg') or through= a point")
            block_of[block] = guide
        return block_of

    def _read_slots(self, links, ground, slots) -> list:
        """``[(pin, body, centre point or "")]``: circular slots by their centre (a point of
        the body, or one added at the given coordinates), straight ones by their angle (rad,
        into ``slot_angles``)."""
        self.slot_angles = {}
        slot_specs = []
        for pin, spec in dict(slots or {}).items():
            spec = dict(spec)
            if pin not in self.points:
                raise ValueError(f"{self.name}: slots: pin {pin!r} is not in points; {did_you_mean(pin, self.points, 'points')}")
            body = spec.get("on", GROUND)
            pts = ground if body == GROUND else links.get(body)
            if pts is None:
                raise ValueError(f"{self.name}: slots[{pin!r}]: {body!r} is not a link or 'ground'; {did_you_mean(body, links, 'links')}")
            if "center" in spec or "centre" in spec:
                c = spec.get("center", spec.get("centre"))
                if isinstance(c, str):
                    if c not in pts:
                        raise ValueError(f"{self.name}: slots[{pin!r}]: centre {c!r} is not a point of {body!r}; {did_you_mean(c, pts, 'its points')}")
                    slot_centre = c
                else:
                    slot_centre = f"centre_{pin}"
                    self.points[slot_centre] = _point(c, f"slots[{pin!r}].center")
                    pts.append(slot_centre)
                slot_specs.append((pin, body, slot_centre))
            elif "through" in spec or "angle" in spec:
                self.slot_angles[pin] = (self._towards(pin, spec["through"], f"slots[{pin!r}]") if "through" in spec
                                         else _number(spec["angle"], "rad", f"slots[{pin!r}].angle"))
                slot_specs.append((pin, body, ""))
            else:
                raise ValueError(f"{self.name}: slots[{pin!r}] needs center= (a circular slot), or angle= or through= (a straight one)")
        return slot_specs

    def _towards(self, start: str, through, what: str) -> float:
        """A straight guide's or slot's angle (rad, global) from `start` towards point `through`."""
        if through not in self.points or self.points[through] == self.points[start]:
            why = f"is where {start!r} is" if through in self.points else f"is not in points; {did_you_mean(str(through), self.points)}"
            raise ValueError(f"{self.name}: {what}: through= {through!r} {why}")
        return cmath.phase(self.points[through] - self.points[start])

    def _read_actuators(self, actuators) -> dict:
        """``{actuator: (point, point)}``: each joins two points of the drawing."""
        acts = {}
        for k, v in dict(actuators or {}).items():
            pts = _names(v, f"actuators[{k!r}]")
            if len(pts) != 2 or any(x not in self.points for x in pts):
                raise ValueError(f"{self.name}: actuators[{k!r}] joins two points of the drawing, got {v!r}{near_hint(pts, self.points)}")
            acts[k] = pts
        return acts

    def _read_forces(self, links, forces) -> list:
        """``[(point, link)]``: the link each constant force acts on (the point's only link,
        or ``on=``); the forces (N, complex) into ``force_values``."""
        force_specs, self.force_values = [], {}
        for x, spec in dict(forces or {}).items():
            spec = spec if isinstance(spec, Mapping) else {"force": spec}
            owners = [k for k, pts in links.items() if x in pts]
            on = spec.get("on", owners[0] if len(owners) == 1 else None)
            if on not in links:  # (a point of no link, or misspelt)
                near = near_hint([x], self.points) or near_hint([on], links)
                raise ValueError(f"{self.name}: forces[{x!r}]: say which link it acts on (on=); the point is on {owners}{near}")
            force_specs.append((x, on))
            self.force_values[x] = _point(spec["force"], f"forces[{x!r}]", "N")
        return force_specs

    # ----------------------------------------------------------------- mass properties
    def _masses(self, links, mass, inertia, centre):
        mass, inertia, centre = dict(mass or {}), dict(inertia or {}), dict(centre or {})
        for what, d in (("mass", mass), ("inertia", inertia), ("centre", centre)):
            for k in d:
                if k not in links:
                    raise ValueError(f"{self.name}: {what}: {k!r} is not a link; {did_you_mean(k, links, 'links')}")
        out = {}
        for k in links:
            m = _number(mass.get(k, 0.0), "kg", f"mass[{k!r}]")
            if m < 0:
                raise ValueError(f"{self.name}: mass[{k!r}] must not be negative, got {m}")
            c = centre.get(k)
            c = (self.points[c] if isinstance(c, str) and c in self.points else _point(c, f"centre[{k!r}]")) if c is not None else None
            J = _number(inertia[k], "kg m^2", f"inertia[{k!r}]") if k in inertia else None
            out[k] = (m, c, J)
        return out

    # ----------------------------------------------------------------- the drawing
    def _drawing_values(self):
        b = self.built
        pts = dict(self.points)
        joints = b.joints
        masses = {}
        for link, (m, c, J) in self.mass_spec.items():
            ring = [pts[x] for x in (joints[link] if len(joints[link]) >= 2 else self.links[link])]
            gc, Jc = link_mass_properties(ring, m)
            masses[link] = (m, gc if c is None else c, Jc if J is None else J)
        for v, (body, what) in b.virtual.items():
            pts[v] = masses[body][1] if what[0] == "com" else pts[what[1]]
        frame = {GROUND: 0.0}
        for body, (entry, direction) in b.frames.items():
            frame[body] = self.slider_angles[body] if direction is None else cmath.phase(pts[direction] - pts[entry])
        vals = {}
        for name, r in b.recipes.items():
            kind = r[0]
            if kind in ("x", "y"):
                vals[name] = pts[r[1]].real if kind == "x" else pts[r[1]].imag
            elif kind == "len":
                vals[name] = abs(pts[r[2]] - pts[r[1]])
            elif kind == "ang":
                _, d, e, x = r
                vals[name] = _wrap(cmath.phase(pts[x] - pts[e]) - cmath.phase(pts[d] - pts[e]))
            elif kind == "frame":
                _, body, e, x = r
                vals[name] = _wrap(cmath.phase(pts[x] - pts[e]) - frame[body])
            elif kind == "guide":
                vals[name] = _wrap(self.slider_angles[r[1]] - frame[r[2]])
            elif kind == "slot":
                vals[name] = _wrap(self.slot_angles[r[1]] - frame[r[2]])
            elif kind == "radius":
                vals[name] = abs(pts[r[1]] - pts[r[2]])
        for link, (m, _, J) in masses.items():
            vals[f"m_{link}"], vals[f"J_{link}"] = m, J
        vals["g"] = self.g
        for x, f in self.force_values.items():
            vals[f"Fx_{x}"], vals[f"Fy_{x}"] = f.real, f.imag
        vals.update({f"M_{k}": v for k, v in self.moment_values.items()})
        vals.update(self.extra)

        def at_drawing(recipe):
            if recipe[0] == "angle":
                return frame[recipe[1]]
            if recipe[0] == "length":
                return abs(pts[recipe[2]] - pts[recipe[1]])
            if recipe[0] == "arc":
                return cmath.phase(pts[recipe[1]] - pts[recipe[2]])
            return 0.0

        self._guess = np.array([at_drawing(r) for r in b.coords.values()], float)
        self._u0 = np.array([at_drawing(r) for r in b.inputs.values()], float)
        vals.update(drawing_values(self.model, self.elements, self._guess, self._u0, vals))
        missing = [n for n in self.model.parameters if n not in vals]
        if missing:
            raise ValueError(f"{self.name}: give the values of the loads' parameters {missing} in params=")
        return {k: vals[k] for k in self.model.parameters}

    # ----------------------------------------------------------------- what it is
    @property
    def mechanism(self):
        """The ``Mechanism``: coordinates, inputs, parameters, loop equations, points."""
        return self.built.mechanism

    @property
    def model(self):
        """The ``Model``: a body per link, every joint, gravity and the loads."""
        return self.built.model

    @property
    def params(self) -> dict:
        """Every parameter's value in this drawing (SI), by name (a fresh dict)."""
        return dict(self._values)

    @property
    def guess(self) -> np.ndarray:
        """The coordinates at the drawing ``(m,)``: every link's angle, travels 0."""
        return self._guess.copy()

    @property
    def input_at_drawing(self) -> np.ndarray:
        """The inputs at the drawing ``(dof,)`` (rad or m)."""
        return self._u0.copy()

    @property
    def joints(self) -> tuple[str, ...]:
        """The names of the joints whose reactions inverse dynamics and statics give."""
        return tuple(joint_name(j) for j in self.model.joints)

    def equations(self) -> list[str]:
        """The loop equations as an engineer writes them, one per closing joint:
        ``"loop B: len_O2_A e^{i theta_crank} + len_A_B e^{i theta_coupler} - ... = 0"``."""
        return [f"{name}: {show(terms)} = 0" for name, terms in self.built.loops]

    def __repr__(self):
        m = self.mechanism
        return (f"Linkage({self.name!r}: {len(self.links)} links, {len(self.built.loops)} loops, coordinates {m.coords}, "
                f"inputs {m.inputs}, joints {self.joints})")

    # ----------------------------------------------------------------- solving
    def _p(self, p):
        if p is None:
            return self.params
        unknown = [k for k in p if k not in self._values]
        if unknown:
            derived = any(k.startswith("J_") or "_G_" in k for k in unknown)
            hint = ("; a link's centre of mass and inertia follow its joints unless given: pass centre= or inertia= to "
                    "Linkage for values of your own" if derived else "")
            see = f"did you mean {closest(unknown[0], self._values)!r}?" if closest(unknown[0], self._values) else "see Linkage.params"
            raise ValueError(f"{self.name}: unknown parameter(s) {unknown}; {see}{hint}")
        return {**self._values, **{k: p[k] for k in p}}

    def _approach(self, samples: Samples):
        """`samples` with the way from the drawing's input to the first sample put in front,
        and how many samples that added."""
        u = np.asarray(samples.u, float)
        u0 = self._u0
        if np.max(np.abs(u[0] - u0)) <= 1e-12 * (1.0 + np.max(np.abs(u0))):
            return samples, 0
        way = u0[None, :] + np.linspace(0.0, 1.0, APPROACH, endpoint=False)[:, None] * (u[0] - u0)[None, :]
        zero = np.zeros_like(way)
        t = np.asarray(samples.times, float)
        return Samples(np.concatenate([way, u]), np.concatenate([zero, np.asarray(samples.u_dot, float)]),
                       np.concatenate([zero, np.asarray(samples.u_ddot, float)]), np.concatenate([np.full(APPROACH, t[0]), t])), APPROACH

    def _samples(self, drive, t):
        mech = self.mechanism
        if isinstance(drive, Samples):
            if t is not None:
                raise ValueError(f"{self.name}: a Samples drive carries its own times (Samples(t=...)); leave t out")
            return check_samples(mech, drive)
        if t is None:
            raise ValueError(f"{self.name}: t (the sample times, s) is required for a drive law; or give Samples(u, u_dot, u_ddot)")
        t = np.asarray(t, float)
        u, ud, udd = (np.asarray(x) for x in drive_rates(drive, t, mech.dof))
        return Samples(u, ud, udd, t)

    def _stroke(self, us, what: str) -> np.ndarray:
        """A stroke of inputs as ``(N, dof)``; ``ValueError`` naming `what` otherwise."""
        dof = self.mechanism.dof
        u = np.asarray(us, float)
        if u.ndim == 1 and dof == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[0] < 1 or u.shape[1] != dof:
            raise ValueError(f"{self.name}: {what} must be a stroke of shape (N,) or (N, {dof}) with N >= 1 "
                             f"(inputs {list(self.mechanism.inputs)}), got shape {np.shape(us)}")
        return u

    def solve(self, us, p: Mapping | None = None, *, options: SolverOptions = SolverOptions()):
        """Positions along a stroke of inputs ``us (N,)`` or ``(N, dof)`` (in the order
        given), on the drawing's assembly mode: a ``Solution`` (``sol["theta_rocker"]``)."""
        s, k = self._approach(check_samples(self.mechanism, Samples(self._stroke(us, "us"), 0.0, 0.0)))
        sol = solve_stroke(self.mechanism, s.u, self._p(p), self._guess, options=options)
        return _drop(sol, k)

    def motion(self, drive, t=None, p: Mapping | None = None, *, options: SolverOptions = SolverOptions()) -> Motion:
        """Positions, velocities and accelerations of every coordinate and named point (joints,
        tracers, centres of mass ``G_<link>``) along a drive law at times `t`, or along
        ``Samples(u, u_dot, u_ddot)``: a ``Motion``."""
        s, k = self._approach(self._samples(drive, t))
        return _drop(motion(self.mechanism, s, p=self._p(p), guess=self._guess, options=options), k)

    def inverse_dynamics(self, drive, t=None, p: Mapping | None = None, *, quasi_static: bool = False,
                         options: SolverOptions = SolverOptions()) -> InverseDynamics:
        """Everything along a drive law at times `t` or along ``Samples(u, u_dot, u_ddot)``
        (the stroke may reverse), from one call: coordinates and their rates, every named
        point's position, velocity and acceleration (``points``), the drive's torque or force
        (``tau``) and every joint's reaction (``joints``; ``reaction(name)``)."""
        s, k = self._approach(self._samples(drive, t))
        res = inverse_dynamics(self.model, s, p=self._p(p), guess=self._guess, quasi_static=quasi_static, options=options,
                               friction=self.friction)
        return _drop(res, k)

    def statics(self, u, p: Mapping | None = None, *, t=0.0, options: SolverOptions = SolverOptions()) -> InverseDynamics:
        """Statics at the inputs ``u (N,)`` or ``(N, dof)`` (solved in the order given, from
        the drawing): the holding torque or force (``tau``) and every joint's reaction under
        gravity and the loads, at rest."""
        u = self._stroke(u, "u")
        samples = check_samples(self.mechanism, Samples(u, 0.0, 0.0, np.full(u.shape[:1], float(t))))
        return self.inverse_dynamics(samples, p=p, quasi_static=True, options=options)

    holding = linkage_holding

    power = linkage_power  # (linkage/power.py: the dampers' and the joints' friction's dissipation)

    from .forward import linkage_forward_dynamics as forward_dynamics  # (linkage/forward.py: spec.py is full)
    def mass_properties(self, p: Mapping | None = None) -> dict:
        """``{link: (mass (kg), centre of mass (complex, m, at the drawing's pose), inertia
        about it (kg m^2))}`` for the drawing, or for its parameters changed by `p` (the
        centre then at the drawing's coordinates, the inertia the changed shape's): what the
        model's bodies use, derived or given (see the class's `mass`)."""
        from ..actuators import resolve

        values = self._p(p)
        mech = self.mechanism
        out = {}
        for body in self.model.bodies:
            g = mech.point(body.position, np.asarray(self.guess), np.asarray(self.input_at_drawing), values)
            out[body.name] = (float(resolve(body.mass, values)), complex(g), float(resolve(body.inertia, values)))
        return out

    def scene(self, stroke=None, speed: float = 1.0, summary: str | None = None):
        """This linkage as a ``Scene`` (what ``run_scene``, ``sweep_scene``, ``sweep_dataset``
        and the design functions take; they also take the linkage itself, as
        ``linkage.scene()``): its drawing's parameters as defaults, the driven input from
        ``stroke = (start, end)`` (default: a crank's whole turn from the drawing, an
        actuator's or slider's drawing value to 1.5 times it) at constant ``speed`` (rad/s
        or m/s); the table holds every coordinate, the drive's effort and every joint's
        reaction, with joint friction where the linkage has it (its ``mu_<key>``,
        ``rpin_<key>``, ``cv_<key>`` among the scene's parameters)."""
        from ..scenes.linkage_scene import linkage_scene
        return linkage_scene(self, stroke, speed, summary)


def _drop(result, k: int):
    """A stroke's result without its first `k` samples (the approach from the drawing)."""
    if k == 0:
        return result
    return jax.tree_util.tree_map(lambda x: x[k:], result)
