"""Worked design problems (examples/design_problems.py), each checked against truths the solver does
not use: run_scene (the eager engine path) for the flap, the closed form for the gear, the
thesis's own checks and the closed-form depth for the arc-track flap, and the known
parameters behind synthetic records for the identification."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from examples import design_problems as problems  # noqa: E402
from jaxmech.scenes import run_scene  # noqa: E402

DEG = np.pi / 180
REL_CLOSED = 1e-9  # the brief's agreement with the gear's closed form


# ----------------------------------------------------------------------- 1. flap_msd
def test_flap_msd_sixty_degrees_at_lower_peak_torque():
    from jaxmech.scenes.flap_msd import DEFAULTS, SCENE

    points = 46  # the seeds' run_scene(SCENE, 46): its compiled stroke is shared
    # Two starts and a short budget: the test checks the problem's guarantees (every
    # constraint met, recomputed by run_scene), not the optimum (benchmarks/design.py).
    res = problems.flap_msd(points=points, starts=2, maxiter=15)
    assert res.violation <= 1e-8
    assert res.document_theta_travel == pytest.approx(60.5816 * DEG, abs=1e-6)
    assert "peak torque" in res.report and "won" in res.report

    # Independent recompute with run_scene (the eager path: continuation over the stroke,
    # the virtual-power torque); it raises if the design cannot be assembled.
    run = run_scene(SCENE, points, **{k: res.params[k] for k in problems.FLAP_VARS})
    table = run.table()
    assert np.all(table["status[-]"] == 0)
    th = table["theta[rad]"]
    assert abs((th[-1] - th[0]) - 60 * DEG) < 1e-8
    assert th[0] == pytest.approx(0.024093 * DEG, abs=1e-8)  # same retracted start
    assert np.max(table["torque[N m]"]) == pytest.approx(res.peak_torque, rel=1e-9)
    mu2 = np.arcsin(-np.sin(table["phi[rad]"] - table["psi[rad]"]))
    mu3 = np.arcsin(np.cos(table["theta[rad]"] + table["xi[rad]"]))
    assert min(mu2.min(), mu3.min()) >= problems.FLAP_MIN_TRANSMISSION - 1e-8
    doc = run_scene(SCENE, points).table()["torque[N m]"]
    assert np.max(doc) == pytest.approx(res.document_peak_torque, rel=1e-9)
    assert res.peak_torque < res.document_peak_torque
    # Loop 1 untouched: the main flap moves as designed.
    for k in ("a", "b", "c", "l", "r"):
        assert res.params[k] == DEFAULTS[k]


# ----------------------------------------------------------------------- 2. landing_gear
def test_landing_gear_recovers_closed_form():
    from jaxmech.scenes.landing_gear import FT

    x1, x2 = 1.25, 2.0  # ft
    d_cf = (-x1 + np.sqrt(2 * x2**2 - x1**2)) / 2
    h_cf = np.hypot(d_cf, x1)
    res = problems.landing_gear()
    assert res.d / FT == pytest.approx(d_cf, rel=REL_CLOSED)
    assert res.h / FT == pytest.approx(h_cf, rel=REL_CLOSED)
    assert res.theta1 == pytest.approx(np.arctan2(x1, d_cf), rel=REL_CLOSED)
    # The gradient fit alone (before the polishing solve) is already close.
    assert res.fit_d / FT == pytest.approx(d_cf, rel=1e-6)
    assert res.fit_h / FT == pytest.approx(h_cf, rel=1e-6)
    assert round(res.d / FT, 5) == 0.64361 and round(res.h / FT, 4) == 1.4060


# ----------------------------------------------------------------------- 3. arc_track_flap
def test_arc_track_flap_shallower_fairing_within_checks_and_cap():
    from jaxmech.scenes.arc_track_flap import SCENE, forces, validate

    res = problems.arc_track_flap()
    p = res.params
    validate(p)  # the thesis's red cells: c1 < b1, s34_f <= a3, a1 > a2, beta ranges
    f = forces(p)  # engine solve over the stroke; validate(p, s34): pins within their slots
    assert np.all(f["status"] == 0)
    assert np.max(f["T_R"]) <= res.cap * (1 + 1e-8)  # the constraint's stated feasibility
    assert res.cap == pytest.approx(problems.ARC_TORQUE_CAP * np.max(forces(dict(SCENE.defaults))["T_R"]), rel=1e-9)
    assert res.s34_f <= p["a3"]
    # Depth: the least distance from A0 to the screw line is h = a2 cos(beta3/2).
    h = p["a2"] * np.cos(p["beta3"] / 2)
    assert res.depth == pytest.approx(h, rel=1e-9)
    assert res.baseline_depth == pytest.approx(228.892e-3, abs=1e-6)
    assert res.depth < res.baseline_depth
    assert res.violation <= 1e-8
    # Closed-form optimum: the moment about A0 does not depend on a1, a2, alpha0 and the
    # screw line's moment arm is a2 sin(psi) with psi fixed by beta3, so T_R ~ 1/a2 and
    # the active cap fixes a2 = a2_0 / 1.1: depth = baseline / 1.1.
    expect = res.baseline_depth / problems.ARC_TORQUE_CAP
    assert res.depth == pytest.approx(expect, rel=1e-7)


# ----------------------------------------------------------------------- 4. identification
def test_identify_fourbar_within_noise():
    truth = {"b": 3.0, "c": 2.5, "k_v": 5.0}
    n, sig_theta, sig_torque = 41, 1e-3, 0.5
    clean = run_scene(problems.LOADED_FOURBAR, n, **truth).table()
    rng = np.random.default_rng(3)
    theta4 = clean["theta4[rad]"] + sig_theta * rng.standard_normal(n)
    torque = clean["torque[N m]"] + sig_torque * rng.standard_normal(n)
    res = problems.identify_fourbar(theta4, torque, sig_theta=sig_theta, sig_torque=sig_torque, truth=truth)
    for k in problems.IDENT_UNKNOWN:
        assert abs(res.estimate[k] - truth[k]) < 4 * res.stderr[k]
        assert res.stderr[k] < 0.05 * truth[k]  # the data do determine every parameter
    dof = res.n_data - len(problems.IDENT_UNKNOWN)
    assert 0.6 * dof < res.chi2 < 1.5 * dof  # residuals consistent with the stated noise
    with pytest.raises(ValueError, match="same shape"):
        problems.identify_fourbar(theta4, torque[:-1], sig_theta=sig_theta, sig_torque=sig_torque)
