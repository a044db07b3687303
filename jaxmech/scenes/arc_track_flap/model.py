"""The arc-track flap's model: its design method (Ch. 4), validity checks, mechanism,
loads and statics, and the scenes (see the package docstring)."""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ...actuators import ScrewJack
from ...dynamics import Body, Gravity, Model, Moment, generalized_forces
from ...mechanism.mechanism import Mechanism, cis
from ..base import Scene
from ..outputs import Outputs
from ...solver.xla import jit

__all__ = ["SCENE", "LANDING_SCENE", "SCENARIOS", "PARAMETERS", "THESIS_INPUTS", "MECHANISM", "scene_for", "design", "geometry", "validate", "air_moment", "screw_torques", "SCREW", "MODEL", "quasi_static", "OUTPUT_UNITS"]


MM = 1e-3  #: one millimetre (m): the thesis's lengths are in mm
DEG = math.pi / 180.0  #: one degree (rad)

#: Whole-flap air moments (N m) at the closed (``M12_i``) and deployed (``M12_f``) flap
#: for the thesis's two flight scenarios (Section 5.2).  Cruise is given for the closed
#: flap only; the thesis's sheet (Fig. 46) holds it over the stroke.
SCENARIOS = {
    "cruise": {"M12_i": 750.0, "M12_f": 750.0},
    "landing": {"M12_i": 220.0, "M12_f": 650.0},
}

#: The Chapter 4 design inputs of the case study (Table 2, yellow cells), SI.
THESIS_INPUTS = dict(
    a1=275 * MM, a2=240 * MM, alpha0=65 * DEG,
    b1=350 * MM, c1=300 * MM, beta1=40 * DEG, beta2=20 * DEG, beta3=35 * DEG,
    x_D=-30 * MM, y_D=340 * MM, m_flap=12.0, g=9.81,
    r=16 * MM, l=8 * MM, f=0.1,
)

#: Every parameter of the scene, in the thesis's order.
PARAM_NAMES = ("a1", "a2", "a3", "alpha0", "b1", "c1", "beta1", "beta2", "beta3", "x_D", "y_D",
           "m_flap", "g", "r", "l", "f", "n_jacks", "weight_share", "M12_i", "M12_f")
_LENGTH_PARAMS = ("a1", "a2", "a3", "b1", "c1", "x_D", "y_D", "r", "l")

#: What each parameter is: (SI unit, meaning); the thesis's names (Table 2).
PARAMETERS = {
    "a1": ("m", "|A0 B0|: flap rotation centre to the screw pivot"),
    "a2": ("m", "|A0 A|: rotation centre to the nut pin A on the flap"),
    "a3": ("m", "screw length B0-B (must exceed the stroke end s34_f)"),
    "alpha0": ("rad", "angle x-A0-B0 of the screw pivot"),
    "b1": ("m", "radius of the outer slot (pin F); b1 > c1"),
    "c1": ("m", "radius of the inner slot (pin G)"),
    "beta1": ("rad", "angle of F's slot start (flap closed)"),
    "beta2": ("rad", "angle F-A0-G between the pins"),
    "beta3": ("rad", "arc angle of both slots = flap rotation"),
    "x_D": ("m", "flap centre of mass D, x (flap closed)"),
    "y_D": ("m", "flap centre of mass D, y (flap closed)"),
    "m_flap": ("kg", "flap mass"),
    "g": ("m/s^2", "gravity"),
    "r": ("m", "screw mean radius"),
    "l": ("m", "screw lead"),
    "f": ("-", "screw thread friction coefficient"),
    "n_jacks": ("-", "screw jacks per flap (the air moment is shared)"),
    "weight_share": ("-", "share of the flap weight each jack carries (1: the thesis's reading)"),
    "M12_i": ("N m", "whole-flap air moment, flap closed (closing positive)"),
    "M12_f": ("N m", "whole-flap air moment, flap deployed (linear in s34 between)"),
}


# --------------------------------------------------------------------------- design (Ch. 4)
def _cosine_rule(s34, a1, a2):
    """theta12, theta13 (rad) from eqs. (3.1.1)-(3.1.2); branch theta12, theta13 in (0, pi)."""
    th12 = jnp.arccos((a1**2 + a2**2 - s34**2) / (2 * a1 * a2))
    th13 = jnp.pi - jnp.arccos((a1**2 + s34**2 - a2**2) / (2 * a1 * s34))
    return th12, th13


def _theta12_i(p, xp=jnp):
    """Closed-flap crank angle of the collinear design: A_i is beta3/2 short of the chord's
    midpoint W, which lies at acos(h/a1) from B0 seen from A0 (h = a2 cos(beta3/2))."""
    return xp.arccos(p["a2"] * xp.cos(p["beta3"] / 2) / p["a1"]) - p["beta3"] / 2


def stroke_ends(p, xp=jnp):
    """(s34_i, s34_f, theta12_i) of the collinear design (Chapter 4, steps 2-4); ``xp=np``
    for eager checks on plain numbers."""
    a1, a2, b3 = p["a1"], p["a2"], p["beta3"]
    # A turns by beta3 on a circle of radius a2: its chord A_i A_f has length
    # delta_s = 2 a2 sin(beta3/2) at distance h = a2 cos(beta3/2) from A0; B0 on the
    # chord's line: a1^2 = h^2 + t^2, t = |B0 W| = s34_i + delta_s/2.
    t = xp.sqrt(a1**2 - (a2 * xp.cos(b3 / 2)) ** 2)
    s34_i = t - a2 * xp.sin(b3 / 2)
    s34_f = s34_i + 2 * a2 * xp.sin(b3 / 2)
    return s34_i, s34_f, _theta12_i(p, xp)


def geometry(p: Mapping) -> dict:
    """Derived geometry of a design (Chapter 4), differentiable in ``p`` (jnp scalars).

    **Returns** (SI): ``delta_s`` = 2 a2 sin(beta3/2), ``h`` = a2 cos(beta3/2), ``t``,
    ``s34_i``, ``s34_f``, ``theta12_i``, ``theta12_f``, ``theta13_i``, ``theta13_f``
    (equal by construction), ``mu_min`` = (pi - beta3)/2, ``r_D`` = |A0 D|,
    ``theta_D_i``, ``A_i``, ``A_f`` and the slot ends ``F1_i``, ``F1_f``, ``F2_i``,
    ``F2_f`` (complex).  Flap-link lengths (g2, p2, q2, alpha2) come from the engine's
    points: see ``table2``.
    """
    a1, a2, al0, b3 = p["a1"], p["a2"], p["alpha0"], p["beta3"]
    s34_i, s34_f, _ = stroke_ends(p)
    th12_i, th13_i = _cosine_rule(s34_i, a1, a2)
    th12_f, th13_f = _cosine_rule(s34_f, a1, a2)
    h = a2 * jnp.cos(b3 / 2)
    B0 = a1 * cis(al0)
    F1_i = p["b1"] * cis(p["beta1"])
    F2_i = p["c1"] * cis(p["beta1"] + p["beta2"])
    return dict(
        delta_s=s34_f - s34_i, h=h, t=jnp.sqrt(a1**2 - h**2), s34_i=s34_i, s34_f=s34_f,
        theta12_i=th12_i, theta12_f=th12_f, theta13_i=th13_i, theta13_f=th13_f,
        mu_min=(jnp.pi - b3) / 2, r_D=jnp.hypot(p["x_D"], p["y_D"]),
        theta_D_i=jnp.arctan2(p["y_D"], p["x_D"]),  # the thesis writes Excel's ATAN2(x; y)
        A_i=B0 + s34_i * cis(al0 + th13_i), A_f=B0 + s34_f * cis(al0 + th13_i),
        F1_i=F1_i, F1_f=F1_i * cis(b3), F2_i=F2_i, F2_f=F2_i * cis(b3),
    )


def design(*, a1, a2, alpha0, b1, c1, beta1, beta2, beta3, x_D, y_D, m_flap, r, l, f,
           g=9.81, a3=None, n_jacks=2.0, weight_share=1.0, M12_i=750.0, M12_f=750.0) -> dict:
    """Chapter 4 design method: inputs -> scene parameters (SI), validated.

    The initial and final nut positions are collinear with B0 (``theta13_f = theta13_i``),
    so the stroke is the chord of A's circle, ``delta s = 2 a2 sin(beta3/2)``, and the
    flap turns by exactly ``beta3``, the arc angle of both slots.  ``a3`` (screw length,
    step 9: slightly longer than ``s34_f``) defaults to ``1.1 s34_f`` rounded up to whole
    centimetres, which gives the thesis's 250 mm.

    **Raises** ``ValueError`` as ``validate``.
    """
    p = dict(a1=a1, a2=a2, a3=0.0, alpha0=alpha0, b1=b1, c1=c1, beta1=beta1, beta2=beta2,
             beta3=beta3, x_D=x_D, y_D=y_D, m_flap=m_flap, g=g, r=r, l=l, f=f,
             n_jacks=n_jacks, weight_share=weight_share, M12_i=M12_i, M12_f=M12_f)
    p = {k: float(v) for k, v in p.items()}
    _validate_design(p)
    s34_f = float(stroke_ends(p, np)[1])
    p["a3"] = float(a3) if a3 is not None else math.ceil(round(1.1 * s34_f * 100, 9)) / 100
    validate(p)
    return p


# --------------------------------------------------------------------------- validity (Sec. 5.3)
def _validate_design(p):
    if not p["c1"] < p["b1"]:
        raise ValueError(
            f"c1 = {p['c1']:.6g} m must be smaller than b1 = {p['b1']:.6g} m (pin G runs in the inner "
            f"slot; the thesis's sheet colours c1 red): lower c1 or raise b1"
        )
    if not p["a1"] > p["a2"]:
        raise ValueError(
            f"a1 = {p['a1']:.6g} m must exceed a2 = {p['a2']:.6g} m, otherwise s34_i <= 0 (B0 would lie "
            f"inside the circle of A): raise a1 or lower a2"
        )
    if not 0.0 < p["beta3"] < math.pi:
        raise ValueError(f"beta3 = {p['beta3']:.6g} rad (flap rotation range) must lie in (0, pi)")
    if not 0.0 < abs(p["beta2"]) < math.pi:
        raise ValueError(
            f"beta2 = {p['beta2']:.6g} rad must lie in (0, pi) in magnitude: with the pins collinear "
            f"with A0 the slots do not locate the flap; change beta2"
        )
    if not p["n_jacks"] > 0:
        raise ValueError(f"n_jacks = {p['n_jacks']:.6g} must be positive (screw jacks per flap)")


def validate(p: Mapping, s34=None) -> None:
    """The thesis's red cells (Section 5.3) as ``ValueError`` (eager; concrete values).

    1. ``c1 >= b1``: c1 must be the smaller radius.
    2. Stroke longer than the screw: ``s34_f > a3``.
    3. A pin leaves its slot: any given ``s34`` outside ``[s34_i, s34_f]`` (equivalently
       ``theta12 - theta12_i`` outside ``[0, beta3]``; theta12 grows with s34).  The
       scene's own stroke is that interval by construction, so this applies to travels
       a caller asks for (``forces(p, s34)``).

    Also: ``a1 > a2`` (else ``s34_i <= 0``), ``0 < beta3 < pi``, ``0 < |beta2| < pi``.
    """
    p = {k: float(p[k]) for k in PARAM_NAMES}
    _validate_design(p)
    s34_i, s34_f, _ = (float(x) for x in stroke_ends(p, np))
    if s34_f > p["a3"]:
        raise ValueError(
            f"the stroke is longer than the screw: s34_f = {s34_f:.6g} m > a3 = {p['a3']:.6g} m (the "
            f"sheet colours a3 red); lengthen the screw to a3 > s34_f, or shorten the stroke "
            f"2 a2 sin(beta3/2) with a smaller a2 or beta3"
        )
    if s34 is not None:
        s = np.atleast_1d(np.asarray(s34, dtype=float))
        tol = 1e-12 * max(1.0, s34_f)
        bad = (s < s34_i - tol) | (s > s34_f + tol)
        if np.any(bad):
            raise ValueError(
                f"s34 = {s[bad][0]:.6g} m is outside the slot range [s34_i, s34_f] = [{s34_i:.6g}, "
                f"{s34_f:.6g}] m: pins F and G would leave their slots (the sheet colours s34 red); "
                f"keep s34 within the stroke"
            )


# --------------------------------------------------------------------------- mechanism
def _flap(q, p):
    """Flap pose: (translation x2 + i y2, rotation from closed theta12 - theta12_i)."""
    return q.x2 + 1j * q.y2, q.theta12 - _theta12_i(p)


def _pt_A(q, u, p):
    c, _ = _flap(q, p)
    return c + p.a2 * cis(p.alpha0 + q.theta12)


def _pt_G(q, u, p):
    c, dth = _flap(q, p)
    return c + p.c1 * cis(p.beta1 + p.beta2 + dth)


def _pt_F(q, u, p):
    c, dth = _flap(q, p)
    return c + p.b1 * cis(p.beta1 + dth)


def _pt_D(q, u, p):
    c, dth = _flap(q, p)
    return c + (p.x_D + 1j * p.y_D) * cis(dth)


def _constraints(q, u, p):
    # Loop A0-B0-A (the thesis's inverted slider-crank, plus the flap translation that the
    # slots remove); then the slots, each |P - A0| - R with a unit gradient (multiplier in N).
    loop = _pt_A(q, u, p) - p.a1 * cis(p.alpha0) - u.s34 * cis(p.alpha0 + q.theta13)
    return [loop, jnp.abs(_pt_G(q, u, p)) - p.c1, jnp.abs(_pt_F(q, u, p)) - p.b1]


def _fixed(fn):
    return lambda q, u, p: fn(p) + 0.0 * u.s34


MECHANISM = Mechanism(
    name="arc_track_flap",
    coords=("theta12", "theta13", "x2", "y2"),
    inputs=("s34",),
    params=PARAM_NAMES,
    lengths=_LENGTH_PARAMS + ("x2", "y2", "s34"),
    signed=("x_D", "y_D"),
    constraints=_constraints,
    points={
        "A0": _fixed(lambda p: 0.0j),
        "B0": _fixed(lambda p: p.a1 * cis(p.alpha0)),
        "A": _pt_A,
        "B": lambda q, u, p: p.a1 * cis(p.alpha0) + p.a3 * cis(p.alpha0 + q.theta13),
        "D": _pt_D,
        "G": _pt_G,
        "F": _pt_F,
    },
    # theta13 in (0, pi): A is CCW of B0 seen from A0 (the thesis's assembly).
    branch=lambda q, u, p: jnp.sin(q.theta13),
)


def initial_pose(p):
    """Coordinates ``(theta12, theta13, x2, y2)`` at the stroke start (the closed flap)."""
    g = geometry(p)
    z = jnp.zeros_like(g["s34_i"])
    return jnp.stack([g["theta12_i"], g["theta13_i"], z, z])


# --------------------------------------------------------------------------- loads and statics
def air_moment(s34, p: Mapping):
    """Air moment on ONE mechanism (N m, > 0 closes the flap): ``M12 / n_jacks`` with M12
    linear in the nut travel from ``M12_i`` (s34_i) to ``M12_f`` (s34_f) (Fig. 48)."""
    s34_i, s34_f, _ = stroke_ends(p)
    x = (s34 - s34_i) / (s34_f - s34_i)
    return (p["M12_i"] + (p["M12_f"] - p["M12_i"]) * x) / p["n_jacks"]


#: The screw jack of eqs. (3.6.9)-(3.6.10): square thread, mean diameter 2 r, lead l.
SCREW = ScrewJack(lead="l", mean_diameter=lambda p: 2 * p.r, friction="f")

#: Bodies and loads of one mechanism (per screw jack) for ``jaxmech.dynamics``: the flap
#: (centre of mass D, angle theta12 + const) carrying ``weight_share * m_flap``, gravity,
#: and the closing air couple ``-air_moment`` on theta12.
MODEL = Model(
    MECHANISM,
    bodies=[Body("D", mass=lambda p: p.weight_share * p.m_flap, angle="theta12", name="flap")],
    loads=[Gravity("g"), Moment("theta12", lambda q, u, p, v, t: -air_moment(u.s34, p), name="air moment")],
)


def screw_torques(L, p: Mapping):
    """Square-thread screw torques (N m) for axial load ``L`` (N), eqs. (3.6.9)-(3.6.10),
    by ``jaxmech.actuators.ScrewJack`` (``SCREW``).

    ``tan(lambda) = l / (2 pi r)`` (the thesis prints ``1/2 pi r``)::

        T_R = r L (2 pi r f + l) / (2 pi r - f l)    raise: open the flap, against L
        T_L = r L (2 pi r f - l) / (2 pi r + f l)    lower; > 0: self-locking (f > tan lambda)
    """
    return SCREW.raise_torque(L, p), SCREW.lower_torque(L, p)


def quasi_static_one(q, u, p):
    """Quasi-static forces at one solved pose, by ``dynamics.generalized_forces`` (inertia
    off): ``-Q + Phi_x^T lambda = tau e_u``, so ``Phi_q^T lambda = Q_q`` and
    ``tau = Phi_u^T lambda - Q_u``.  Multiplier rows: loop (x, y) = ``-F42``; slots G, F
    (unit gradients) = ``-G12G``, ``-G12F``; ``tau = F_input``.
    """
    z = jnp.zeros_like(u)
    tau, lam = generalized_forces(MODEL, q, u, z, z, p, inertia=False)
    F_input = tau[0]
    T_R, T_L = screw_torques(F_input, p)
    # F42 = -lambda_A (nut on flap); its component normal to the screw is F34y' (= 0).
    e_s = cis(p["alpha0"] + q[1])
    F42 = -(lam[0] + 1j * lam[1])
    return dict(F_input=F_input, G12G=-lam[2], G12F=-lam[3], T_R=T_R, T_L=T_L, M12=air_moment(u[0], p),
                F34y=jnp.imag(jnp.conj(e_s) * F42), lam=lam)


@jit
def _quasi_static_batch(q, u, p):
    return jax.vmap(lambda q_, u_: quasi_static_one(q_, u_, p))(q, u)


def quasi_static(q, u, p: Mapping) -> dict:
    """Forces at solved poses ``q (N, 4)``, ``u (N, 1)`` (the engine's Jacobians, no inertia).

    **Returns** ``{name: (N,)}``: ``F_input`` (N, nut push on the flap along +s34),
    ``G12G``, ``G12F`` (N, slot on pin, outward radial positive), ``T_R``, ``T_L`` (N m,
    per jack), ``M12`` (N m, per jack), ``F34y`` (N, nut force normal to the screw) and
    ``lam`` (the multipliers: loop x, loop y, slot G, slot F).
    """
    q, u = jnp.asarray(q), jnp.asarray(u)
    pj = {k: jnp.asarray(p[k], q.dtype) for k in PARAM_NAMES}
    return _quasi_static_batch(q, u, pj)


def _outputs(p, mo):
    out = quasi_static(mo.q, mo.u, p)
    g = p["g"]
    return {
        **{k: out[k] for k in ("F_input", "G12G", "G12F", "T_R", "T_L", "M12")},
        "aA_over_g": jnp.abs(mo.points["A"][2]) / g,
        "aD_over_g": jnp.abs(mo.points["D"][2]) / g,
    }


#: The scenes' outputs: their units, in column order (forces, moments, accelerations in g).
OUTPUT_UNITS = {"F_input": "N", "G12G": "N", "G12F": "N", "T_R": "N m", "T_L": "N m", "M12": "N m", "aA_over_g": "-",
                "aD_over_g": "-"}


# --------------------------------------------------------------------------- scenes
def _drawing(p):
    """Drawing spec (``jaxmech.viz.drawing``): screw B0-B with the nut's line, the flap plate
    A-F-G-D, both arc slots about A0 (the arcs their pins sweep), the chord A_i A_f of the
    design method (fixed points), traced A and D, transmission angle at A (A0-A-B0)."""
    pn = {k: np.asarray(p[k], float) for k in PARAM_NAMES}
    g = geometry(pn)
    return {
        "links": [("B0", "B"), ("A", "F"), ("F", "G"), ("G", "D"), ("D", "A")],
        "ground": ["A0", "B0"],
        "slots": [{"centre": "A0", "radius": float(pn["b1"]), "pin": "F"},
                  {"centre": "A0", "radius": float(pn["c1"]), "pin": "G"},
                  {"line": ("B0", "B")}],
        "chords": [(complex(g["A_i"]), complex(g["A_f"]))],
        "polygons": [("A", "F", "G", "D")],
        "trace": ["A", "D"],
        "transmission": ("A0", "A", "B0"),
    }


def _stroke(p):
    """(s34_i, s34_f) in m; traceable (sweeps call it under jit)."""
    s34_i, s34_f, _ = stroke_ends(p)
    return s34_i, s34_f


def _moments(scenario):
    """``"750 N m"`` (held) or ``"220 -> 650 N m"`` (closed -> deployed)."""
    m_i, m_f = SCENARIOS[scenario]["M12_i"], SCENARIOS[scenario]["M12_f"]
    return f"{m_i:g} N m" if m_i == m_f else f"{m_i:g} -> {m_f:g} N m (closed -> deployed)"


@functools.cache
def scene_for(scenario: str = "cruise") -> Scene:
    """The scene with the air moments of a flight scenario ("cruise" or "landing")."""
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}, got {scenario!r}")
    defaults = design(**THESIS_INPUTS, a3=0.250, **SCENARIOS[scenario])
    return Scene(
        name="arc_track_flap" if scenario == "cruise" else f"arc_track_flap_{scenario}",
        summary=f"circular-arc-track flap, screw jack at 35 mm/s, {scenario} air moment {_moments(scenario)} (Arslan 2022)",
        mechanism=MECHANISM,
        defaults=defaults,
        guess=initial_pose,
        stroke=_stroke,
        speed=0.035,
        units={"s34": "m", "theta12": "rad", "theta13": "rad", "x2": "m", "y2": "m"},
        outputs=Outputs(_outputs, OUTPUT_UNITS),
        validate=validate,
        drawing=_drawing,
        parameters=PARAMETERS,
        document="G. Arslan, 'Development of kinetostatic design methodology for airplane flap mechanisms', MSc thesis, İzmir Institute of Technology, December 2022; corrections in docs/seeds/arc_track_flap.md",
    )


#: Cruise (the default flight scenario): M12 = 750 N m over the stroke.
SCENE = scene_for("cruise")
#: Landing: M12 from 220 N m (closed) to 650 N m (deployed), linear in s34.
LANDING_SCENE = scene_for("landing")
