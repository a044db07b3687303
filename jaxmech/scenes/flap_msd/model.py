"""The double flap's model: parameters, the three loop closures, the closed-form guess,
loads, torque and voltage, and the scene (see the package docstring)."""

from __future__ import annotations

import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ...actuators import DCMotor
from ...dynamics import Body, Gravity, Model, Moment, PointForce, generalized_forces
from ...kinematics import Motion, chain_rule
from ...mechanism.mechanism import Mechanism, cis
from ..base import Scene
from ..outputs import Outputs
from ...solver.xla import jit

__all__ = ["SCENE", "mechanism", "DEFAULTS", "PARAMETERS", "closed_form_positions", "MODEL", "MOTOR", "loop_determinants", "torque", "torque_document", "voltage", "OUTPUT_UNITS"]


_K = 17.0  # the report's "meter-model conversion factor" (§4): drawing units per metre
DEG = np.pi / 180.0  #: one degree (rad)
ALPHA_START, ALPHA_END = 275.0 * DEG, 320.0 * DEG
COORDS = ("beta", "delta", "phi", "psi", "xi", "theta")

#: Report §4 data in SI units (lengths in m: the report's drawing units divided by K).
DEFAULTS = {
    # kinematics
    "a": 3.5 / _K, "b": 9.0 / _K, "c": 5.0 / _K,          # crank OA, coupler AG, flap arm CG
    "l": 9.0 / _K, "r": 6.5 / _K,                          # C - O = l - i r
    "d": 9.0 / _K, "p": 2.25 / _K,                         # bar BD, D-G part of bar DGE
    "s": 7.0 / _K, "t": 8.0 / _K,                          # C - B = s - i t
    "g": 3.0 / _K, "h": 17.75 / _K, "z": 4.0 / _K,         # G-E, link EH, second flap arm FH
    "c1": 1.0, "c2": 0.5,                                  # chords (not scaled by K)
    # inertia (J as printed: M c1 3.5/K, m c2 2.5/K; see the module docstring)
    "M": 20.0, "m": 10.0,
    "J_M": 20.0 * 1.0 * 3.5 / _K, "J_m": 10.0 * 0.5 * 2.5 / _K,
    "G": 9.81,
    # aerodynamics: rho (kg/m^3), U = 240 km/h, S = 1.5 c (m^2), Cl (1/rad), Cm (-)
    "rho": 1.225, "U": 240.0 / 3.6, "S1": 1.5, "S2": 0.75,
    "Cl_delta": 1.4, "Cl_theta": 1.3, "Cm_delta": -0.3, "Cm_theta": -0.3,
    # DC motor: armature resistance (ohm), torque constant (N m/A)
    "R_a": 2.0, "K_m": 20.0,
}

#: What each parameter is: (SI unit, meaning); report §4's names.
PARAMETERS = {
    "a": ("m", "crank O-A (3.5/K)"),
    "b": ("m", "coupler A-G (9/K)"),
    "c": ("m", "main flap arm C-G, normal to the chord (5/K)"),
    "l": ("m", "main flap hinge C from the crank pivot O, x offset: C - O = l - i r"),
    "r": ("m", "main flap hinge C below the crank pivot O: C - O = l - i r"),
    "d": ("m", "bar B-D (9/K)"),
    "p": ("m", "D-G part of the straight bar D-G-E (2.25/K)"),
    "s": ("m", "main flap hinge C from the pivot B, x offset: C - B = s - i t"),
    "t": ("m", "main flap hinge C below the pivot B: C - B = s - i t"),
    "g": ("m", "G-E part of the bar D-G-E (printed q; 3/K)"),
    "h": ("m", "link E-H (17.75/K)"),
    "z": ("m", "second flap arm F-H, normal to its chord (4/K)"),
    "c1": ("m", "main flap chord C-F"),
    "c2": ("m", "second flap chord F-L"),
    "M": ("kg", "main flap mass (at the chord midpoint G1)"),
    "m": ("kg", "second flap mass (at the chord midpoint G2)"),
    "J_M": ("kg m^2", "main flap inertia about G1 (as printed: M c1 3.5/K)"),
    "J_m": ("kg m^2", "second flap inertia about G2 (as printed: m c2 2.5/K)"),
    "G": ("m/s^2", "gravity"),
    "rho": ("kg/m^3", "air density"),
    "U": ("m/s", "airspeed (240 km/h)"),
    "S1": ("m^2", "main flap area"),
    "S2": ("m^2", "second flap area"),
    "Cl_delta": ("1/rad", "main flap lift slope"),
    "Cl_theta": ("1/rad", "second flap lift slope"),
    "Cm_delta": ("-", "main flap moment coefficient"),
    "Cm_theta": ("-", "second flap moment coefficient"),
    "R_a": ("ohm", "DC motor armature resistance"),
    "K_m": ("N m/A", "DC motor torque constant"),
}

_LENGTHS = ("a", "b", "c", "l", "r", "d", "p", "s", "t", "g", "h", "z", "c1", "c2")
# Offsets of the fixed pivots: any sign (and zero) is a valid design.
_SIGNED = ("l", "r", "s", "t")

# Expected sign of the acos in each dyad (circle intersection) on the chosen branch.
BRANCH_SIGNS = (1.0, -1.0, 1.0)


# --------------------------------------------------------------------------- geometry
def _loops(q, u, p):
    """The report's three loop closures (§2.1-§2.3), each a complex number that must vanish."""
    arm = 1j * p.c * cis(-q.delta)  # G - C
    return [
        p.a * cis(u.alpha) + p.b * cis(q.beta) - (p.l - 1j * p.r) - arm,
        p.d * cis(q.phi) + p.p * cis(q.psi) - (p.s - 1j * p.t) - arm,
        (1j * p.c - p.c1) * cis(-q.delta) + p.g * cis(q.psi) + p.h * cis(q.xi) - 1j * p.z * cis(-q.theta),
    ]


def _C(p):
    return p.l - 1j * p.r


def _B(p):
    return _C(p) - (p.s - 1j * p.t)


def _F(q, p):
    return _C(p) + p.c1 * cis(-q.delta)


_POINTS = {
    "O": lambda q, u, p: 0.0 * cis(u.alpha),
    "A": lambda q, u, p: p.a * cis(u.alpha),
    "C": lambda q, u, p: _C(p) + 0.0 * cis(u.alpha),
    "B": lambda q, u, p: _B(p) + 0.0 * cis(u.alpha),
    "G": lambda q, u, p: _C(p) + 1j * p.c * cis(-q.delta),
    "D": lambda q, u, p: _B(p) + p.d * cis(q.phi),
    "E": lambda q, u, p: _C(p) + 1j * p.c * cis(-q.delta) + p.g * cis(q.psi),
    "F": lambda q, u, p: _F(q, p),
    "H": lambda q, u, p: _F(q, p) + 1j * p.z * cis(-q.theta),
    "L": lambda q, u, p: _F(q, p) + p.c2 * cis(-q.theta),
    "G1": lambda q, u, p: _C(p) + 0.5 * p.c1 * cis(-q.delta),
    "G2": lambda q, u, p: _F(q, p) + 0.5 * p.c2 * cis(-q.theta),
    "AC1": lambda q, u, p: _C(p) + 0.25 * p.c1 * cis(-q.delta),
    "AC2": lambda q, u, p: _F(q, p) + 0.25 * p.c2 * cis(-q.theta),
}


def _branch(q, u, p):
    # Each loop's 2x2 Jacobian determinant over its own unknowns is, up to a positive
    # factor, cos(beta+delta), -sin(phi-psi), cos(theta+xi): the sign of the cross
    # product of the loop's two unknown links, i.e. its assembly mode.  All three are
    # positive on the chosen branch, each checked on its own (a flip names its loop).
    return {
        "loop 1 (beta, delta)": jnp.cos(q.beta + q.delta),
        "loop 2 (phi, psi)": -jnp.sin(q.phi - q.psi),
        "loop 3 (xi, theta)": jnp.cos(q.theta + q.xi),
    }


mechanism = Mechanism(
    name="flap_msd",
    coords=COORDS,
    inputs=("alpha",),
    params=tuple(DEFAULTS),
    constraints=_loops,
    lengths=_LENGTHS,
    signed=_SIGNED,
    points=_POINTS,
    branch=_branch,
)


def loop_determinants(q, p):
    """Jacobian determinants of the three loops over their own unknowns (m^2).

    ``(b c cos(beta+delta), -d p sin(phi-psi), h z cos(theta+xi))`` for one sample
    (``q`` of shape ``(6,)``): the constraint Jacobian is block lower triangular, so
    ``det Phi_q`` is their product and loop ``k`` is singular (a toggle: its two unknown
    links aligned) where the ``k``-th vanishes.  The report's ``det(A)`` (§2.1-§2.3) has
    the opposite sign (its first row is negated).
    """
    q = jnp.asarray(q)
    beta, delta, phi, psi, xi, theta = (q[..., i] for i in range(6))
    return jnp.stack(
        [
            p["b"] * p["c"] * jnp.cos(beta + delta),
            -p["d"] * p["p"] * jnp.sin(phi - psi),
            p["h"] * p["z"] * jnp.cos(theta + xi),
        ],
        axis=-1,
    )


# --------------------------------------------------------------------------- closed-form guess
def _dyad(p1, r1, p2, r2, sign, xp=jnp):
    """Angle of ``X - p1`` where ``|X - p1| = r1``, ``|X - p2| = r2`` (NaN if they miss)."""
    dist = xp.abs(p2 - p1)
    cos_ = (r1**2 + dist**2 - r2**2) / (2.0 * r1 * dist)
    return xp.angle(p2 - p1) + sign * xp.arccos(cos_)  # arccos gives NaN for |cos_| > 1


def _closed_form(p: Mapping, alpha, signs, xp):
    """``closed_form_positions`` with the array module ``xp`` (``jnp``, or ``np`` on the host)."""
    alpha = xp.asarray(alpha, float)
    C = p["l"] - 1j * p["r"]
    B = C - (p["s"] - 1j * p["t"])
    A = p["a"] * xp.exp(1j * alpha)
    beta = _dyad(A, p["b"], C, p["c"], signs[0], xp)  # loop 1: G on circles about A and C
    G = A + p["b"] * xp.exp(1j * beta)
    delta = -xp.angle((G - C) / (1j * p["c"]))
    phi = _dyad(B, p["d"], G, p["p"], signs[1], xp)  # loop 2: D on circles about B and G
    D = B + p["d"] * xp.exp(1j * phi)
    psi = xp.angle(G - D)
    E = G + p["g"] * xp.exp(1j * psi)
    F = C + p["c1"] * xp.exp(-1j * delta)
    xi = _dyad(E, p["h"], F, p["z"], signs[2], xp)  # loop 3: H on circles about E and F
    H = E + p["h"] * xp.exp(1j * xi)
    theta = -xp.angle((H - F) / (1j * p["z"]))
    return xp.stack([beta, delta, phi, psi, xi, theta], axis=-1)


@functools.partial(jit, static_argnames="signs")  # one program, not ~15 eager operations
def closed_form_positions(p: Mapping, alpha, signs=BRANCH_SIGNS):
    """Positions ``q`` by three circle intersections (dyads), one per loop.

    ``signs`` picks each dyad's assembly; the default is the scene's branch.  NaN where a
    loop cannot close.  Used as the Newton guess (``SCENE.guess``) so that a changed
    design still starts on its own branch.

    **Returns** ``(..., 6)`` array ``(beta, delta, phi, psi, xi, theta)`` in rad (the batch
    shape of the parameters and ``alpha`` in front).
    """
    return _closed_form(p, alpha, signs, jnp)


def _validate(p):
    # numpy on the host: a check of one design need not compile a program (0.1 s)
    with np.errstate(invalid="ignore"):
        q = _closed_form({k: np.asarray(v, float) for k, v in p.items()}, ALPHA_START, BRANCH_SIGNS, np)
    if np.all(np.isfinite(q)):
        return
    C = p["l"] - 1j * p["r"]
    B = C - (p["s"] - 1j * p["t"])
    A = p["a"] * np.exp(1j * ALPHA_START)
    if not np.isfinite(q[0]):
        what = f"|A - C| = {abs(A - C):.6g} m must lie in [|b - c|, b + c] = [{abs(p['b'] - p['c']):.6g}, {p['b'] + p['c']:.6g}] m"
        loop, fix = 1, "a, b, c, l or r"
    elif not np.isfinite(q[2]):
        G = C + 1j * p["c"] * np.exp(-1j * q[1])
        what = f"|G - B| = {abs(G - B):.6g} m must lie in [|d - p|, d + p] = [{abs(p['d'] - p['p']):.6g}, {p['d'] + p['p']:.6g}] m"
        loop, fix = 2, "d, p, s or t"
    else:
        G = C + 1j * p["c"] * np.exp(-1j * q[1])
        E = G + p["g"] * np.exp(1j * q[3])
        F = C + p["c1"] * np.exp(-1j * q[1])
        what = f"|E - F| = {abs(E - F):.6g} m must lie in [|h - z|, h + z] = [{abs(p['h'] - p['z']):.6g}, {p['h'] + p['z']:.6g}] m"
        loop, fix = 3, "g, h, z or c1"
    raise ValueError(f"flap_msd: loop {loop} cannot close at alpha = 275 deg: {what}; change {fix}")


# --------------------------------------------------------------------------- loads and torque
def _qdyn(p):
    return 0.5 * p.rho * p.U**2  # dynamic pressure (Pa)


#: Flap bodies and loads (report §3.1).  Masses at the chord midpoints G1, G2; the flap
#: angles are clockwise, so the bodies' counter-clockwise angles are -delta and -theta.
#: Lift ``q S Cl angle`` at the quarter chords, normal to the chord (``+i e^{-i angle}``,
#: i.e. ``F1x = F1 sin(delta)``, ``F1y = F1 cos(delta)``).  The aerodynamic moments are
#: generalized forces on ``delta`` and ``theta``: power ``MAC1 delta_dot + MAC2 theta_dot``,
#: exactly as the report's Pi writes them.
MODEL = Model(
    mechanism,
    bodies=(
        Body("G1", mass="M", angle=lambda q, u, p: -q.delta, inertia="J_M", name="main flap"),
        Body("G2", mass="m", angle=lambda q, u, p: -q.theta, inertia="J_m", name="second flap"),
    ),
    loads=(
        Gravity(g="G"),
        PointForce("AC1", lambda q, u, p, v, t: _qdyn(p) * p.S1 * p.Cl_delta * q.delta * 1j * cis(-q.delta), name="lift F1"),
        PointForce("AC2", lambda q, u, p, v, t: _qdyn(p) * p.S2 * p.Cl_theta * q.theta * 1j * cis(-q.theta), name="lift F2"),
        Moment("delta", lambda q, u, p, v, t: _qdyn(p) * p.S1 * p.c1 * p.Cm_delta, name="MAC1"),
        Moment("theta", lambda q, u, p, v, t: _qdyn(p) * p.S2 * p.c2 * p.Cm_theta, name="MAC2"),
    ),
)

#: The DC motor on the crank (§3.2), steady current (``L_a di/dt`` neglected).
MOTOR = DCMotor(resistance="R_a", constant="K_m")


@jit
def _torque_batch(p, q, u, ud, udd, t, d1, d2):
    def one(q_, u_, ud_, udd_, t_, d1_, d2_):
        qd, qdd = chain_rule(d1_, d2_, ud_, udd_)  # this drive's rates from dq/du, d2q/du2
        return generalized_forces(MODEL, q_, u_, ud_, udd_, p, t_, q_dot=qd, q_ddot=qdd)[0][0]

    return jax.vmap(one)(q, u, ud, udd, t, d1, d2)


def torque(p: Mapping, motion: Motion):
    """Driving torque ``T_m`` at O (N m, counter-clockwise on the crank), ``(N,)``.

    Inverse dynamics by virtual power (``jaxmech.dynamics.generalized_forces`` on ``MODEL``):
    flap masses and inertias, gravity, lift and aerodynamic moments; the report's power
    balance ``T_m alpha_dot = dT/dt - Pi_loads`` without the division by ``alpha_dot``, so
    it holds for any drive law and at rest.  NaN where the position solve failed.
    """
    dt = motion.q.dtype
    pj = {k: jnp.asarray(v, dt) for k, v in p.items()}
    args = (pj, motion.q, motion.u, motion.u_dot, motion.u_ddot, jnp.asarray(motion.t, dt), motion.dq_du, motion.d2q_du2)
    return _torque_batch(*args)


def voltage(p: Mapping, motion: Motion, torque_values=None):
    """Steady DC-motor voltage ``v = R_a T_m / K_m + K_m alpha_dot`` (V), §3.2 (``L_a di/dt``
    neglected).  ``torque_values`` (N m) defaults to ``torque(p, motion)``."""
    tq = torque(p, motion) if torque_values is None else torque_values
    return MOTOR.steady_voltage(tq, motion.u_dot[:, 0], p)


def torque_document(p: Mapping, motion: Motion, *, corrected: bool = False):
    """The report's printed ``T_m`` (§3.1), evaluated on this motion (N m).

    Printed: ``... + F2 c1 sin(theta - delta) ...`` and ``theta_dd (m (c2^2/4)^2 + J_m)``.
    ``corrected=True`` uses ``cos(theta - delta)`` and ``m c2^2/4``; it then equals
    ``torque`` (the report's energy method, done right).  Inputs: ``delta' = d delta/d alpha``,
    ``theta'``, the actual ``delta_dd``, ``theta_dd`` and ``alpha_dot``.
    """
    q, qdd, d1, ud = motion.q, motion.q_ddot, motion.dq_du[..., 0], motion.u_dot[:, 0]
    de, th, dp, tp, dedd, thdd = q[:, 1], q[:, 5], d1[:, 1], d1[:, 5], qdd[:, 1], qdd[:, 5]
    M, m, c1, c2, G = p["M"], p["m"], p["c1"], p["c2"], p["G"]
    qdyn = 0.5 * p["rho"] * p["U"] ** 2
    F1, F2 = qdyn * p["S1"] * p["Cl_delta"] * de, qdyn * p["S2"] * p["Cl_theta"] * th
    mac1, mac2 = qdyn * p["S1"] * c1 * p["Cm_delta"], qdyn * p["S2"] * c2 * p["Cm_theta"]
    trig = jnp.cos(th - de) if corrected else jnp.sin(th - de)
    i2 = m * c2**2 / 4 if corrected else m * (c2**2 / 4) ** 2
    return (
        (dedd * (M * c1**2 / 4 + p["J_M"] + m * c1**2) - mac1 + F1 * c1 / 4 + F2 * c1 * trig
         - (M * G * c1 / 2 + m * G * c1) * jnp.cos(de)) * dp
        + (thdd * (i2 + p["J_m"]) - mac2 + F2 * c2 / 4 - m * G * c2 / 2 * jnp.cos(th)) * tp
        + 0.5 * m * c1 * c2 * ((thdd * dp + dedd * tp) * jnp.cos(th - de)
                               - dp * tp * jnp.sin(th - de) * (tp - dp) * ud**2)
    )


def _outputs(p, motion: Motion):
    tq = torque(p, motion)
    qdyn = 0.5 * p["rho"] * p["U"] ** 2
    return {
        "torque": tq,
        "voltage": voltage(p, motion, tq),
        "current": MOTOR.steady_current(tq, p),
        "torque_document": torque_document(p, motion),
        "lift_main": qdyn * p["S1"] * p["Cl_delta"] * motion.q[:, 1],
        "lift_second": qdyn * p["S2"] * p["Cl_theta"] * motion.q[:, 5],
    }


#: The scene's outputs: their units, in column order.
OUTPUT_UNITS = {"torque": "N m", "voltage": "V", "current": "A", "torque_document": "N m", "lift_main": "N",
                "lift_second": "N"}


# --------------------------------------------------------------------------- drawing
def _drawing(p):
    return {
        # crank, coupler, flap arm, bar BD, bar DGE (straight through G), link EH, flap arm FH
        "links": [("O", "A"), ("A", "G"), ("C", "G"), ("B", "D"), ("D", "G"), ("G", "E"), ("E", "H"), ("F", "H")],
        "ground": ["O", "C", "B"],
        # E rides in a rail in the prototype (§1), but the model does not constrain it: its
        # path is the trace of E.
        "slots": [],
        "chords": [("C", "F"), ("F", "L")],
        "trace": ["E", "L"],
    }


SCENE = Scene(
    name="flap_msd",
    summary="MSD double flap (PoliMi report): crank 275-320 deg at 1 rad/s, second flap turns 60.6 deg",
    mechanism=mechanism,
    defaults=DEFAULTS,
    parameters=PARAMETERS,
    guess=lambda p: closed_form_positions(p, ALPHA_START),
    stroke=lambda p: (ALPHA_START, ALPHA_END),
    speed=1.0,
    units={"alpha": "rad", **{n: "rad" for n in COORDS}},
    outputs=Outputs(_outputs, OUTPUT_UNITS),
    validate=_validate,
    drawing=_drawing,
    document="A. Carnevali, A. Fernandez, G. Landa, 'MSD Project: flap extraction and retraction system', Group 6 project report, Multibody System Dynamics (Prof. P. Masarati), Politecnico di Milano, A.Y. 2022/23; corrections in docs/seeds/flap_msd.md",
)
