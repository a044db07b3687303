"""Actuator laws against textbook numbers and hand formulas; the DC motor's dynamic steady
state against the algebraic voltage formula."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech import Mechanism, cis  # noqa: E402
import jaxmech as jm  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402
from jaxmech.actuators import DCMotor, HydraulicCylinder, LinearSpring, ScrewJack, SMAWire, resolve  # noqa: E402

RTOL = 1e-12
RTOL_STEADY = 1e-6


def test_resolve_specs():
    p = {"k": 3.0}
    assert resolve("k", p) == 3.0 and resolve(2.0, p) == 2.0 and resolve(lambda p: 2 * p.k, p) == 6.0
    with pytest.raises(ValueError, match="unknown parameter 'kk'"):
        resolve("kk", p)


def test_dc_motor_formulas():
    m = DCMotor("R", "K", inductance="L", ratio="n")
    p = dict(R=2.0, K=0.5, L=1e-3, n=10.0)
    T, w = 30.0, 4.0  # at the input (after the gear)
    v = float(m.steady_voltage(T, w, p))
    assert abs(v - (2.0 * 30.0 / (10 * 0.5) + 10 * 0.5 * 4.0)) <= RTOL * abs(v)
    assert abs(float(m.steady_torque(v, w, p)) - T) <= RTOL * T
    i = float(m.steady_current(T, p))
    assert abs(float(m.torque(i, p)) - T) <= RTOL * T
    assert abs(float(m.current_rate(i, v, w, p))) <= 1e-9  # steady: di/dt = 0
    with pytest.raises(ValueError, match="needs an inductance"):
        DCMotor("R", "K").current_rate(1.0, 1.0, 1.0, p)


def test_screw_jack_textbook_example():
    """Shigley's Mechanical Engineering Design, Example 8-1: square double thread, d_m = 30 mm,
    lead 8 mm, f = 0.08, F = 6.4 kN: T_R = 15.94 N m, T_L = -0.466 N m (collar excluded)."""
    s = ScrewJack(lead="l", mean_diameter="dm", friction="f")
    p = dict(l=0.008, dm=0.030, f=0.08)
    assert abs(float(s.raise_torque(6400.0, p)) - 15.94) < 5e-3
    assert abs(float(s.lower_torque(6400.0, p)) - (-0.466)) < 5e-4
    assert not bool(s.self_locking(p))
    # exact formulas, and the thread-angle secant (Acme, 14.5 deg half angle)
    a = np.deg2rad(14.5)
    sa = ScrewJack(lead="l", mean_diameter="dm", friction="f", thread_angle=a)
    l, dm, f, sec = 0.008, 0.030, 0.08, 1 / np.cos(a)
    TR = 6400 * dm / 2 * (l + np.pi * f * dm * sec) / (np.pi * dm - f * l * sec)
    TL = 6400 * dm / 2 * (np.pi * f * dm * sec - l) / (np.pi * dm + f * l * sec)
    assert abs(float(sa.raise_torque(6400.0, p)) - TR) <= RTOL * TR
    assert abs(float(sa.lower_torque(6400.0, p)) - TL) <= RTOL * abs(TL)
    # efficiency of a frictionless screw is one
    assert abs(float(s.efficiency(dict(l=0.008, dm=0.030, f=0.0))) - 1.0) <= RTOL


def test_hydraulic_cylinder():
    c = HydraulicCylinder(bore="D", rod="d", cap_pressure="pc", rod_pressure="pr")
    p = dict(D=0.08, d=0.04, pc=20e6, pr=1e6)
    Ac, Aa = np.pi * 0.08**2 / 4, np.pi * (0.08**2 - 0.04**2) / 4
    F = 20e6 * Ac - 1e6 * Aa
    assert abs(float(c.force(p)) - F) <= RTOL * F
    assert abs(float(c.cap_pressure_for(F, p)) - 20e6) <= RTOL * 20e6
    assert float(c(0.5, 0.0, p, 0.0)) == -float(c.force(p))  # pushes: negative tension


def test_linear_spring():
    s = LinearSpring(stiffness="k", length0="L0", preload="F0")
    p = dict(k=1000.0, L0=0.1, F0=5.0)
    assert abs(float(s.tension(0.12, p)) - 25.0) <= RTOL * 25
    # energy's derivative is the tension
    dE = jax.grad(lambda L: s.energy(L, p))(0.12)
    assert abs(float(dE) - 25.0) <= RTOL * 25


def test_sma_wire_linear_branch_and_hook():
    p = dict(A_w=1e-7, L0=0.16, E_M=28e9, E_A=75e9, eps=-0.02, xi=0.25, T=330.0, A_s=320.0, A_f=340.0)
    w = SMAWire(prestrain="eps", fraction="xi")
    E = 0.25 * 28e9 + 0.75 * 75e9
    L = 0.158
    strain = L / (0.16 * 0.98) - 1
    assert abs(float(w.tension(L, p)) - E * 1e-7 * strain) <= RTOL * E * 1e-7 * strain
    assert float(w.tension(0.15, p)) == 0.0  # slack: a wire cannot push
    assert float(SMAWire(prestrain="eps", fraction="xi", slack=False).tension(0.15, p)) < 0
    # temperature: martensite below A_s, austenite above A_f, half-way in the middle
    wt = SMAWire(temperature="T")
    for T, xi in ((300.0, 1.0), (330.0, 0.5), (360.0, 0.0)):
        assert abs(float(wt.martensite_fraction({**p, "T": T})) - xi) <= 1e-15
    # a user's constitutive law replaces the linear branch
    wl = SMAWire(prestrain="eps", law=lambda e, p: p.E_A * e + 1e12 * e**3)
    assert abs(float(wl.stress(0.01, p)) - (75e9 * 0.01 + 1e12 * 1e-6)) <= RTOL * 1e9
    with pytest.raises(ValueError, match="martensite `fraction` or a wire `temperature`"):
        SMAWire()


def test_dc_motor_steady_state_matches_voltage_formula():
    """A crank (flywheel J, viscous loss c) driven by an inductive DC motor at constant
    voltage: the speed settles where v = R i + K w with K i = c w (the loop's coupler and
    rocker are massless, so the inertia is constant)."""
    mech = Mechanism(
        name="fourbar_flywheel",
        coords=("theta3", "theta4"),
        inputs=("theta2",),
        params=("a", "b", "c", "d", "J", "cv", "R_a", "K_m", "L_a", "V"),
        lengths=("a", "b", "c", "d"),
        constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d],
        points={"O": lambda q, u, p: 0.0 * p.a + 0j},
    )
    model = D.Model(mech, bodies=[D.Body("O", 0.0, angle="theta2", inertia="J")],
                    loads=[D.Moment("theta2", lambda q, u, p, v, t: -p.cv * v.theta2)])
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5, J=0.01, cv=0.1, R_a=2.0, K_m=0.5, L_a=1e-3, V=12.0)
    motor = DCMotor("R_a", "K_m", inductance="L_a")
    # electrical time constant L/R = 0.5 ms against a 5 ms step: stiff, Radau IIA damps it
    tr = D.forward_dynamics(model, p, 0.0, 0.0, jnp.array([0.2, 1.2]), h=5e-3, steps=300, motor=motor, voltage="V")
    assert int(tr.status) == jm.Status.CONVERGED
    w, i = float(tr.u_dot[-1, 0]), float(tr.current[-1, 0])
    v_formula = p["R_a"] * p["cv"] * w / p["K_m"] + p["K_m"] * w
    assert abs(v_formula - p["V"]) <= RTOL_STEADY * p["V"]
    assert abs(i - p["cv"] * w / p["K_m"]) <= RTOL_STEADY * i


# --------------------------------------------------------------------------- stateful actuators
def test_registry_finds_the_stateful_actuators():
    from jaxmech.actuators import REGISTRY, get_actuator

    assert get_actuator("dc_motor") is DCMotor and set(REGISTRY) >= {"dc_motor", "oil_cylinder"}
    assert get_actuator("oil_cylinder").__name__ == "OilCylinder"
    with pytest.raises(ValueError, match="unknown actuator 'pump'; known actuators: dc_motor, oil_cylinder"):
        get_actuator("pump")


def test_oil_cylinder_closed_chamber_against_its_closed_form():
    """A mass on a piston (a mechanism of one input, no dependent coordinate) under a constant
    load, held by a closed oil chamber (``OilCylinder``, found by name in the registry):
    ``dP/dt = -beta A x_dot / V(x)`` integrates to ``P = P0 - beta ln(V(x)/V0)`` at every
    instant, and ``m v^2 / 2 + F0 x + beta (V ln(V/V0) - V + V0) - P0 A (x - x0)`` is conserved.
    Radau IIA at w h = 0.05: measured 1.4e-13 P0 and 4e-10 of the energy scale."""
    from jaxmech.actuators import get_actuator

    cylinder = get_actuator("oil_cylinder")(bore="D", volume0="V0", position0="x0", bulk_modulus="beta", pressure0="P0")
    piston = Mechanism(name="piston", coords=(), inputs=("x",), params=(), points={"P": lambda q, u, p: u.x + 0j})
    model = D.Model(piston, bodies=[D.Body("P", "m")], loads=[D.Moment("x", lambda q, u, p, v, t: -p.F0, name="load")],
                    params=("m", "F0"))
    p = dict(m=50.0, F0=5000.0, D=0.05, V0=1e-3, x0=0.0, beta=1e8, P0=3e6)
    A = np.pi * p["D"] ** 2 / 4
    w = np.sqrt(p["beta"] * A**2 / p["V0"] / p["m"])  # 88.6 rad/s: 126 steps per period
    tr = D.forward_dynamics(model, p, 0.0, 0.0, (), h=0.05 / w, steps=190, actuators={"x": cylinder})
    assert int(tr.status) == jm.Status.CONVERGED and tr.states.shape == (191, 1) and tr.current.shape == (191, 0)
    x, v, P = (np.asarray(a) for a in (tr.u[:, 0], tr.u_dot[:, 0], tr.states[:, 0]))
    assert np.ptp(x) > 1e-3  # it oscillates (amplitude ~2 mm)
    V = p["V0"] + A * x
    np.testing.assert_allclose(P, p["P0"] - p["beta"] * np.log(V / p["V0"]), rtol=0, atol=1e-11 * p["P0"])
    E = 0.5 * p["m"] * v**2 + p["F0"] * x + p["beta"] * (V * np.log(V / p["V0"]) - V + p["V0"]) - p["P0"] * A * x
    scale = (p["P0"] * A - p["F0"]) ** 2 / (p["beta"] * A**2 / p["V0"])  # twice the oscillation's energy
    assert np.max(np.abs(E - E[0])) <= 1e-8 * scale
