"""Springs and dampers as elements of a ``jm.Linkage`` against independent models written
here in numpy (no jaxmech code):

- a four-bar held by two torsion springs and gravity: its potential energy and its
  derivative in the crank angle written out (closed-form positions, velocity ratios from the
  loop's 2x2 system), the equilibrium angle found by ``scipy.optimize.brentq``;
- an offset slider-crank with a linear spring and a damper, driven back and forth: the
  crank torque and every joint's force from the per-body Newton-Euler equations (closed-form
  kinematics and their derivatives by hand);
- the same slider-crank with every kind of element, a force and a moment: each term of the
  power balance (kinetic, potential, dissipated, delivered) from the same kinematics;
- the derivative of the peak crank torque in a spring's stiffness and in a gas spring's
  polytropic index against central differences.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from helpers import central_diff  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

import jaxmech as jm  # noqa: E402

TOL = 1e-10  # relative to the largest value of the quantity over the stroke


def cross(r, f):
    """z of r x f for planar vectors as complex numbers."""
    return (np.conj(r) * f).imag


def dot(a, b):
    return np.real(np.conj(a) * b)


# --------------------------------------------------------------------------- four-bar
# O2 = 0, O4 = d on the x axis; crank a, coupler b, rocker c; uniform bars (centres at the
# midpoints); drawn at theta2 = 60 deg on the open branch.
FA, FB, FC, FD = 0.3, 0.9, 0.6, 0.8
FM = {"crank": 1.0, "coupler": 2.0, "rocker": 1.5}
G = 9.81
K_ROCKER, FREE_ROCKER = 40.0, np.radians(20.0)  # ground-rocker spring at O4
K_KNEE, FREE_KNEE = 15.0, np.radians(-10.0)  # crank-coupler spring at A
TH2_DRAWN = np.radians(60.0)


def fourbar_pose(t2):
    """``(theta3, theta4)`` (rad) of the open four-bar at crank angle `t2`."""
    a = FA * np.exp(1j * t2)
    diag = FD - a
    beta = np.arccos((FB**2 + abs(diag) ** 2 - FC**2) / (2 * FB * abs(diag)))
    t3 = np.angle(diag) + beta
    return t3, np.angle(a + FB * np.exp(1j * t3) - FD)


def fourbar_ratios(t2, t3, t4):
    """``(dtheta3/dtheta2, dtheta4/dtheta2)`` from the derivative of the loop
    ``a e^{i t2} + b e^{i t3} - c e^{i t4} - d = 0``."""
    m = np.array([[-FB * np.sin(t3), FC * np.sin(t4)], [FB * np.cos(t3), -FC * np.cos(t4)]])
    return np.linalg.solve(m, [FA * np.sin(t2), -FA * np.cos(t2)])


T3_DRAWN, T4_DRAWN = fourbar_pose(TH2_DRAWN)


def fourbar_energy(t2):
    """Potential energy (J): gravity on the three bars and the two torsion springs, each free
    at its free angle from the drawing's relative angle."""
    t3, t4 = fourbar_pose(t2)
    y = {"crank": FA / 2 * np.sin(t2), "coupler": FA * np.sin(t2) + FB / 2 * np.sin(t3), "rocker": FC / 2 * np.sin(t4)}
    rocker = t4 - T4_DRAWN - FREE_ROCKER
    knee = (t3 - t2) - (T3_DRAWN - TH2_DRAWN) - FREE_KNEE
    return G * sum(FM[k] * y[k] for k in FM) + 0.5 * K_ROCKER * rocker**2 + 0.5 * K_KNEE * knee**2


def fourbar_denergy(t2):
    """dV/dtheta2 (N m): the holding torque on the crank, by the chain rule through the
    velocity ratios."""
    t3, t4 = fourbar_pose(t2)
    d3, d4 = fourbar_ratios(t2, t3, t4)
    dy = {"crank": FA / 2 * np.cos(t2), "coupler": FA * np.cos(t2) + FB / 2 * np.cos(t3) * d3, "rocker": FC / 2 * np.cos(t4) * d4}
    rocker = t4 - T4_DRAWN - FREE_ROCKER
    knee = (t3 - t2) - (T3_DRAWN - TH2_DRAWN) - FREE_KNEE
    return G * sum(FM[k] * dy[k] for k in FM) + K_ROCKER * rocker * d4 + K_KNEE * knee * (d3 - 1.0)


def fourbar():
    a = FA * np.exp(1j * TH2_DRAWN)
    b = a + FB * np.exp(1j * T3_DRAWN)
    return jm.Linkage(points={"O2": (0, 0), "A": (a.real, a.imag), "B": (b.real, b.imag), "O4": (FD, 0)},
                      links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B"}, ground="O2 O4", driver="crank",
                      mass=FM, gravity=G,
                      torsion_springs={"rocker_spring": {"at": "O4", "k": K_ROCKER, "free_angle": "20deg"},
                                       "knee": {"links": ["crank", "coupler"], "k": "15 N m/rad", "free_angle": "-10deg"}})


def test_fourbar_torsion_spring_equilibrium_against_brentq():
    lk = fourbar()
    lo, hi = np.radians(50.0), np.radians(110.0)
    truth = brentq(fourbar_denergy, lo, hi, xtol=1e-15, rtol=1e-15)
    # it is a minimum of the energy written out (not only a root of its derivative)
    h = 1e-4
    assert fourbar_energy(truth - h) > fourbar_energy(truth) < fourbar_energy(truth + h)
    eq = jm.equilibrium(lk.model, lk.params, (lo, hi), lk.guess)
    assert int(eq.status[()]) == jm.Status.CONVERGED and bool(eq.stable)
    assert abs(float(eq.u[0]) - truth) <= 1e-10
    # statics: the holding torque is dV/dtheta2 along the range, zero at the equilibrium
    us = np.radians(np.linspace(30.0, 130.0, 11))
    held = lk.statics(us)
    want = np.array([fourbar_denergy(u) for u in us])
    np.testing.assert_allclose(np.asarray(held.tau[:, 0]), want, rtol=0, atol=TOL * np.max(np.abs(want)))
    assert abs(float(lk.statics([truth]).tau[0, 0])) <= TOL * np.max(np.abs(want))
    # the springs matter: without them the equilibrium is elsewhere (the test can fail)
    soft = lk.statics(us, p={"kt_rocker_spring": 0.0, "kt_knee": 0.0})
    assert np.max(np.abs(np.asarray(soft.tau[:, 0]) - want)) > 1.0


# --------------------------------------------------------------------------- slider-crank
# Crank O-A (r), rod A-B (l), block at B on the line y = e; uniform bars, the block a point
# mass at B.  A spring from the frame point S to the block, a damper from D to the crank pin.
R, L, E = 0.12, 0.40, 0.03
SM = {"crank": 1.2, "rod": 2.5, "block_B": 0.8}
S, D, S2 = 0.30 + 0.25j, -0.10 + 0.20j, 0.55 - 0.05j
K, L0, F0, C = 1500.0, 0.20, 40.0, 25.0
GAS_F, GAS_LG, GAS_N = 120.0, 0.25, 1.3
KT, FREE_T, CT = 4.0, np.radians(10.0), 0.8
LOAD, MOMENT = -300.0 + 50.0j, 6.0
TH0 = 1.0
T = np.linspace(0.0, np.pi, 41)


def drive(t):
    """The crank's angle, speed and acceleration: back and forth, reversing at t = pi/4, 3pi/4."""
    return TH0 + 1.2 * np.sin(2 * t), 2.4 * np.cos(2 * t), -4.8 * np.sin(2 * t)


def slider_kinematics(th):
    """Positions and their first and second derivatives in the crank angle: ``A``, ``B``
    (complex) and the rod's angle ``phi``, each as ``(x, dx, ddx)``."""
    s, s1, s2 = R * np.sin(th) - E, R * np.cos(th), -R * np.sin(th)
    w = np.sqrt(L * L - s * s)
    w1 = -s * s1 / w
    w2 = -(s1 * s1 + s * s2) / w - (s * s1) ** 2 / w**3
    a = (R * np.exp(1j * th), 1j * R * np.exp(1j * th), -R * np.exp(1j * th))
    b = (R * np.cos(th) + w + 1j * E, -R * np.sin(th) + w1 + 0j, -R * np.cos(th) + w2 + 0j)
    phi = (np.arctan2(-s, w), -s1 / w, -(s2 * w - s1 * w1) / w**2)
    return a, b, phi


def motion_at(t):
    """Everything at time `t`: the crank's rates, positions, velocities and accelerations of
    the pins and centres of mass, and the rod's angle and rates."""
    th, om, al = drive(t)
    a, b, phi = slider_kinematics(th)
    vel = lambda x: x[1] * om  # noqa: E731
    acc = lambda x: x[2] * om**2 + x[1] * al  # noqa: E731
    mid = tuple(0.5 * (p + q) for p, q in zip(a, b))
    half = tuple(0.5 * p for p in a)
    return dict(th=th, om=om, al=al, A=a[0], B=b[0], vA=vel(a), vB=vel(b), G={"crank": half[0], "rod": mid[0], "block_B": b[0]},
                vG={"crank": vel(half), "rod": vel(mid), "block_B": vel(b)}, aG={"crank": acc(half), "rod": acc(mid), "block_B": acc(b)},
                phi=phi[0], w3=phi[1] * om, al3=phi[2] * om**2 + phi[1] * al)


def inertias():
    return {"crank": SM["crank"] * R * R / 12, "rod": SM["rod"] * L * L / 12, "block_B": 0.0}


def axial(x, vx, anchor):
    """``(L, dL/dt, unit vector anchor -> x)`` of an element from a frame point to a moving one."""
    length = abs(x - anchor)
    e = (x - anchor) / length
    return length, dot(e, vx), e


def newton_euler(t):
    """Crank torque and joint forces of the slider-crank with the spring and the damper: the
    square per-body system (crank, rod, block) in the unknowns ``F_O, F_A, F_B`` (each on the
    second body: crank, rod, block), the guide's normal force ``N`` (along +y), its moment
    and the torque."""
    mo = motion_at(t)
    A, B, G_, aG = mo["A"], mo["B"], mo["G"], mo["aG"]
    J = inertias()
    gv = -1j * G
    ls, _, es = axial(B, mo["vB"], S)
    f_spring = -(F0 + K * (ls - L0)) * es  # on the block: the tension pulls B towards S
    _, ld_dot, ed = axial(A, mo["vA"], D)
    f_damper = -C * ld_dot * ed  # on the crank
    m, rhs = np.zeros((9, 9)), np.zeros(9)

    def pin(row, col, sign, at, centre):
        m[row, col] += sign
        m[row + 1, col + 1] += sign
        r = at - centre
        m[row + 2, col] += -sign * r.imag
        m[row + 2, col + 1] += sign * r.real

    pin(0, 0, 1, 0j, G_["crank"])
    pin(0, 2, -1, A, G_["crank"])
    m[2, 8] = 1.0  # the drive's torque on the crank
    applied = SM["crank"] * gv + f_damper
    rhs[0:3] = [SM["crank"] * aG["crank"].real - applied.real, SM["crank"] * aG["crank"].imag - applied.imag,
                J["crank"] * mo["al"] - cross(A - G_["crank"], f_damper)]
    pin(3, 2, 1, A, G_["rod"])
    pin(3, 4, -1, B, G_["rod"])
    rhs[3:6] = [SM["rod"] * (aG["rod"] - gv).real, SM["rod"] * (aG["rod"] - gv).imag, J["rod"] * mo["al3"]]
    pin(6, 4, 1, B, G_["block_B"])
    m[7, 6] += 1.0  # the guide's normal force, along +y
    m[8, 7] = 1.0  # the guide's moment on the block (no arm: every force acts at B = G)
    applied = SM["block_B"] * gv + f_spring
    rhs[6:9] = [SM["block_B"] * aG["block_B"].real - applied.real, SM["block_B"] * aG["block_B"].imag - applied.imag, 0.0]
    x = np.linalg.solve(m, rhs)
    return {"tau": x[8], "O": x[0] + 1j * x[1], "A": x[2] + 1j * x[3], "B": x[4] + 1j * x[5], "N": x[6]}


def slider_crank(every: bool = False, **kw):
    """The slider-crank as a ``jm.Linkage`` (drawn at the crank angle TH0), with the spring
    and the damper; `every`: with a gas spring, a torsion spring, a rotary damper, a force
    on the block and a moment on the rod too."""
    a, b, _ = slider_kinematics(TH0)
    pts = {"O": (0, 0), "A": (a[0].real, a[0].imag), "B": (b[0].real, b[0].imag), "S": (S.real, S.imag),
           "D": (D.real, D.imag), "S2": (S2.real, S2.imag)}
    args = dict(springs={"s1": {"between": ["S", "B"], "on": ["ground", "block_B"], "k": K, "free_length": L0, "preload": F0}},
                dampers={"d1": {"between": "D A", "on": "ground crank", "c": C}})
    if every:
        args.update(gas_springs={"g1": {"between": ["S2", "B"], "on": ["ground", "block_B"], "force": GAS_F, "gas_length": GAS_LG,
                                        "n": GAS_N}},
                    torsion_springs={"t1": {"at": "A", "k": KT, "free_angle": FREE_T}},
                    rotary_dampers={"r1": {"at": "B", "c": CT}},
                    forces={"B": {"force": (LOAD.real, LOAD.imag), "on": "block_B"}}, moments={"rod": MOMENT})
    args.update(kw)
    return jm.Linkage(points=pts, links={"crank": "O A", "rod": "A B"}, ground="O S D S2", driver="crank",
                      sliders={"B": {"angle": 0.0}}, mass=SM, gravity=G, **args)


def samples():
    return jm.Samples(*drive(T), T)


def test_slider_crank_spring_and_damper_effort_and_reactions_against_newton_euler():
    lk = slider_crank()
    res = lk.inverse_dynamics(samples())
    assert np.all(np.asarray(res.status) == jm.Status.CONVERGED)
    ne = [newton_euler(t) for t in T]
    tau = np.array([x["tau"] for x in ne])
    np.testing.assert_allclose(np.asarray(res.tau[:, 0]), tau, rtol=0, atol=TOL * np.max(np.abs(tau)))
    for joint, link in (("O", "crank"), ("A", "rod"), ("B", "block_B")):
        want = np.array([x[joint] for x in ne])
        np.testing.assert_allclose(np.asarray(res.force_on(link, joint)), want, rtol=0, atol=TOL * np.max(np.abs(want)))
    normal = np.array([x["N"] for x in ne])
    np.testing.assert_allclose(np.asarray(res.normal_force("block_B on ground")), normal, rtol=0, atol=TOL * np.max(np.abs(normal)))
    # the elements carry real forces: without them the torque differs (the test can fail)
    bare = lk.inverse_dynamics(samples(), p={"k_s1": 0.0, "F0_s1": 0.0, "c_d1": 0.0})
    assert np.max(np.abs(np.asarray(bare.tau[:, 0]) - tau)) > 0.1 * np.max(np.abs(tau))


def power_terms(t, tau):
    """Each term of the power balance (W) of the slider-crank with every element at time `t`,
    from the kinematics above: ``(input, kinetic, potential, dissipated, delivered, per element)``."""
    mo = motion_at(t)
    J = inertias()
    omega = {"crank": mo["om"], "rod": mo["w3"], "block_B": 0.0}
    alpha = {"crank": mo["al"], "rod": mo["al3"], "block_B": 0.0}
    kinetic = sum(SM[k] * dot(mo["vG"][k], mo["aG"][k]) + J[k] * omega[k] * alpha[k] for k in SM)
    gravity = sum(SM[k] * G * mo["vG"][k].imag for k in SM)
    ls, ls_dot, _ = axial(mo["B"], mo["vB"], S)
    lg, lg_dot, _ = axial(mo["B"], mo["vB"], S2)
    lg0 = abs(slider_kinematics(TH0)[1][0] - S2)
    push = GAS_F * (GAS_LG / (GAS_LG + lg - lg0)) ** GAS_N
    rel, rel0 = mo["phi"] - mo["th"], slider_kinematics(TH0)[2][0] - TH0
    _, ld_dot, _ = axial(mo["A"], mo["vA"], D)
    elements = {"s1": (F0 + K * (ls - L0)) * ls_dot, "g1": -push * lg_dot, "t1": KT * (rel - rel0 - FREE_T) * (mo["w3"] - mo["om"]),
                "d1": C * ld_dot**2, "r1": CT * mo["w3"] ** 2}
    potential = gravity + elements["s1"] + elements["g1"] + elements["t1"]
    dissipated = elements["d1"] + elements["r1"]
    delivered = -dot(LOAD, mo["vB"]) - MOMENT * mo["w3"]
    return tau * mo["om"], kinetic, potential, dissipated, delivered, elements


def test_power_balance_with_every_element_against_numpy():
    lk = slider_crank(every=True)
    pw = lk.power(samples())
    res = lk.inverse_dynamics(samples())
    tau = np.asarray(res.tau[:, 0])
    terms = [power_terms(t, x) for t, x in zip(T, tau)]
    scale = np.max(np.abs([x[0] for x in terms]))
    # the balance closes at every sample, in jaxmech and with the numpy terms around jaxmech's torque
    assert np.max(np.abs(np.asarray(pw.residual))) <= TOL * scale
    own = np.array([x[0] - x[1] - x[2] - x[3] - x[4] for x in terms])
    assert np.max(np.abs(own)) <= TOL * scale
    for k, field in enumerate(("input", "kinetic", "potential", "dissipated", "loads")):
        want = np.array([x[k] for x in terms])
        np.testing.assert_allclose(np.asarray(getattr(pw, field)), want, rtol=0, atol=TOL * scale, err_msg=field)
    for name in ("s1", "g1", "t1", "d1", "r1"):
        want = np.array([x[5][name] for x in terms])
        np.testing.assert_allclose(np.asarray(pw.elements[name]), want, rtol=0, atol=TOL * scale, err_msg=name)
        assert np.max(np.abs(want)) > 1e-3 * scale, name  # each element takes part
    assert np.all(np.asarray(pw.dissipated) >= 0.0)
    # the stroke's efficiency: the energy delivered to the loads over the energy put in
    trapz = lambda y: float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(T)))  # noqa: E731
    e_in, e_out = trapz(np.array([x[0] for x in terms])), trapz(np.array([x[4] for x in terms]))
    work = pw.work()
    assert abs(float(work["input"]) - e_in) <= TOL * abs(e_in) and abs(float(work["loads"]) - e_out) <= TOL * abs(e_in)
    if e_in > 0 and e_out >= 0:
        assert abs(float(pw.efficiency) - e_out / e_in) <= 1e-9
    else:
        assert np.isnan(float(pw.efficiency))


def test_efficiency_of_a_stroke_that_delivers_work():
    """A crank turning forwards against a force on the block opposing its travel on average:
    the efficiency is the delivered energy over the input (both positive), below 1 with
    the dampers."""
    lk = slider_crank(every=True)
    t = np.linspace(0.0, 1.0, 41)
    pw = lk.power(jm.ConstantSpeed(TH0, 2 * np.pi), t, p={"Fx_B": -300.0, "Fy_B": 0.0, "M_rod": 0.0})
    work = {k: float(v) for k, v in pw.work().items()}
    assert work["input"] > 0 and work["loads"] > 0 and work["dissipated"] > 0
    assert abs(float(pw.efficiency) - work["loads"] / work["input"]) <= 1e-14
    assert 0.0 < float(pw.efficiency) < 1.0


@pytest.mark.parametrize(("name", "value", "h"), [("k_s1", K, 1.0), ("n_g1", GAS_N, 1e-3)])
def test_gradient_of_the_peak_effort_against_central_differences(name, value, h):
    lk = slider_crank(every=True)
    s = samples()

    def peak(x):
        return jnp.max(lk.inverse_dynamics(s, p={name: x}).tau[:, 0])

    grad = float(jax.grad(peak)(value))
    fd = float(central_diff(lambda x: float(peak(x)), value, h=h))
    assert abs(grad - fd) <= 1e-8 * abs(fd) and abs(fd) > 1e-6
