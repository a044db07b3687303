"""Every joint type of a linkage from its drawing: a slider on a moving link (quick return), a
pin in a circular slot, a pin in a straight slot, a hydraulic cylinder.  Each against its
geometry (closed forms), the power balance ``tau u_dot = dT/dt + dV/dt`` (energies from the
bodies' own centre-of-mass motion) and the per-body Newton-Euler efforts, which must equal the
virtual-power torque."""

import functools

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.dynamics import joint_reactions  # noqa: E402
from jaxmech.dynamics.virtual_power import loaded_state  # noqa: E402

TOL = 1e-10  # relative to the largest value compared: everything here is exact in float64
S = np.linspace(0.0, 2 * np.pi, 48)


def _quick_return():
    a_pos = 0.3 * np.exp(0.7j)
    b_pos = -0.5j + 1.2 * (a_pos + 0.5j) / abs(a_pos + 0.5j)
    return jm.Linkage({"O2": (0, 0), "A": (a_pos.real, a_pos.imag), "O4": (0, -0.5), "B": (b_pos.real, b_pos.imag)},
                      {"crank": "O2 A", "rocker": "O4 B"}, ground="O2 O4", sliders={"A": {"on": "rocker", "through": "B"}},
                      driver="crank", mass={"crank": 0.4, "rocker": 2.0}, gravity=9.81, name="quick_return")


C, R, A0, L = 2.0 + 0j, 1.0, 0.5 * np.exp(0.3j), 1.6
# P on the circle |P - C| = R with |P - A0| = L (law of cosines at C); |A - C| stays within
# (L - R, L + R) over the crank's turn, so the pin never reaches a toggle of the slot
_BETA = np.arccos((R * R + abs(A0 - C) ** 2 - L * L) / (2 * R * abs(A0 - C)))
P_ARC = C + R * np.exp(1j * (np.angle(A0 - C) - _BETA))


def _circular_slot():
    return jm.Linkage({"O2": (0, 0), "A": (A0.real, A0.imag), "P": (P_ARC.real, P_ARC.imag), "C": (C.real, C.imag)},
                      {"crank": "O2 A", "coupler": "A P"}, ground="O2 C", slots={"P": {"center": "C"}}, driver="crank",
                      mass={"crank": 0.3, "coupler": 1.0}, gravity=9.81, name="arc_slot")


def _straight_slot():
    return jm.Linkage({"O2": (0, 0), "A": (A0.real, A0.imag), "P": (1.8, 0.4)}, {"crank": "O2 A", "coupler": "A P"}, ground="O2",
                      slots={"P": {"angle": "10deg"}}, driver="crank", mass={"crank": 0.3, "coupler": 1.0}, gravity=9.81, name="line_slot")


H, D, TH = 0.43, 0.196, 1.0  # a nose gear: pivot B, cylinder from C = (H, 0) to the rod end P


def _gear():
    p_pos, a_pos = D * np.exp(-1j * TH), 0.3 * np.exp(-1j * (TH + 0.2))
    return jm.Linkage({"B": (0, 0), "C": (H, 0), "P": (p_pos.real, p_pos.imag), "A": (a_pos.real, a_pos.imag)},
                      {"leg": "B P A"}, ground="B C", actuators={"cyl": "C P"}, driver="cyl", mass={"leg": 20.0},
                      gravity=9.81, name="gear")


CASES = {"quick_return": (_quick_return, 0.7 + S, 3.0, 0.0), "arc_slot": (_circular_slot, 0.3 + S, 2.0, 0.5),
         "line_slot": (_straight_slot, 0.3 + S, 2.0, 0.5), "gear": (_gear, 0.38 + 0.03 * np.sin(S), 0.03, -0.01)}


@functools.lru_cache(maxsize=None)
def run(name):
    make, u, ud, udd = CASES[name]
    lk = make()
    ud = ud * np.cos(S) if name == "gear" else np.full_like(u, ud)
    udd = udd * np.sin(S) if name == "gear" else np.full_like(u, udd)
    return lk, lk.inverse_dynamics(jm.Samples(u, ud, udd))


def _cross(r, f):
    return r.real * f.imag - r.imag * f.real


@pytest.mark.parametrize("name", list(CASES))
def test_power_balance_and_newton_euler_efforts(name):
    lk, res = run(name)
    assert np.all(np.asarray(res.status) == 0), jm.status_counts(res.status)
    p, mass = lk.params, lk.mass_properties()
    dE = np.zeros(res.q.shape[0])
    for body in lk.model.bodies:
        m, _, J = mass[body.name]
        _, v, a = (np.asarray(x) for x in res.points[body.position])
        dE += m * np.real(np.conj(v) * a) + m * p["g"] * v.imag  # gravity down: dV/dt = m g vy
        if J:
            # the body's angular rate and acceleration from two of its points: w = Im(conj(r) dr)/|r|^2
            pts = [x for x in lk.links[body.name] if x != body.position][:1] + [body.position]
            (r1, v1, a1), (r2, v2, a2) = ([np.asarray(x) for x in res.points[n]] for n in pts)
            r, dr, ddr = r1 - r2, v1 - v2, a1 - a2
            w = np.imag(np.conj(r) * dr) / np.abs(r) ** 2
            alpha = np.imag(np.conj(r) * ddr) / np.abs(r) ** 2  # |r| constant on a rigid body
            dE += J * w * alpha
    power = np.asarray(res.tau[:, 0] * res.u_dot[:, 0])
    assert np.max(np.abs(power - dE)) <= TOL * np.max(np.abs(power))
    # the Newton-Euler efforts (the joints' system) equal the virtual-power torque
    pj = {k: jnp.asarray(v) for k, v in p.items()}
    eff = jax.vmap(lambda *a: joint_reactions(lk.model, loaded_state(lk.model, a[0], a[1], a[2], a[3], pj, 0.0, q_dot=a[4], q_ddot=a[5]))[0])(
        res.q, res.u, res.u_dot, res.u_ddot, res.q_dot, res.q_ddot)
    np.testing.assert_allclose(np.asarray(eff), np.asarray(res.tau), rtol=0, atol=TOL * np.max(np.abs(np.asarray(res.tau))))


def test_quick_return_geometry_and_massless_block():
    lk, res = run("quick_return")
    a = np.asarray(res.points["A"][0])
    rocker = np.asarray(res.q[:, lk.mechanism.coords.index("theta_rocker")])
    drawn = np.angle((a + 0.5j))  # the rocker passes through the crank pin
    assert np.max(np.abs(np.angle(np.exp(1j * (rocker - drawn))))) <= 1e-12
    np.testing.assert_allclose(np.abs(a), 0.3, rtol=1e-13)
    # a massless block pinned at A: no moment on its guide, and the pin force is the guide's
    # normal force (perpendicular to the rocker)
    M = np.asarray(res.joint_moments["block_A on rocker"])
    F = np.asarray(res.joints["block_A on rocker"])
    assert np.max(np.abs(M)) <= TOL * np.max(np.abs(F)) * 1.2
    e = np.exp(1j * rocker)
    assert np.max(np.abs(np.real(np.conj(e) * F))) <= TOL * np.max(np.abs(F))
    np.testing.assert_allclose(np.asarray(res.joints["A"]), -F, rtol=0, atol=TOL * np.max(np.abs(F)))


def test_slots_keep_their_pins_and_push_normal_to_them():
    _, res = run("arc_slot")
    p = np.asarray(res.points["P"][0])
    assert np.max(np.abs(np.abs(p - C) - R)) <= 1e-13
    n = np.asarray(res.joints["P in ground"])
    assert np.max(np.abs(np.imag(n * np.conj(p - C)))) <= TOL * np.max(np.abs(n))  # radial
    _, res = run("line_slot")
    p = np.asarray(res.points["P"][0])
    e = np.exp(np.radians(10) * 1j)
    assert np.max(np.abs(np.imag(np.conj(e) * (p - (1.8 + 0.4j))))) <= 1e-13  # on the line
    n = np.asarray(res.joints["P in ground"])
    assert np.max(np.abs(np.real(np.conj(e) * n))) <= TOL * np.max(np.abs(n))  # normal to it


def test_cylinder_holds_the_gear_by_its_moment_arm():
    """Statics of the gear: the cylinder's force times its moment arm about B balances the
    leg's weight moment (closed form from the drawn pose); the pivot carries the rest."""
    lk = _gear()
    x = np.linspace(0.33, 0.5, 7)
    res = lk.statics(x)
    assert np.all(np.asarray(res.status) == 0)
    p = lk.params
    P = np.asarray(res.points["P"][0])
    G = np.asarray(res.points["G_leg"][0])
    e = (P - H) / np.abs(P - H)  # from C to P
    weight = -1j * p["m_leg"] * p["g"]
    force = -_cross(G, weight) / _cross(P, e)  # moments about B: F (P x e) + G x W = 0
    np.testing.assert_allclose(np.asarray(res.tau[:, 0]), force, rtol=TOL)
    np.testing.assert_allclose(np.asarray(res.joints["cyl"]), force * e, rtol=0, atol=TOL * np.max(np.abs(force)))
    np.testing.assert_allclose(np.asarray(res.joints["B"]), -weight - force * e, rtol=0, atol=TOL * np.max(np.abs(force)))
