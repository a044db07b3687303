"""The power balance (``Linkage.power``) of a linkage with joint friction, against what the
friction laws say it dissipates, written out here in numpy (no jaxmech code but the joint
forces, which ``tests/test_joint_friction.py`` checks against Newton-Euler):

- an offset slider-crank with Coulomb friction at its three pins and in the guide, viscous
  damping at a pin and in the guide, and a linear damper on the block, driven back and forth
  through two reversals: the balance closes to 1e-10 of the largest input power at every
  sample, and each joint's dissipation is ``mu r |F| |w| tanh(|w| / (width W)) + c w^2``
  (``mu |N| ...`` in the guide) with the relative speeds ``w`` from the closed-form
  kinematics written here;
- a one-way stroke against a force: the efficiency is the force's work over the drive's,
  below 1, and below the same stroke's without friction;
- a result with friction given to ``power_balance`` without it is refused.
"""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.dynamics.power import power_balance  # noqa: E402

TOL = 1e-10  # relative to the largest input power over the stroke

# Crank O-A (R), rod A-B (L), block at B on the guide y = E; a damper from D (on the guide's
# line, on the ground) to the block; a force on the block.
R, L, E = 0.12, 0.40, 0.03
TH0 = 1.0
MASS = {"crank": 1.2, "rod": 2.5, "block_B": 0.8}
LOAD = -300.0 + 50.0j
C_DAMPER = 25.0  # N s/m
MU = {"O": 0.10, "A": 0.12, "B": 0.20, "block_B on ground": 0.15}
ARM = {"O": 0.010, "A": 0.008, "B": 0.012, "block_B on ground": 1.0}  # a pin's radius; the guide: 1
VISCOUS = {"A": 0.8, "block_B on ground": 40.0}  # N m s/rad at the pin, N s/m in the guide
WIDTH = 1e-3
FRICTION = {"all": {"mu": MU["O"], "radius": "10 mm"}, "A": {"mu": MU["A"], "radius": "8 mm", "damping": VISCOUS["A"]},
            "B": {"mu": MU["B"], "radius": "12 mm"}, "block_B": {"mu": MU["block_B on ground"], "damping": "40 N s/m"},
            "width": WIDTH}


def pose(th):
    """``(A, B, phi)``: the pins and the rod's angle at crank angle `th`."""
    phi = np.arcsin((E - R * np.sin(th)) / L)
    a = R * np.exp(1j * th)
    return a, a + L * np.exp(1j * phi), phi


def relative_speeds(th, om):
    """Each friction joint's relative speed: the pins' rotation rates of one body on the
    other (rad/s), the block's speed along the guide (m/s)."""
    _, _, phi = pose(th)
    phi_dot = -R * np.cos(th) * om / (L * np.cos(phi))
    v_block = -R * np.sin(th) * om - L * np.sin(phi) * phi_dot
    return {"O": om, "A": phi_dot - om, "B": -phi_dot, "block_B on ground": v_block}


def linkage(**kw):
    a, b, _ = pose(TH0)
    pts = {"O": (0, 0), "A": (a.real, a.imag), "B": (b.real, b.imag), "D": (-0.2, E)}
    return jm.Linkage(points=pts, links={"crank": "O A", "rod": "A B"}, ground="O D", driver="crank", sliders={"B": {"angle": 0.0}},
                      mass=MASS, gravity=9.81, forces={"B": {"force": (LOAD.real, LOAD.imag), "on": "block_B"}},
                      dampers={"d": {"between": ["D", "B"], "on": ["ground", "block_B"], "c": C_DAMPER}}, **kw)


def rocking():
    """The crank back and forth, reversing at t = pi/4 and 3 pi/4."""
    t = np.linspace(0.0, np.pi, 41)
    return jm.Samples(TH0 + 1.2 * np.sin(2 * t), 2.4 * np.cos(2 * t), -4.8 * np.sin(2 * t), t)


def friction_dissipation(res, th, om) -> dict:
    """``{joint: W}`` per sample from the laws: ``mu r |F| |w| tanh(|w| / (width W)) + c w^2``."""
    w = {j: np.array([relative_speeds(a, b)[j] for a, b in zip(th, om)]) for j in MU}
    force = {j: np.abs(np.asarray(res.joints[j])) for j in ("O", "A", "B")}
    force["block_B on ground"] = np.abs(np.asarray(res.normal_force("block_B on ground")))
    out = {}
    for j, x in w.items():
        coulomb = MU[j] * ARM[j] * force[j] * np.abs(x) * np.tanh(np.abs(x) / (WIDTH * np.max(np.abs(x))))
        out[j] = coulomb + VISCOUS.get(j, 0.0) * x**2
    return out


def test_power_balance_with_friction_and_a_damper_closes_along_a_reversing_stroke():
    lk = linkage(friction=FRICTION)
    s = rocking()
    pw, res = lk.power(s), lk.inverse_dynamics(s)
    assert np.all(np.asarray(res.status) == jm.Status.CONVERGED)
    p_in = np.asarray(pw.input)
    scale = np.max(np.abs(p_in))
    np.testing.assert_allclose(p_in, np.asarray(res.tau[:, 0]) * np.asarray(s.u_dot), rtol=0, atol=1e-14 * scale)
    assert np.max(np.abs(np.asarray(pw.residual))) <= TOL * scale
    # each joint's dissipation is the friction law's, every sample
    want = friction_dissipation(res, np.asarray(s.u), np.asarray(s.u_dot))
    assert set(pw.joints) == set(want)
    for j, x in want.items():
        np.testing.assert_allclose(np.asarray(pw.joints[j]), x, rtol=0, atol=TOL * scale, err_msg=j)
        assert np.all(np.asarray(pw.joints[j]) >= -TOL * scale), j
        assert np.max(x) > 1e-3 * scale, j  # each joint takes part
    # the damper's: c v^2; the dissipated total: the damper and every joint
    v_block = np.array([relative_speeds(a, b)["block_B on ground"] for a, b in zip(np.asarray(s.u), np.asarray(s.u_dot))])
    np.testing.assert_allclose(np.asarray(pw.elements["d"]), C_DAMPER * v_block**2, rtol=0, atol=TOL * scale)
    total = C_DAMPER * v_block**2 + sum(want.values())
    np.testing.assert_allclose(np.asarray(pw.dissipated), total, rtol=0, atol=TOL * scale)
    # friction matters here: the balance with the joints left out would miss by far more than the tolerance
    assert np.max(sum(want.values())) > 1e-2 * scale


def test_efficiency_of_a_stroke_with_friction_is_the_forces_work_over_the_drives():
    """The crank turning back at constant speed pushes the block out against the force's
    -300 N: the efficiency is the force's work over the drive's (trapezoidal, as
    ``work()``), below 1, and below the same stroke's without friction."""
    t = np.linspace(0.0, 1.0, 41)
    om = -0.8
    s = jm.Samples(TH0 + om * t, np.full_like(t, om), np.zeros_like(t), t)
    lk = linkage(friction=FRICTION)
    pw, res = lk.power(s), lk.inverse_dynamics(s)
    trapz = lambda y: float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))  # noqa: E731
    v_block = np.array([relative_speeds(a, om)["block_B on ground"] for a in TH0 + om * t])
    e_out = trapz(-LOAD.real * v_block)  # the force on the block is constant; the guide takes its y part
    e_in = trapz(np.asarray(res.tau[:, 0]) * om)
    assert e_out > 0 and e_in > e_out
    assert abs(float(pw.efficiency) - e_out / e_in) <= 1e-12
    assert 0.0 < float(pw.efficiency) < 1.0
    frictionless = lk.power(s, p={k: 0.0 for k in lk.params if k.startswith(("mu_", "cv_"))})
    assert float(pw.efficiency) < float(frictionless.efficiency) - 1e-3
    assert all(np.max(np.abs(np.asarray(x))) == 0.0 for x in frictionless.joints.values())


def test_a_result_with_friction_needs_the_friction_for_its_balance():
    lk = linkage(friction=FRICTION)
    res = lk.inverse_dynamics(rocking())
    with pytest.raises(ValueError, match="the result has joint friction; give friction="):
        power_balance(lk.model, res, lk.params)
    bare = linkage().inverse_dynamics(rocking())
    with pytest.raises(ValueError, match="no joint friction at"):
        power_balance(lk.model, bare, lk.params, friction=lk.friction)
    assert linkage().power(rocking()).joints == {}
