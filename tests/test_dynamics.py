"""Inverse dynamics, reactions, statics and forward dynamics against independent truths:
hand Newton-Euler free-body equations (numpy), hand free-body statics, energy, scipy brentq."""

import jax

jax.config.update("jax_enable_x64", True)

import functools  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

from helpers import central_diff, fourbar_closed  # noqa: E402
from jaxmech import Mechanism, SmoothStart, cis  # noqa: E402
import jaxmech as jm  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402
from jaxmech.actuators import LinearSpring, SMAWire  # noqa: E402

RTOL_NE = 1e-9  # inverse dynamics vs Newton-Euler
RTOL_POWER = 1e-10  # power balance, relative to the stroke's peak power
TOL_EQ = 1e-10  # equilibrium angle vs brentq (rad)
RTOL_FD = 1e-7  # equilibrium derivatives vs finite differences


def cross(r, f):
    return np.imag(np.conj(r) * f)


# --------------------------------------------------------------------------- scenes
SC = Mechanism(
    name="slider_crank_masses",
    coords=("theta3", "x"),
    inputs=("theta2",),
    params=("a", "b", "e", "s", "m2", "J2", "m3", "J3", "m4", "g", "Fx", "Fy"),
    lengths=("a", "b", "e", "x"),
    signed=("e",),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - q.x - 1j * p.e],
    points={
        "G2": lambda q, u, p: 0.5 * p.a * cis(u.theta2),
        "G3": lambda q, u, p: p.a * cis(u.theta2) + 0.5 * p.b * cis(q.theta3),
        "P": lambda q, u, p: p.a * cis(u.theta2) + p.s * p.b * cis(q.theta3),
        "B": lambda q, u, p: q.x + 1j * p.e,
    },
)
SC_MODEL = D.Model(
    SC,
    bodies=[D.Body("G2", "m2", angle="theta2", inertia="J2"), D.Body("G3", "m3", angle="theta3", inertia="J3"), D.Body("B", "m4")],
    loads=[D.Gravity(), D.PointForce("P", lambda q, u, p, v, t: p.Fx + 1j * p.Fy)],
)
SC_P = dict(a=0.1, b=0.35, e=0.03, s=0.3, m2=1.0, J2=0.002, m3=2.0, J3=0.02, m4=1.5, g=9.81, Fx=-40.0, Fy=25.0)

FB = Mechanism(
    name="fourbar_masses",
    coords=("theta3", "theta4"),
    inputs=("theta2",),
    params=("a", "b", "c", "d", "m2", "J2", "m3", "J3", "m4", "J4", "g", "F0", "cd", "c2"),
    lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d],
    points={
        "G2": lambda q, u, p: 0.5 * p.a * cis(u.theta2),
        "G3": lambda q, u, p: p.a * cis(u.theta2) + 0.5 * p.b * cis(q.theta3),
        "P": lambda q, u, p: p.a * cis(u.theta2) + 0.7 * p.b * cis(q.theta3) + 0.2 * p.b * 1j * cis(q.theta3),
        "G4": lambda q, u, p: p.d + 0.5 * p.c * cis(q.theta4),
    },
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)
FB_MODEL = D.Model(
    FB,
    bodies=[
        D.Body("G2", "m2", angle="theta2", inertia="J2"),
        D.Body("G3", "m3", angle="theta3", inertia="J3"),
        D.Body("G4", "m4", angle="theta4", inertia="J4"),
    ],
    loads=[
        D.Gravity(),
        # a follower force normal to the coupler, growing with the coupler angle
        D.PointForce("P", lambda q, u, p, v, t: p.F0 * (1.0 + q.theta3) * 1j * cis(q.theta3)),
        # a viscous damper on the rocker (velocity dependent) and on the crank
        D.Moment("theta4", lambda q, u, p, v, t: -p.cd * v.theta4),
        D.Moment("theta2", lambda q, u, p, v, t: -p.c2 * v.theta2),
    ],
)
FB_P = dict(a=1.0, b=3.0, c=2.5, d=3.5, m2=1.0, J2=0.1, m3=2.0, J3=1.5, m4=1.5, J4=0.8, g=9.81, F0=7.0, cd=0.6, c2=0.0)
FB_GUESS = jnp.array([0.2, 1.2])


# --------------------------------------------------------------------------- hand kinematics (numpy)
def sc_kinematics(th2, w2, al2, P):
    a, b, e = P["a"], P["b"], P["e"]
    th3 = np.arcsin((e - a * np.sin(th2)) / b)
    w3 = -a * np.cos(th2) * w2 / (b * np.cos(th3))
    al3 = (b * np.sin(th3) * w3**2 + a * np.sin(th2) * w2**2 - a * np.cos(th2) * al2) / (b * np.cos(th3))
    return th3, w3, al3


def fb_kinematics(th2, w2, al2, P):
    a, b, c, d = P["a"], P["b"], P["c"], P["d"]
    th3, th4 = (float(x) for x in fourbar_closed(th2, a, b, c, d))
    E2, E3, E4 = np.exp(1j * th2), np.exp(1j * th3), np.exp(1j * th4)
    # velocity loop: i(a w2 E2 + b w3 E3 - c w4 E4) = 0, linear in (w3, w4)
    Mv = np.array([[np.real(1j * b * E3), np.real(-1j * c * E4)], [np.imag(1j * b * E3), np.imag(-1j * c * E4)]])
    rv = -1j * a * w2 * E2
    w3, w4 = np.linalg.solve(Mv, [rv.real, rv.imag])
    ra = -(a * (1j * al2 - w2**2) * E2 - b * w3**2 * E3 + c * w4**2 * E4)
    al3, al4 = np.linalg.solve(Mv, [ra.real, ra.imag])
    return th3, th4, w3, w4, al3, al4


def _rows(n, eqs):
    Amat = np.zeros((len(eqs), n))
    rhs = np.zeros(len(eqs))
    for k, (coef, r) in enumerate(eqs):
        for j, v in coef.items():
            Amat[k, j] = v
        rhs[k] = r
    return Amat, rhs


def sc_newton_euler(th2, w2, al2, P):
    """Free bodies crank (2), rod (3), slider (4, point mass on a frictionless guide).

    Unknowns: F12 (ground on crank) x,y; F23 (crank on rod) x,y; F34 (rod on slider) x,y;
    N (guide on slider, vertical); tau (on crank).  Returns (tau, F34)."""
    a, b, e, s = P["a"], P["b"], P["e"], P["s"]
    m2, J2, m3, J3, m4, g = P["m2"], P["J2"], P["m3"], P["J3"], P["m4"], P["g"]
    F = P["Fx"] + 1j * P["Fy"]
    th3, w3, al3 = sc_kinematics(th2, w2, al2, P)
    E2, E3 = np.exp(1j * th2), np.exp(1j * th3)
    A = a * E2
    aA = a * E2 * (1j * al2 - w2**2)
    G2, aG2 = A / 2, aA / 2
    G3, aG3 = A + b / 2 * E3, aA + b / 2 * E3 * (1j * al3 - w3**2)
    Bp, aB = A + b * E3, aA + b * E3 * (1j * al3 - w3**2)
    Pp = A + s * b * E3
    rO, rA2 = -G2, A - G2
    rA3, rB3, rP3 = A - G3, Bp - G3, Pp - G3
    eqs = [
        ({4: 1}, m4 * aB.real),  # slider x: F34x = m4 aBx
        ({5: 1, 6: 1}, m4 * aB.imag + m4 * g),  # slider y
        ({2: 1, 4: -1}, m3 * aG3.real - F.real),  # rod x
        ({3: 1, 5: -1}, m3 * aG3.imag + m3 * g - F.imag),  # rod y
        ({2: -rA3.imag, 3: rA3.real, 4: rB3.imag, 5: -rB3.real}, J3 * al3 - cross(rP3, F)),  # rod moment about G3
        ({0: 1, 2: -1}, m2 * aG2.real),  # crank x
        ({1: 1, 3: -1}, m2 * aG2.imag + m2 * g),  # crank y
        ({7: 1, 0: -rO.imag, 1: rO.real, 2: rA2.imag, 3: -rA2.real}, J2 * al2),  # crank moment about G2
    ]
    x = np.linalg.solve(*_rows(8, eqs))
    return x[7], x[4] + 1j * x[5]


def fb_newton_euler(th2, w2, al2, P):
    """Free bodies crank, coupler, rocker.  Unknowns F12, F23, F34 (coupler on rocker), F14,
    tau.  Returns (tau, F34)."""
    a, b, c, d = P["a"], P["b"], P["c"], P["d"]
    m2, J2, m3, J3, m4, J4, g = (P[k] for k in ("m2", "J2", "m3", "J3", "m4", "J4", "g"))
    th3, th4, w3, w4, al3, al4 = fb_kinematics(th2, w2, al2, P)
    E2, E3, E4 = np.exp(1j * th2), np.exp(1j * th3), np.exp(1j * th4)
    A = a * E2
    aA = a * E2 * (1j * al2 - w2**2)
    B = d + c * E4
    G2, aG2 = A / 2, aA / 2
    G3, aG3 = A + b / 2 * E3, aA + b / 2 * E3 * (1j * al3 - w3**2)
    G4, aG4 = d + c / 2 * E4, c / 2 * E4 * (1j * al4 - w4**2)
    Pp = A + 0.7 * b * E3 + 0.2 * b * 1j * E3
    F = P["F0"] * (1 + th3) * 1j * E3
    M4 = -P["cd"] * w4 - 0.0
    M2 = -P["c2"] * w2
    lin = lambda r: (-r.imag, r.real)  # noqa: E731  cross(r, F) = -r_y Fx + r_x Fy
    eqs = []
    # crank: F12 - F23 + m2 g = m2 aG2; tau + (O-G2) x F12 + (A-G2) x (-F23) + M2 = J2 al2
    eqs += [({0: 1, 2: -1}, m2 * aG2.real), ({1: 1, 3: -1}, m2 * aG2.imag + m2 * g)]
    r1, r2 = lin(-G2), lin(A - G2)
    eqs += [({8: 1, 0: r1[0], 1: r1[1], 2: -r2[0], 3: -r2[1]}, J2 * al2 - M2)]
    # coupler: F23 - F34 + F + m3 g = m3 aG3; (A-G3) x F23 + (B-G3) x (-F34) + (P-G3) x F = J3 al3
    eqs += [({2: 1, 4: -1}, m3 * aG3.real - F.real), ({3: 1, 5: -1}, m3 * aG3.imag + m3 * g - F.imag)]
    r1, r2 = lin(A - G3), lin(B - G3)
    eqs += [({2: r1[0], 3: r1[1], 4: -r2[0], 5: -r2[1]}, J3 * al3 - cross(Pp - G3, F))]
    # rocker: F34 + F14 + m4 g = m4 aG4; (B-G4) x F34 + (O4-G4) x F14 + M4 = J4 al4
    eqs += [({4: 1, 6: 1}, m4 * aG4.real), ({5: 1, 7: 1}, m4 * aG4.imag + m4 * g)]
    r1, r2 = lin(B - G4), lin(d - G4)
    eqs += [({4: r1[0], 5: r1[1], 6: r2[0], 7: r2[1]}, J4 * al4 - M4)]
    x = np.linalg.solve(*_rows(9, eqs))
    return x[8], x[4] + 1j * x[5]


STATES = np.array([[0.3, 2.0, 1.5], [1.7, -3.0, 0.4], [2.9, 1.2, -2.0], [4.4, 0.5, 6.0], [5.8, -2.2, -1.0]])


# --------------------------------------------------------------------------- inverse dynamics
def test_slider_crank_torque_matches_newton_euler():
    g = jnp.array([0.1, 0.44])
    r = D.inverse_dynamics_at(SC_MODEL, STATES[:, 0], STATES[:, 1], STATES[:, 2], SC_P, g)
    assert np.all(np.asarray(r.status) == 0)
    for k, (th2, w2, al2) in enumerate(STATES):
        tau, F34 = sc_newton_euler(th2, w2, al2, SC_P)
        scale = max(abs(tau), abs(F34))
        assert abs(float(r.tau[k, 0]) - tau) <= RTOL_NE * scale
        # loop a e^{i t2} + b e^{i t3} - (x + i e): lambda is the force of the rod on the slider
        assert abs(complex(r.reaction(0)[k]) - F34) <= RTOL_NE * scale


FB_DRIVE = SmoothStart(u0=jnp.asarray(0.1), w=jnp.asarray(2.0), k=jnp.asarray(3.0))
FB_T = jnp.linspace(0.0, 3.0, 61)
FB_PD = {**FB_P, "c2": 0.3}


@functools.lru_cache(maxsize=None)
def _fb_stroke():
    """Inverse dynamics along a smooth-start stroke (one compiled call shared by two tests)."""
    return D.inverse_dynamics(FB_MODEL, FB_DRIVE, FB_T, FB_PD, FB_GUESS)


def test_fourbar_torque_matches_newton_euler():
    r = _fb_stroke()
    assert np.all(np.asarray(r.status) == 0)
    for k in range(0, len(FB_T), 4):
        th2, w2, al2 = (float(x[k, 0]) for x in (r.u, r.u_dot, r.u_ddot))
        tau, F34 = fb_newton_euler(th2, w2, al2, FB_PD)
        scale = max(abs(tau), abs(F34))
        assert abs(float(r.tau[k, 0]) - tau) <= RTOL_NE * scale
        # loop a e^{i t2} + b e^{i t3} - (d + c e^{i t4}): lambda = coupler's force on the rocker
        assert abs(complex(r.reaction(0)[k]) - F34) <= RTOL_NE * scale


def test_power_balance_along_stroke():
    """tau u_dot = dT/dt - Pi along the stroke, with dT/dt and Pi from the hand kinematics
    (numpy loop velocity and acceleration equations) and the drive law's own derivatives."""
    P = FB_PD
    r = _fb_stroke()
    a, b, c, d, g = P["a"], P["b"], P["c"], P["d"], P["g"]
    m = np.array([P["m2"], P["m3"], P["m4"]])
    J = np.array([P["J2"], P["J3"], P["J4"]])
    lhs, rhs = [], []
    for t in np.asarray(FB_T):
        e = np.exp(-3.0 * t)  # SmoothStart(u0=0.1, w=2, k=3) by hand
        th2, w2, al2 = 0.1 + 2.0 * (t + (e - 1.0) / 3.0), 2.0 * (1.0 - e), 6.0 * e
        th3, th4, w3, w4, al3, al4 = fb_kinematics(th2, w2, al2, P)
        E2, E3, E4 = np.exp(1j * th2), np.exp(1j * th3), np.exp(1j * th4)
        vA, aA = 1j * w2 * a * E2, a * E2 * (1j * al2 - w2**2)
        v = np.array([vA / 2, vA + b / 2 * 1j * w3 * E3, c / 2 * 1j * w4 * E4])
        acc = np.array([aA / 2, aA + b / 2 * E3 * (1j * al3 - w3**2), c / 2 * E4 * (1j * al4 - w4**2)])
        w, al = np.array([w2, w3, w4]), np.array([al2, al3, al4])
        dT = np.sum(m * np.real(np.conj(v) * acc)) + np.sum(J * w * al)
        vP = vA + (0.7 + 0.2j) * b * 1j * w3 * E3
        F = P["F0"] * (1 + th3) * 1j * E3
        Pi = np.sum(m * np.real(np.conj(-1j * g) * v)) + np.real(np.conj(F) * vP) - P["cd"] * w4**2 - P["c2"] * w2**2
        lhs.append(w2)
        rhs.append(dT - Pi)
    lhs = np.asarray(r.tau[:, 0]) * np.asarray(lhs)
    err = np.abs(lhs - np.asarray(rhs))
    assert np.max(err) <= RTOL_POWER * np.max(np.abs(lhs)), f"worst at sample {np.argmax(err)}: {err}"


def test_three_force_member_reactions():
    """Quasi-static slider-crank (inertia left out although the links have mass), no gravity,
    one force on the rod: the rod carries three forces (pin A, guide normal at B, the load at
    P), solved by hand as a free body."""
    P = {**SC_P, "g": 0.0}
    th2 = np.array([0.4, 2.0, 3.6, 5.1, 6.0])
    r = D.inverse_dynamics_at(SC_MODEL, th2, 1.5, -4.0, P, jnp.array([0.1, 0.44]), quasi_static=True)
    F = P["Fx"] + 1j * P["Fy"]
    for k, t2 in enumerate(th2):
        th3, _, _ = sc_kinematics(t2, 0.0, 0.0, P)
        A = P["a"] * np.exp(1j * t2)
        B = A + P["b"] * np.exp(1j * th3)
        Pp = A + P["s"] * P["b"] * np.exp(1j * th3)
        N = -cross(Pp - A, F) / (B - A).real  # guide on rod (vertical): moments about A
        FA = -F - 1j * N  # crank on rod: force balance
        tau = cross(A, FA)  # crank: tau + A x (-FA) = 0
        scale = max(abs(F), abs(tau))
        assert abs(float(r.tau[k, 0]) - tau) <= RTOL_NE * scale
        assert abs(complex(r.reaction(0)[k]) - (-1j * N)) <= RTOL_NE * scale


def test_failed_position_gives_nan_and_status():
    u = jnp.array([0.3, jnp.nan, 1.0, 2.0, 3.0])
    r = D.inverse_dynamics_at(SC_MODEL, u, 1.0, 0.0, SC_P, jnp.array([0.1, 0.44]))
    assert int(r.status[0]) == 0 and int(r.status[1]) != 0
    assert np.isfinite(r.tau[0, 0]) and np.isnan(r.tau[1, 0]) and np.all(np.isnan(r.reactions[1]))


def test_model_checks_names():
    with pytest.raises(ValueError, match="unknown point 'Q'"):
        D.Model(SC, bodies=[D.Body("Q", "m2")])
    with pytest.raises(ValueError, match="unknown parameter 'mass'"):
        D.Model(SC, bodies=[D.Body("G2", "mass")])
    with pytest.raises(ValueError, match="inertia needs an angle"):
        D.Model(SC, bodies=[D.Body("G2", "m2", inertia="J2")])


# --------------------------------------------------------------------------- statics: SMA flap
# One hinged flap (hinge J at the origin of its own frame): an SMA wire pulls a horn above the
# hinge, a bias spring a horn below it, gravity on the flap.  The dependent coordinate is the
# wire length s (a real equation |A - F| - s = 0, unit gradient in s).
def _flap_mechanism():
    """The flap with its horn points (complex constants) written into the equations."""
    Fw, Aw = 0.06 + 0.010j, 0.22 + 0.010j
    Fs, As = 0.14 - 0.010j, 0.22 - 0.010j
    cg = 0.29 + 0.0j
    rot = lambda u, z, p: p.Jx + cis(u.theta) * (z - p.Jx)  # noqa: E731
    mech = Mechanism(
        name="sma_flap",
        coords=("s",),
        inputs=("theta",),
        params=("Jx", "m", "g", "area", "E_M", "E_A", "xi", "eps", "k", "Fpre", "L0w", "L0s"),
        lengths=("Jx", "s", "L0w", "L0s"),
        constraints=lambda q, u, p: [jnp.abs(rot(u, Aw, p) - Fw) - q.s],
        points={"Fw": lambda q, u, p: Fw + 0 * p.Jx, "Aw": lambda q, u, p: rot(u, Aw, p),
                "Fs": lambda q, u, p: Fs + 0 * p.Jx, "As": lambda q, u, p: rot(u, As, p),
                "G": lambda q, u, p: rot(u, cg, p)},
    )
    consts = dict(Fw=Fw, Aw=Aw, Fs=Fs, As=As, cg=cg)
    return mech, consts


FLAP_MECH, FLAP_C = _flap_mechanism()
WIRE = SMAWire(area="area", length0="L0w", E_M="E_M", E_A="E_A", prestrain="eps", fraction="xi")
BIAS = LinearSpring(stiffness="k", length0="L0s", preload="Fpre")
FLAP_MODEL = D.Model(
    FLAP_MECH,
    bodies=[D.Body("G", "m", angle="theta")],
    loads=[D.Gravity(), D.Axial("Aw", "Fw", WIRE, name="sma"), D.Axial("As", "Fs", BIAS, name="bias")],
)
FLAP_PARAMS = dict(Jx=0.22, m=0.10, g=9.81, area=np.pi * 0.381e-3**2 / 4, E_M=28e9, E_A=75e9, xi=1.0, eps=-0.01,
                   k=1000.0, Fpre=5.0, L0w=abs(FLAP_C["Aw"] - FLAP_C["Fw"]), L0s=abs(FLAP_C["As"] - FLAP_C["Fs"]))


def flap_residual_np(th, P):
    """dV/dtheta by hand: sum T dL/dtheta + m g d(y_G)/dtheta (numpy)."""
    J = P["Jx"]
    rot = lambda z: J + np.exp(1j * th) * (z - J)  # noqa: E731
    drot = lambda z: 1j * np.exp(1j * th) * (z - J)  # noqa: E731
    R = 0.0
    E = P["xi"] * P["E_M"] + (1 - P["xi"]) * P["E_A"]
    for A, F, kind in ((FLAP_C["Aw"], FLAP_C["Fw"], "w"), (FLAP_C["As"], FLAP_C["Fs"], "s")):
        r = rot(A) - F
        L = abs(r)
        dL = np.real(np.conj(r / L) * drot(A))
        if kind == "w":
            T = max(E * P["area"] * (L / (P["L0w"] * (1 + P["eps"])) - 1), 0.0)
        else:
            T = P["Fpre"] + P["k"] * (L - P["L0s"])
        R += T * dL
    return R + P["m"] * P["g"] * np.imag(drot(FLAP_C["cg"]))


LIM = np.deg2rad(60.0)


def _brentq_equilibrium(P):
    return brentq(lambda th: flap_residual_np(th, P), -LIM, LIM, xtol=1e-15, rtol=1e-15, maxiter=200)


FLAP_GUESS = jnp.array([FLAP_PARAMS["L0w"]])
# A batch of designs in one compiled call: (prestrain, martensite fraction); the last wire is
# so short that the flap has no equilibrium in the range.
FLAP_CASES = [(-0.01, 1.0), (-0.03, 0.3), (0.0, 0.0), (-0.005, 1.0), (-0.35, 1.0)]


@functools.lru_cache(maxsize=None)
def _flap_batch():
    eps, xi = (jnp.array(c) for c in zip(*FLAP_CASES))
    return D.equilibrium(FLAP_MODEL, {**FLAP_PARAMS, "eps": eps, "xi": xi}, (-LIM, LIM), FLAP_GUESS)


@pytest.mark.parametrize("case", range(len(FLAP_CASES) - 1))
def test_equilibrium_matches_brentq(case):
    eps, xi = FLAP_CASES[case]
    sol = _flap_batch()
    assert int(sol.status[case]) == jm.Status.CONVERGED
    assert abs(float(sol.u[case, 0]) - _brentq_equilibrium({**FLAP_PARAMS, "eps": eps, "xi": xi})) <= TOL_EQ
    assert bool(sol.stable[case])


def test_no_equilibrium_in_range_is_reported():
    sol = _flap_batch()
    assert int(sol.status[-1]) == jm.Status.NO_EQUILIBRIUM
    assert np.isnan(sol.u[-1, 0]) and np.isnan(sol.q[-1, 0])
    assert "no equilibrium" in jm.status_message(sol.status[-1])


def _flap_theta(P):
    return D.equilibrium(FLAP_MODEL, P, (-LIM, LIM), FLAP_GUESS).u[0]


@functools.lru_cache(maxsize=None)
def _flap_derivatives():
    P = {k: jnp.asarray(v) for k, v in FLAP_PARAMS.items()}
    return jax.jacfwd(_flap_theta)(P), jax.grad(_flap_theta)(P)


@pytest.mark.parametrize("name", ["eps", "k", "m", "Fpre", "E_M", "Jx", "xi"])
def test_equilibrium_derivatives_match_finite_differences(name):
    fwd, rev = (float(d[name]) for d in _flap_derivatives())
    x0 = FLAP_PARAMS[name]
    h = 1e-3 * abs(x0)
    # finite differences of the brentq truth: independent of the implicit rule
    fd = central_diff(lambda x: _brentq_equilibrium({**FLAP_PARAMS, name: x}), x0, h)
    assert abs(fwd - fd) <= RTOL_FD * abs(fd)
    assert abs(rev - fd) <= RTOL_FD * abs(fd)


# --------------------------------------------------------------------------- forward dynamics
FB_FREE = {**FB_P, "F0": 0.0, "cd": 0.0, "c2": 0.0}  # conservative: gravity only


def _energy(model, tr, P):
    T = jax.vmap(lambda q, u, ud: D.kinetic_energy(model, q, u, ud, P))(tr.q, tr.u, tr.u_dot)
    V = jax.vmap(lambda q, u: D.potential_energy(model, q, u, P))(tr.q, tr.u)
    return np.asarray(T + V)


def test_energy_is_conserved_without_loads():
    # no applied loads but gravity (a potential): T + V is conserved; about one crank turn
    tr = D.forward_dynamics(FB_MODEL, FB_FREE, 0.0, 6.0, FB_GUESS, h=0.005, steps=300)
    assert int(tr.status) == jm.Status.CONVERGED
    assert float(tr.u[-1, 0]) > 2 * np.pi
    E = _energy(FB_MODEL, tr, FB_FREE)
    assert np.max(np.abs(E / E[0] - 1.0)) < 1e-8


def test_inverse_dynamics_torque_reproduces_motion():
    drive = SmoothStart(u0=0.3, w=2.0, k=4.0)
    P = {**FB_P, "c2": 0.0}

    def torque(q, u, p, v, t):
        # the prescribed motion's inverse-dynamics torque, at the drive's own state
        uu, uud, uudd = (jnp.reshape(x, (1,)) for x in _drive_derivs(drive, t))
        p = dict(p)
        qd = D.close_loop(FB, uu, p, jnp.stack([q[n] for n in FB.coords]), 8)[0]
        return D.generalized_forces(FB_MODEL, qd, uu, uud, uudd, p, t)[0]

    tr = D.forward_dynamics(FB_MODEL, P, 0.3, 0.0, FB_GUESS, h=0.005, steps=300, load=torque)
    assert int(tr.status) == jm.Status.CONVERGED
    want = jax.vmap(drive)(tr.t)
    assert np.max(np.abs(np.asarray(tr.u[:, 0] - want))) < 1e-6


def _drive_derivs(drive, t):
    from jaxmech import time_derivatives

    return time_derivatives(drive, t)


def test_stroke_end_and_singular_position_stop_with_status():
    tr = D.forward_dynamics(FB_MODEL, FB_FREE, 0.0, 6.0, FB_GUESS, h=0.005, steps=300, stroke=(-1.0, 2.0))
    assert int(tr.status) == jm.Status.STROKE_END
    last = int(np.sum(np.isfinite(np.asarray(tr.u[:, 0])))) - 1
    assert float(tr.u[last, 0]) > 2.0 and float(tr.u[last - 1, 0]) <= 2.0
    assert np.all(np.isnan(np.asarray(tr.u[last + 1:, 0])))
    assert abs(float(tr.t_stop) - float(tr.t[last])) < 1e-12
    # a triple rocker (non-Grashof, a = 2.4): the crank cannot turn past the toggle where
    # the coupler and rocker align, |A - O4| = b + c, cos(theta2) = (a^2 + d^2 - (b + c)^2) / (2 a d);
    # a fast crank (no gravity) runs into it.
    Pt = {**FB_FREE, "a": 2.4, "g": 0.0}
    lim = np.arccos((2.4**2 + 3.5**2 - 5.5**2) / (2 * 2.4 * 3.5))
    g = jnp.array(fourbar_closed(0.0, 2.4, 3.0, 2.5, 3.5))
    tr = D.forward_dynamics(FB_MODEL, Pt, 0.0, 6.0, g, h=0.005, steps=300)
    assert int(tr.status) == jm.Status.POSITION
    ok = np.isfinite(np.asarray(tr.u[:, 0]))
    n = int(np.sum(ok))
    assert np.all(ok[:n]) and not np.any(ok[n:]) and n < 301
    assert np.all(np.asarray(tr.u[ok, 0]) < lim) and float(tr.u[n - 1, 0]) > lim - 0.05
