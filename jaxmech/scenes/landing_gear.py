"""Hydraulic retractable nose gear (seed 001_2d20636cf4490e47).

Source: SEM0501 "Projeto de Mecanismo", A. Z. Creppe, 2021 (a student report, in
Portuguese).  The analysis behind every choice below, with evidence, is in
``docs/seeds/landing_gear.md``.  ``tests/seeds/reference_landing_gear.py`` is an independent
numpy/scipy implementation that the tests compare against.

**Model.**  The gear leg AB (2.5 ft) turns about the airframe pivot ``B``.  A hydraulic cylinder
runs from the fixed airframe pivot ``C`` to the rod end ``P``, which is rigid on the gear.  Its
pin-to-pin length ``x`` goes from 1.25 ft (gear down) to 2.0 ft (gear up).  Gauss plane with the
real axis along B -> C.  The gear angle ``theta`` (angle C-B-P) is measured *clockwise*, so an
increasing theta is the report's clockwise retraction.  ``phi`` is the direction of the
cylinder, P -> C.  Vector loop (report §3.2 eq. 4 is its law-of-cosines form):

    d e^{-i theta} + x e^{i phi} - h = 0        <=>   x^2 = d^2 + h^2 - 2 d h cos(theta)

The input is the cylinder length ``x``.  The coordinates are ``theta`` (gear angle) and
``phi`` (cylinder angle).  ``gear_by_angle`` is the same loop driven by ``theta`` instead; it is
used for the report's linear-angle law.

**Design (report §3.1).**  ``d`` (B to the rod end) and ``h`` (B to C) are not copied: ``design``
solves the three design equations with the engine (``jaxmech.solve``).  They are the start and
end lengths over a 90 deg rotation, plus the report's unstated right angle at P in the gear-down
position.  The result is d = 0.643611 ft, h = 1.405964 ft, theta1 = 62.7566 deg.  Without the
right angle the design is a one-parameter family (``design_family``).

**Units.**  SI inside (m, s, rad).  The report works in feet: 1 ft = 0.3048 m (``FT``), so the
stroke is 0.381-0.6096 m and the piston speed 0.25 ft/s = 0.0762 m/s.  The ``report_*``
transcriptions keep the report's units (ft, rounded constants).

**Default drive.**  Constant piston speed 0.25 ft/s, which retracts in 3 s (report eq. 2, the
physically consistent law).  The report's linear-angle law, theta = theta1 + (pi/6) t (eq. 3), is
``linear_angle_motion``.  The two laws contradict each other.

**Corrections to the report** (10 in all, with evidence, in ``docs/seeds/landing_gear.md``):

- §3.1: cos(theta2) = **-**sin(theta1).  The second closure must read ``+2dh sin(theta1)``.  The
  two sign errors cancel, so eq. 1 and d are right (``report_printed_system``).
- §3.1: theta1 = arcsin(1.25/**h**), not arcsin(1.25/0.64361), whose argument is 1.94 > 1.
- §3.1: the right angle at P is a hidden third design condition.  The design is not unique, and
  the transmission angle falls from 90 deg to 18.77 deg at gear-up (``transmission_angle``).
- §3.2: eqs. 2 (constant piston speed) and 3 (constant gear rate) contradict each other.
  Eq. 5 is evaluated on the linear theta(t) of eq. 3: the plotted omega integrates to 99.58 deg,
  not 90 deg (``report_plotted_omega_angle``).
- Listing 1 lines 19-22 leave out the factor f of eq. 6, so Fig. 8 is wrong (``report_listing``).
- §4.1: x(t) is exactly linear under eq. 2.  theta is the gear's angle, not the piston's.  The
  rising omega comes from a *worse* transmission angle: the cylinder needs 3.1 times the force
  per unit gear torque at gear-up (``force_ratio``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..kinematics import ConstantSpeed, Motion, input_derivatives, motion
from ..mechanism.mechanism import Mechanism, cis
from ..solver.options import SolverOptions
from ..solver.positions import solve
from ..solver.solution import Solution
from .base import Scene
from .outputs import Outputs
from ..solver.xla import jit

__all__ = ["SCENE", "OUTPUT_UNITS", "FT", "SPEED", "mechanism", "design", "design_family", "DEFAULTS", "PARAMETERS",
           "gear_angle", "constant_speed_motion", "linear_angle_motion", "retraction_time", "transmission_angle",
           "moment_arm", "REPORT", "report_printed_system", "report_eq5", "report_eq6", "report_listing",
           "report_plotted_omega_angle"]

FT = 0.3048  #: m per ft (exact)
X1, X2 = 1.25 * FT, 2.0 * FT  #: cylinder length gear down / gear up (m): 1.25 ft, 2 ft
DTHETA = np.pi / 2  #: required clockwise rotation (rad)
T_RETRACT = 3.0  #: the report's chosen retraction time (s)
SPEED = (X2 - X1) / T_RETRACT  #: piston speed (m/s): 0.25 ft/s, report eq. 2
T_REQUIRED = 4.0  #: "menos de 4 segundos" (s)

#: The report's rounded numbers (ft, rad, as printed in §3.1-§3.2 and Listing 1).
REPORT = dict(d=0.64361, d_other=-1.89361, h=1.4060, theta1=1.0953, theta1_deg=62.76,
              c0=2.3911, c1=1.8098, c2=3.6196, c3=0.9049, omega=np.pi / 6, v=0.25)


# --------------------------------------------------------------------------- design (§3.1)
def _dist(z):
    return jnp.abs(z)


#: The three design equations (report §3.1), in metres.  Unknowns d, h, theta1; input x1.
#:   (E1) |P(theta1) - C| = x1            start of the stroke
#:   (E2) |P(theta1 + dtheta) - C| = x2   end of the stroke, after rotating dtheta clockwise
#:   (E3) hypot(d, x1) = h                right angle at P at gear-down (the hidden condition)
design_mechanism = Mechanism(
    name="landing_gear_design",
    coords=("d", "h", "theta1"),
    inputs=("x1",),
    params=("x2", "dtheta"),
    lengths=("d", "h", "x1", "x2"),
    constraints=lambda q, u, p: [
        _dist(q.d * cis(-q.theta1) - q.h) - u.x1,
        _dist(q.d * cis(-(q.theta1 + p.dtheta)) - q.h) - p.x2,
        jnp.hypot(q.d, u.x1) - q.h,
    ],
)

#: The design without the right-angle condition: (d, h) for a chosen theta1 (input).
family_mechanism = Mechanism(
    name="landing_gear_family",
    coords=("d", "h"),
    inputs=("theta1",),
    params=("x1", "x2", "dtheta"),
    lengths=("d", "h", "x1", "x2"),
    constraints=lambda q, u, p: [
        _dist(q.d * cis(-u.theta1) - q.h) - p.x1,
        _dist(q.d * cis(-(u.theta1 + p.dtheta)) - q.h) - p.x2,
    ],
)


def design(x1=X1, x2=X2, dtheta=DTHETA, *, guess=(FT, FT, 1.0), options: SolverOptions = SolverOptions()) -> Solution:
    """Solve the report's design equations (§3.1) for ``d``, ``h`` (m) and ``theta1`` (rad).

    Uses the engine's Newton solve of ``design_mechanism`` from a neutral guess (1 ft, 1 ft,
    1 rad).  It is not the closed form.  The result is differentiable in ``x1``, ``x2`` and
    ``dtheta`` (implicit function theorem).

    **Arguments**: `x1`, `x2`: cylinder lengths gear down / up (m); `dtheta`: rotation (rad);
    `guess`: ``(d, h, theta1)``.

    **Returns** a ``Solution`` (``sol["d"]``, ``sol["h"]``, ``sol["theta1"]``).
    """
    return solve(design_mechanism, x1, {"x2": x2, "dtheta": dtheta}, jnp.asarray(guess), options=options)


def design_family(theta1, x1=X1, x2=X2, dtheta=DTHETA, *, guess=(0.5 * FT, 1.5 * FT)) -> Solution:
    """``(d, h)`` (m) that meet only the two stroke conditions for a chosen ``theta1`` (rad).

    This shows that the report's design is not unique without its hidden right angle.  The
    guess selects the ``d < h`` branch.
    """
    return solve(family_mechanism, theta1, {"x1": x1, "x2": x2, "dtheta": dtheta}, jnp.asarray(guess))


# --------------------------------------------------------------------------- the gear
def _theta(q, u):
    return q.theta if "theta" in q else u.theta


def _points():
    # B: gear pivot; C: cylinder pivot; P: rod end on the gear; A: leg end (AB along BP
    # rotated clockwise by beta; the report never gives the offset, default 0).
    return {
        "B": lambda q, u, p: 0.0 * p.h + 0j,
        "C": lambda q, u, p: p.h + 0j,
        "P": lambda q, u, p: p.d * cis(-_theta(q, u)),
        "A": lambda q, u, p: p.AB * cis(-(_theta(q, u) + p.beta)),
    }


_PARAMS = ("d", "h", "x1", "x2", "AB", "beta")
_LENGTHS = ("d", "h", "x1", "x2", "AB")

#: Driven by the cylinder length ``x`` (m); coordinates ``theta`` (gear, clockwise) and ``phi``
#: (cylinder direction P -> C, counter-clockwise).  Branch: P below the B-C line, sin(theta) > 0.
mechanism = Mechanism(
    name="landing_gear",
    coords=("theta", "phi"),
    inputs=("x",),
    params=_PARAMS,
    lengths=_LENGTHS + ("x",),
    constraints=lambda q, u, p: [p.d * cis(-q.theta) + u.x * cis(q.phi) - p.h],
    points=_points(),
    branch=lambda q, u, p: jnp.sin(q.theta),
)

#: The same loop driven by the gear angle ``theta`` (report eq. 3's point of view); coordinates
#: ``x`` (cylinder length, m) and ``phi``.
gear_by_angle = Mechanism(
    name="landing_gear_by_angle",
    coords=("x", "phi"),
    inputs=("theta",),
    params=_PARAMS,
    lengths=_LENGTHS + ("x",),
    constraints=lambda q, u, p: [p.d * cis(-u.theta) + q.x * cis(q.phi) - p.h],
    points=_points(),
    branch=lambda q, u, p: q.x,
)


def _default_params() -> dict:
    # With the arm perpendicular to the cylinder at x1 (h^2 = d^2 + x1^2) and 90 degrees of
    # rotation, x2^2 = d^2 + h^2 + 2 d x1 gives 2 d^2 + 2 x1 d + x1^2 - x2^2 = 0.  Evaluated
    # in numpy (float64 whatever JAX's mode) and without compiling anything at import;
    # ``design()`` recovers the same numbers as an engine solve (tests/seeds/test_landing_gear.py).
    d = 0.5 * (-X1 + np.sqrt(2.0 * X2**2 - X1**2))
    h = float(np.hypot(d, X1))
    return {"d": float(d), "h": h, "x1": X1, "x2": X2, "AB": 2.5 * FT, "beta": 0.0}


#: Default parameters (m, rad): ``d``, ``h`` from the right-angle design closed form.
DEFAULTS = _default_params()

#: What each parameter is: (SI unit, meaning).
PARAMETERS = {
    "d": ("m", "gear pivot B to the rod end P (report §3.1 design)"),
    "h": ("m", "gear pivot B to the cylinder pivot C (report §3.1 design)"),
    "x1": ("m", "cylinder pin-to-pin length, gear down (stroke start; 1.25 ft)"),
    "x2": ("m", "cylinder pin-to-pin length, gear up (stroke end; 2 ft)"),
    "AB": ("m", "gear leg, pivot B to the wheel end A (2.5 ft)"),
    "beta": ("rad", "angle of the leg BA clockwise from B-P (the report gives none: 0)"),
}


def _guess(p: Mapping, x):
    # Law of cosines (eq. 4) on the sin(theta) > 0 branch, then phi from the loop; exact,
    # so it only has to pick the branch.
    d, h = jnp.asarray(p["d"]), jnp.asarray(p["h"])
    th = jnp.arccos(jnp.clip((d * d + h * h - x * x) / (2 * d * h), -1.0, 1.0))
    return jnp.stack([th, jnp.angle(h - d * cis(-th))], axis=-1)


def gear_angle(p: Mapping, x) -> Solution:
    """Solve the loop for ``theta`` and ``phi`` at cylinder lengths ``x`` (m); batched."""
    x = jnp.asarray(x)
    return solve(mechanism, x, dict(p), _guess(p, x))


def constant_speed_motion(p: Mapping, t, v=SPEED, *, points=None) -> Motion:
    """Motion under a constant piston speed ``v`` (m/s) from ``x1`` (report eq. 2): ``x``,
    ``theta``, ``phi`` and their first and second time derivatives at times ``t`` (s).
    `points`: named points to differentiate too (default all, as ``run_scene`` does)."""
    g = _guess(p, p["x1"])
    return motion(mechanism, ConstantSpeed(jnp.asarray(p["x1"]), jnp.asarray(v)), t, dict(p), g, points=points)


def linear_angle_motion(p: Mapping, t, omega=DTHETA / T_RETRACT) -> Motion:
    """Motion under the report's linear-angle law (eq. 3): ``theta = theta1 + omega t`` with
    ``omega = pi/6`` rad/s, theta1 solved at ``x1``.

    ``Motion.q`` holds ``x`` (m) and ``phi``.  Each time is an independent engine solve of
    ``gear_by_angle``.  The derivatives are ``q_dot = q' omega`` and ``q_ddot = q'' omega^2``,
    with ``q'`` and ``q''`` from the implicit function theorem.  ``x_dot`` is not constant,
    which contradicts eq. 2.  ``points`` is left empty.
    """
    t = jnp.asarray(t)
    theta1 = gear_angle(p, jnp.array([p["x1"], p["x2"]]))["theta"][0]
    th = theta1 + omega * t
    d, h = jnp.asarray(p["d"]), jnp.asarray(p["h"])
    x_guess = jnp.sqrt(d * d + h * h - 2 * d * h * jnp.cos(th))  # eq. 4: only picks the branch
    guess = jnp.stack([x_guess, jnp.angle(h - d * cis(-th))], axis=-1)
    sol = solve(gear_by_angle, th, dict(p), guess)
    pj = {k: jnp.asarray(v, sol.q.dtype) for k, v in p.items()}
    d1, d2 = _derivatives(gear_by_angle, sol.q, th[:, None], pj)
    w = jnp.full_like(th, omega)[:, None]
    return Motion(
        t=t, u=th[:, None], u_dot=w, u_ddot=jnp.zeros_like(w), q=sol.q, q_dot=d1[..., 0] * w,
        q_ddot=d2[..., 0, 0] * w * w, dq_du=d1, d2q_du2=d2, points={}, status=sol.status,
        coords=gear_by_angle.coords, inputs=gear_by_angle.inputs,
    )


@functools.partial(jit, static_argnums=(0,))
def _derivatives(mech, q, u, p):
    return jax.vmap(lambda q_, u_: input_derivatives(mech, q_, u_, p))(q, u)


def retraction_time(p: Mapping, v=SPEED):
    """``(time (s), rotation (rad))`` for a full stroke at constant piston speed ``v``.

    The rotation comes from the engine solve at both ends.  The report requires a time below
    ``T_REQUIRED`` = 4 s and a rotation of pi/2.
    """
    sol = gear_angle(p, jnp.array([p["x1"], p["x2"]]))
    th = sol["theta"]
    return (p["x2"] - p["x1"]) / v, th[1] - th[0]


def transmission_angle(q, p=None):
    """Angle at P between P -> B and P -> C (rad), from ``q = (theta, phi)``.  It is 90 deg at
    gear-down for the report's design and 18.77 deg at gear-up."""
    theta, phi = q[..., 0], q[..., 1]
    return jnp.pi - theta - phi


def moment_arm(mo: Motion):
    """``dx/dtheta`` (m/rad): gear torque per unit cylinder force (virtual work
    ``T dtheta = F dx``), i.e. the cylinder's mechanical advantage, from the implicit ``dtheta/dx``."""
    return 1.0 / mo.dq_du[:, 0, 0]


def _outputs(p, mo: Motion):
    arm = moment_arm(mo)
    return {
        "transmission_angle": transmission_angle(mo.q),
        "moment_arm": arm,
        "force_ratio": arm[0] / arm,
        "x_ft": mo.u[:, 0] / FT,
        "theta_deg": jnp.degrees(mo.q[:, 0]),
        "phi_deg": jnp.degrees(mo.q[:, 1]),
    }


#: The scene's outputs: their units, in column order.
OUTPUT_UNITS = {"transmission_angle": "rad", "moment_arm": "m", "force_ratio": "-", "x_ft": "ft", "theta_deg": "deg",
                "phi_deg": "deg"}


def _validate(p):
    if not p["x2"] > p["x1"]:
        raise ValueError(f"x2 must exceed x1 (extending cylinder), got x1={p['x1']}, x2={p['x2']} m")
    if not (abs(p["d"] - p["h"]) < p["x1"] and p["x2"] < p["d"] + p["h"]):
        raise ValueError(
            f"the cylinder stroke {p['x1']:.4g}..{p['x2']:.4g} m does not fit |d - h| < x < d + h "
            f"with d={p['d']:.4g}, h={p['h']:.4g} m; change d, h or the stroke"
        )


def _drawing(p):
    return {
        "links": [("B", "P"), ("B", "A"), ("C", "P")],
        "ground": ["B", "C"],
        "slots": [],
        "chords": [],
        "trace": ["A", "P"],
        "transmission": ("B", "P", "C"),
        "output": "theta",
    }


# --------------------------------------------------------------------------- the report, as printed (ft)
def report_printed_system(d, h, theta1, x1=1.25, x2=2.0):
    """§3.1 system with its printed signs (cos theta2 = +sin theta1): the difference of the
    two printed closures, ``2dh(cos theta1 - sin theta1)``, beside ``x2^2 - x1^2`` (ft^2).  They
    should be equal; they are not even of the same sign."""
    return 2 * d * h * (jnp.cos(theta1) - jnp.sin(theta1)), x2 ** 2 - x1 ** 2


def report_eq5(theta):
    """Report eq. 5: ``omega(theta) = sqrt(2.3911 - 1.8098 cos) / (3.6196 sin)`` (rad/s, ft
    constants).  This is correct as a function of theta under eq. 2."""
    f = REPORT["c0"] - REPORT["c1"] * jnp.cos(theta)
    return jnp.sqrt(f) / (REPORT["c2"] * jnp.sin(theta))


def report_eq6(theta):
    """Report eq. 6 as printed (with the factor f), as a function of theta (rad/s^2)."""
    f = REPORT["c0"] - REPORT["c1"] * jnp.cos(theta)
    w = report_eq5(theta)
    s, c = jnp.sin(theta), jnp.cos(theta)
    return (REPORT["c3"] * s ** 2 * w - c * w * f) / (REPORT["c2"] * s ** 2 * jnp.sqrt(f))


def report_listing(t):
    """The report's Octave Listing 1: theta from eq. 3, omega = eq. 5 evaluated on that theta,
    and alpha without the factor f in ``anum2`` (lines 19-22).  Returns a dict, in ft and s."""
    t = jnp.asarray(t)
    th = REPORT["theta1"] + (jnp.pi / 6) * t
    f = REPORT["c0"] - REPORT["c1"] * jnp.cos(th)
    w = jnp.sqrt(f) / (REPORT["c2"] * jnp.sin(th))
    a = (REPORT["c3"] * jnp.sin(th) ** 2 * w - jnp.cos(th) * w) / (REPORT["c2"] * jnp.sin(th) ** 2 * jnp.sqrt(f))
    return {"t": t, "theta": th, "x": jnp.sqrt(f), "omega": w, "alpha": a}


def report_plotted_omega_angle(t_end=T_RETRACT, n=64):
    """Angle swept by the report's plotted omega(t) (Fig. 7) over 0..t_end (rad), by
    ``n``-point Gauss-Legendre quadrature.  If Figs. 5 and 7 agreed this would be pi/2."""
    x, w = np.polynomial.legendre.leggauss(n)
    t = 0.5 * t_end * (x + 1.0)
    return 0.5 * t_end * jnp.sum(jnp.asarray(w) * report_listing(jnp.asarray(t))["omega"])


SCENE = Scene(
    name="landing_gear",
    summary="hydraulic nose gear (Creppe 2021): cylinder 1.25 -> 2 ft at 0.25 ft/s, gear turns 90 deg in 3 s",
    mechanism=mechanism,
    defaults=DEFAULTS,
    parameters=PARAMETERS,
    guess=lambda p: _guess(p, p["x1"]),
    stroke=lambda p: (p["x1"], p["x2"]),
    speed=SPEED,
    units={"x": "m", "theta": "rad", "phi": "rad"},
    outputs=Outputs(_outputs, OUTPUT_UNITS),
    validate=_validate,
    drawing=_drawing,
    document="A. Z. Creppe, 'SEM0501 - Dinâmica Aplicada às Máquinas, Trabalho 1 - Projeto de Mecanismo' (Prof. M. A. Trindade), student report, June 2021; corrections in docs/seeds/landing_gear.md",
)
