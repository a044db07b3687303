"""The retractable nose-gear scene (seed 001_2d20636cf4490e47) against the independent numpy/scipy
reference ``reference_landing_gear`` and the numbers of ``docs/seeds/landing_gear.md``.

Section, equation and listing numbers refer to the report
(A. Z. Creppe, SEM0501 "Projeto de Mecanismo", 2021).  The report works in feet; the scene is SI and
the tests convert with ``FT`` = 0.3048 m/ft.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import reference_landing_gear as ref  # noqa: E402
from helpers import central_diff  # noqa: E402
from jaxmech import Status  # noqa: E402
from jaxmech.scenes import get_scene, run_scene  # noqa: E402
from jaxmech.scenes.landing_gear import (  # noqa: E402
    DEFAULTS,
    FT,
    REPORT,
    SCENE,
    SPEED,
    T_REQUIRED,
    constant_speed_motion,
    design,
    design_family,
    gear_angle,
    linear_angle_motion,
    report_eq5,
    report_eq6,
    report_listing,
    report_plotted_omega_angle,
    report_printed_system,
    retraction_time,
    transmission_angle,
)

DESIGN_RTOL = 1e-9  # the requirement: engine design vs the closed form
KIN_RTOL = 1e-9  # positions, velocities, accelerations vs the reference
FD_RTOL = 1e-7  # implicit derivatives vs finite differences
T7 = np.linspace(0.0, 3.0, 7)  # the doc's table times (s)
DEG = np.pi / 180.0


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="module")
def result():
    return run_scene(SCENE, 21)


@pytest.fixture(scope="module")
def cs_motion(result):
    """The constant-speed motion of ``run_scene(SCENE, 21)`` (t = 0, 0.15, ..., 3 s)."""
    return result.motion


T21 = np.linspace(0.0, 3.0, 21)
I_DOC = [0, 10, 20]  # t = 0, 1.5, 3 s: rows of the doc's table


# --------------------------------------------------------------------------- §3.1 design
def test_design_solve_matches_closed_form():
    """§3.1, eq. 1: the engine's 3x3 Newton solve of (E1-E3) equals the closed form."""
    sol = design()
    assert int(sol.status) == Status.CONVERGED
    d, h, th1 = ref.design_closed_form()
    assert abs(float(sol["d"]) / FT - d) / d < DESIGN_RTOL
    assert abs(float(sol["h"]) / FT - h) / h < DESIGN_RTOL
    assert abs(float(sol["theta1"]) - th1) / th1 < DESIGN_RTOL
    # and the scene's defaults (its own closed form) agree with that solve, not with the
    # report's rounded numbers
    assert abs(DEFAULTS["d"] - float(sol["d"])) / DEFAULTS["d"] < DESIGN_RTOL
    assert abs(DEFAULTS["h"] - float(sol["h"])) / DEFAULTS["h"] < DESIGN_RTOL
    # the scipy hybrid solve agrees too
    dn, hn, tn = ref.design_solve()
    assert _rel([sol["d"] / FT, sol["h"] / FT, sol["theta1"]], [dn, hn, tn]) < DESIGN_RTOL


def test_design_report_values():
    """§3.1: d = 0.64361 ft, h = 1.4060 ft, theta1 = 62.76 deg = 1.0953 rad; eq. 4 constants
    d^2 + h^2 = 2.3911 (with the rounded h) and 2dh = 1.8098 (ft^2)."""
    sol = design()
    d, h, th1 = (float(sol[k]) for k in ("d", "h", "theta1"))
    d, h = d / FT, h / FT
    assert round(d, 5) == REPORT["d"]
    assert round(h, 4) == REPORT["h"]
    assert round(np.degrees(th1), 2) == REPORT["theta1_deg"]
    assert round(th1, 4) == REPORT["theta1"]
    assert round(d * d + REPORT["h"] ** 2, 4) == REPORT["c0"]
    assert round(2 * d * h, 4) == REPORT["c1"]
    # eq. 1: d^2 + 1.25 d - 1.21875 = 0, the roots 0.64361 and -1.89361 ft
    assert abs(d * d + 1.25 * d - 1.21875) < 1e-12
    assert round(-1.25 - d, 5) == REPORT["d_other"]


def test_design_derivatives_vs_finite_differences():
    """§3.1: d, h, theta1 as functions of the stroke end x2, by the implicit function theorem,
    against central differences of the reference closed form."""
    jac = jax.jacfwd(lambda x2: design(x2=x2).q)(jnp.asarray(ref.X2 * FT))
    fd = central_diff(lambda x2: np.array(ref.design_closed_form(x2=x2 / FT)) * [FT, FT, 1.0], ref.X2 * FT, 1e-4)
    assert _rel(jac, fd) < FD_RTOL


def test_printed_system_sign_error():
    """§3.1 mistakes 1-2: with cos(theta2) = +sin(theta1) as printed, (2) - (1) gives
    2dh(cos - sin) = -0.7806 ft^2, which cannot equal 2^2 - 1.25^2 = 2.4375 ft^2; with the correct
    -sin the difference is 2dh(sin + cos), the report's next line."""
    d, h, th1 = ref.design_closed_form()
    printed, truth = report_printed_system(d, h, th1)
    assert round(float(printed), 4) == -0.7806 and truth == 2.4375
    assert abs(2 * d * h * (np.sin(th1) + np.cos(th1)) - truth) < 1e-12
    assert np.cos(th1 + np.pi / 2) == pytest.approx(-np.sin(th1), abs=1e-15)  # cos(theta2) = -sin(theta1)


def test_theta1_formula_argument():
    """§3.1 mistake 3: arcsin(1.25/0.64361) has argument 1.942 > 1 (undefined); arcsin(1.25/h)
    gives the printed 62.76 deg."""
    assert 1.25 / REPORT["d"] > 1.9
    sol = design()
    th1 = float(sol["theta1"])
    assert abs(np.arcsin(ref.X1 * FT / float(sol["h"])) - th1) < 1e-13
    assert abs(np.arctan2(ref.X1 * FT, float(sol["d"])) - th1) < 1e-13


def test_hidden_right_angle_and_family():
    """§3.1 mistake 4: two stroke conditions leave a one-parameter family (theta1 = 50 deg gives
    d = 0.56346, h = 1.5353 ft); the report's pick is the right angle at P at gear-down, and the
    transmission angle then falls to 18.77 deg at gear-up."""
    fam = design_family(50 * DEG)
    assert int(fam.status) == Status.CONVERGED
    assert _rel(np.asarray(fam.q) / FT, ref.design_family(50 * DEG)) < DESIGN_RTOL
    # the family member at the report's theta1 is the report's design
    sol = design()
    fam1 = design_family(sol["theta1"])
    assert _rel(fam1.q, sol.q[:2]) < DESIGN_RTOL
    q = gear_angle(DEFAULTS, jnp.array([DEFAULTS["x1"], DEFAULTS["x2"]])).q
    mu = np.asarray(transmission_angle(q))
    assert abs(mu[0] - np.pi / 2) < 1e-12
    assert _rel(mu, ref.transmission_angle(ref.THETA1 + np.array([0.0, np.pi / 2]))) < KIN_RTOL
    assert round(np.degrees(mu[1]), 2) == 18.77


# --------------------------------------------------------------------------- §3.2 motion
def test_constant_speed_motion_vs_reference(cs_motion):
    """§3.2 eqs. 2, 4: x = 1.25 + 0.25 t ft; theta, theta_dot, theta_ddot from the engine
    (implicit derivatives of the loop) against the reference's closed form."""
    mo = cs_motion
    r = ref.motion_constant_speed(T21)
    assert np.all(np.asarray(mo.status) == Status.CONVERGED)
    assert _rel(mo.u[:, 0] / FT, r["x"]) < KIN_RTOL
    assert _rel(mo.q[:, 0], r["theta"]) < KIN_RTOL
    assert _rel(mo.q_dot[:, 0], r["theta_dot"]) < KIN_RTOL
    assert _rel(mo.q_ddot[:, 0], r["theta_ddot"]) < KIN_RTOL
    assert np.allclose(np.asarray(mo.q_dot[[0, -1], 0]), [0.388433, 1.207042], atol=5e-7)
    assert abs(float(mo.q_ddot[-1, 0]) - 2.980521) < 5e-7
    # theta_dot(0) = v/d exactly: the right angle at P
    assert abs(float(mo.q_dot[0, 0]) - SPEED / DEFAULTS["d"]) < 1e-12
    # the cylinder angle phi swings from 27.24 to 8.47 deg (mistake 9: not the "piston angle")
    assert _rel(mo.q[:, 1], ref.cylinder_angle(r["theta"])) < KIN_RTOL
    assert np.round(np.degrees(np.asarray(mo.q[[0, -1], 1])), 2).tolist() == [27.24, 8.47]


def test_linear_angle_law_vs_reference():
    """§3.2 eq. 3: theta = theta1 + (pi/6) t; x and x_dot from the engine with theta as the
    input, against the reference (x_dot falls from 0.3370 to 0.1084 ft/s)."""
    mo = linear_angle_motion(DEFAULTS, T7)
    r = ref.motion_linear_angle(T7)
    assert np.all(np.asarray(mo.status) == Status.CONVERGED)
    assert _rel(mo.u[:, 0], r["theta"]) < KIN_RTOL
    assert _rel(mo.q[:, 0] / FT, r["x"]) < KIN_RTOL
    assert _rel(mo.q_dot[:, 0] / FT, r["x_dot"]) < KIN_RTOL
    assert _rel(mo.q_ddot[:, 0] / FT, r["x_ddot"]) < KIN_RTOL
    assert np.round(np.asarray(mo.q_dot[[0, -1], 0]) / FT, 4).tolist() == [0.3370, 0.1084]


def test_eqs_2_and_3_contradict(cs_motion):
    """§3.2 mistake 5: a constant piston speed (eq. 2) and a constant gear rate (eq. 3) cannot
    both hold: under eq. 2 theta_dot runs 0.388 -> 1.207 rad/s, under eq. 3 x_dot runs
    0.337 -> 0.108 ft/s (not 0.25).  They agree only on the average: 90 deg in 3 s."""
    thd = np.asarray(cs_motion.q_dot[:, 0])
    assert np.allclose(np.asarray(cs_motion.u_dot[:, 0]), SPEED, rtol=1e-14)
    assert thd.min() < 0.75 * np.pi / 6 and thd.max() > 2.3 * np.pi / 6
    lin = linear_angle_motion(DEFAULTS, T7)
    xd = np.asarray(lin.q_dot[:, 0]) / FT
    assert xd.max() > 1.3 * REPORT["v"] and xd.min() < 0.45 * REPORT["v"]
    # same end points and duration
    assert abs(float(cs_motion.q[-1, 0] - cs_motion.q[0, 0]) - np.pi / 2) < 1e-12
    assert abs(float(lin.q[-1, 0]) - DEFAULTS["x2"]) < 1e-12


def test_eq5_is_right_as_a_function_of_theta(cs_motion):
    """§3.2 eqs. 5, 6: as functions of theta (rounded constants) they give the true theta_dot and
    theta_ddot under eq. 2 (to the 1e-4 rounding of the printed constants)."""
    th = cs_motion.q[:, 0]
    assert _rel(report_eq5(th), cs_motion.q_dot[:, 0]) < 2e-4
    assert _rel(report_eq6(th), cs_motion.q_ddot[:, 0]) < 5e-4
    assert np.allclose(report_eq6(th), ref.document_eq6(np.asarray(th)), rtol=1e-12)


def test_eq5_on_the_wrong_theta(cs_motion):
    """§3.2 eq. 5 + Listing 1 line 17 + Fig. 7 (mistake 6): eq. 5 evaluated on the *linear* theta
    of eq. 3 is not the derivative of the plotted theta: it integrates to 1.737910 rad = 99.57 deg
    over 3 s, not 90 deg; at t = 1.5 s it plots 0.4977 rad/s where the true value is 0.4533."""
    ang = float(report_plotted_omega_angle())
    assert abs(ang - ref.document_angle_from_plotted_omega()) < 1e-10
    # 99.5749 deg: the analysis (docs/seeds/landing_gear.md) gives it as 99.57 (99.5749)
    assert round(ang, 6) == 1.737910 and abs(np.degrees(ang) - 99.575) < 1e-3
    w = np.asarray(report_listing(jnp.asarray(T7))["omega"])
    assert round(w[3], 4) == 0.4977
    assert round(float(cs_motion.q_dot[10, 0]), 4) == 0.4533
    assert round(float(cs_motion.q[10, 0]), 4) == 1.7092 and round(float(report_listing(1.5)["theta"]), 4) == 1.8807


def test_listing_alpha_missing_factor(cs_motion):
    """Listing 1 lines 19-22 (mistake 7): anum2 lacks the factor f of eq. 6: at t = 3 s the listing
    gives alpha = 0.858 rad/s^2 where eq. 6 gives 2.980 (truth 2.9805); at t = 0 it gives 0.028
    where the truth is 0 (right-angle start)."""
    ls = report_listing(jnp.asarray(T7))
    ds = ref.document_script(T7)
    assert _rel(ls["alpha"], ds["alpha"]) < 1e-12 and _rel(ls["omega"], ds["omega"]) < 1e-12
    a = np.asarray(ls["alpha"])
    assert round(a[-1], 3) == 0.858 and round(a[0], 3) == 0.028
    assert round(float(report_eq6(ls["theta"][-1])), 3) == 2.980
    assert abs(float(cs_motion.q_ddot[0, 0])) < 1e-12
    assert round(float(cs_motion.q_ddot[-1, 0]), 4) == 2.9805


def test_x_is_linear_under_eq2(cs_motion):
    """§4.1 mistake 8: under the stated constant piston speed x(t) is exactly linear."""
    assert np.allclose(np.asarray(cs_motion.u_ddot[:, 0]), 0.0, atol=1e-15)
    assert np.allclose(np.asarray(cs_motion.u[:, 0]) / FT, 1.25 + 0.25 * T21, rtol=1e-14)
    # the same law through the public helper, at any times
    mo = constant_speed_motion(DEFAULTS, jnp.asarray(T21))
    assert _rel(mo.q, cs_motion.q) < 1e-14


# --------------------------------------------------------------------------- §1 requirement
def test_retraction_under_four_seconds():
    """§1 / §3.2: 90 deg clockwise in less than 4 s: 3.000 s at 0.25 ft/s (cross-checked by the
    reference's integral of dtheta / theta_dot); any speed above 0.1875 ft/s meets it."""
    t, rot = retraction_time(DEFAULTS)
    assert abs(t - 3.0) < 1e-12 and t < T_REQUIRED
    assert abs(float(rot) - np.pi / 2) < 1e-12
    assert abs(ref.retraction_time_by_integration() - t) < 1e-9
    t_min, _ = retraction_time(DEFAULTS, v=ref.min_speed_for_requirement() * FT)
    assert abs(t_min - T_REQUIRED) < 1e-12 and round(ref.min_speed_for_requirement(), 4) == 0.1875


def test_mechanical_advantage_worsens(result):
    """§4.1 mistake 10: theta_dot rises because the transmission angle falls (90 -> 18.8 deg): the
    cylinder needs 3.107 times the force per unit gear torque at gear-up; the moment arm
    dx/dtheta starts at d (right angle) and equals d h sin(theta)/x throughout."""
    out = result.outputs
    arm = np.asarray(out["moment_arm"][0])
    th = np.asarray(result.motion.q[:, 0])
    x = np.asarray(result.motion.u[:, 0])
    d, h = DEFAULTS["d"], DEFAULTS["h"]
    assert _rel(arm, d * h * np.sin(th) / x) < KIN_RTOL
    assert abs(arm[0] - d) < 1e-14
    assert round(float(out["force_ratio"][0][-1]), 3) == 3.107
    mu = np.asarray(out["transmission_angle"][0])
    assert _rel(arm, d * np.sin(mu)) < KIN_RTOL


# --------------------------------------------------------------------------- derivatives, scene
def test_gear_angle_parameter_derivatives():
    """eq. 4: d theta / d(d) and d theta / d(h) at mid-stroke (implicit) vs central differences of
    the reference's arccos inverse."""
    x = 0.5 * (DEFAULTS["x1"] + DEFAULTS["x2"])

    def th(d, h):
        p = {**DEFAULTS, "d": d, "h": h}
        return gear_angle(p, x)["theta"]

    g = jax.grad(th, argnums=(0, 1))(DEFAULTS["d"], DEFAULTS["h"])
    fd_d = central_diff(lambda d: ref.gear_angle(x / FT, d / FT, DEFAULTS["h"] / FT), DEFAULTS["d"], 1e-4)
    fd_h = central_diff(lambda h: ref.gear_angle(x / FT, DEFAULTS["d"] / FT, h / FT), DEFAULTS["h"], 1e-4)
    assert abs(float(g[0]) - fd_d) / abs(fd_d) < FD_RTOL
    assert abs(float(g[1]) - fd_h) / abs(fd_h) < FD_RTOL


def test_run_scene_columns(result):
    """``jaxmech run landing_gear``: input x, coordinates theta and phi, 21 converged rows."""
    assert get_scene("landing_gear") is SCENE
    cols = result.table()
    for c in ("t[s]", "x[m]", "x_dot[m/s]", "theta[rad]", "theta_dot[rad/s]", "theta_ddot[rad/s^2]",
              "phi[rad]", "transmission_angle[rad]", "moment_arm[m]", "force_ratio[-]", "status[-]"):
        assert c in cols, c
    assert all(len(v) == 21 for v in cols.values())
    assert np.all(cols["status[-]"] == Status.CONVERGED)
    assert abs(cols["t[s]"][-1] - 3.0) < 1e-12
    # the named points close the loop: |C - P| = x
    mech, p = SCENE.mechanism, result.params
    q, u = result.motion.q, result.motion.u
    CP = [abs(complex(mech.point("C", q[i], u[i], p) - mech.point("P", q[i], u[i], p))) for i in (0, 10, 20)]
    assert np.allclose(CP, np.asarray(u[[0, 10, 20], 0]), rtol=1e-13)


def test_drawing_and_validation(result):
    spec = SCENE.drawing(result.params)
    names = set(SCENE.mechanism.points)
    assert set(spec) <= {"links", "ground", "slots", "chords", "trace", "transmission", "output"}
    assert all(a in names and b in names for a, b in spec["links"])
    assert set(spec["ground"]) <= names and set(spec["trace"]) <= names
    with pytest.raises(ValueError, match="x2 must exceed x1"):
        SCENE.params(x2=0.3)
    with pytest.raises(ValueError, match="does not fit"):
        SCENE.params(x2=0.7)
