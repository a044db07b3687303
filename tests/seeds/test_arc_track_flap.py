"""Seed 003, circular-arc-track flap (Arslan 2022): the engine against the thesis's tables
and against the independent numpy reference ``reference_arc_track_flap.py``.

Reading that reproduces Table 3 (docs/seeds/arc_track_flap.md, Section b): per screw jack,
HALF the air moment (M12 / n_jacks, n_jacks = 2) but the WHOLE flap weight (12 kg);
cruise at the closed flap; landing closed with M12_min = 220 N m and deployed with
M12_max = 650 N m (linear in s34); the landing G12G pair printed in algebraic min/max order.
"""

import jax

jax.config.update("jax_enable_x64", True)

import math  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import reference_arc_track_flap as ref  # noqa: E402

from jaxmech.scenes import get_scene, run_scene  # noqa: E402
from jaxmech.scenes import arc_track_flap as atf  # noqa: E402

REL = 1e-9  # engine vs independent reference
MM, DEG = 1e-3, math.pi / 180

pytestmark = pytest.mark.filterwarnings("error")


@pytest.fixture(scope="module")
def p():
    return atf.params()


@pytest.fixture(scope="module")
def runs():
    """``run_scene`` over the stroke, 21 points, for both flight scenarios (one compile)."""
    return {"cruise": run_scene(atf.SCENE, 21), "landing": run_scene(atf.LANDING_SCENE, 21)}


def _close(a, b, rel=REL, atol=0.0):
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=rel, atol=atol)


# --------------------------------------------------------------------------- parameters
def test_defaults_are_the_thesis_case_study(p):
    """Table 2 inputs (yellow cells) and Section 5.2 moments, in SI; reference params()."""
    r = ref.params()
    for k in ("a1", "a2", "a3", "alpha0", "b1", "c1", "beta1", "beta2", "beta3", "x_D", "y_D",
              "m_flap", "g", "r", "l", "f", "n_jacks"):
        assert p[k] == pytest.approx(r[k], rel=1e-15), k
    assert (p["M12_i"], p["M12_f"], p["weight_share"]) == (750.0, 750.0, 1.0)
    assert atf.params("landing")["M12_i"] == 220.0 and atf.params("landing")["M12_f"] == 650.0
    assert atf.SCENE.speed == 0.035  # Table 2: s34_dot = 35 mm/s
    assert get_scene("arc_track_flap") is atf.SCENE


def test_landing_case_is_a_scene_of_its_own(runs, tmp_path):
    """``jaxmech run arc_track_flap_landing``: its own registry name, title (the summary
    header) and file names, and its air moment from 220 N m (closed) to 650 N m (deployed),
    halved per jack (Section 5.2)."""
    from jaxmech.cli.commands import write_csv

    scene = get_scene("arc_track_flap_landing")
    assert scene is atf.LANDING_SCENE and scene.name == "arc_track_flap_landing"
    res = runs["landing"]
    m12 = np.asarray(res.outputs["M12"][0])
    _close(m12[[0, -1]], [110.0, 325.0], rel=1e-12)
    head = res.summary().splitlines()[0]
    assert head.startswith("scene arc_track_flap_landing: ") and "landing air moment 220 -> 650 N m" in head
    assert "750" not in head and "cruise air moment 750 N m" in runs["cruise"].summary().splitlines()[0]
    write_csv(res.table(), tmp_path / f"{scene.name}.csv")  # the name `jaxmech run` gives its CSV
    assert (tmp_path / "arc_track_flap_landing.csv").read_text().splitlines()[0].split(",")[0] == "t[s]"


# --------------------------------------------------------------------------- Table 2
def test_table2_every_computed_entry(p):
    """Table 2: a3 = 250, s34_i = 80.3, delta_s = 144.3, g2 = 122.7, p2 = 197.1,
    q2 = 319.5 mm, alpha2 = 14 deg -- from the engine's closed pose, to the printed digits."""
    t2 = atf.table2(p)
    for k, printed in ref.DOC_TABLE2.items():
        digits = 0 if k in ("a3", "alpha2") else 1
        assert round(t2[k], digits) == printed, (k, t2[k], printed)
    _close([t2[k] for k in ref.DOC_TABLE2], [ref.table2(ref.params())[k] for k in ref.DOC_TABLE2], rel=1e-12)


# --------------------------------------------------------------------------- Table 3
def test_table3_every_entry_with_the_reading(p):
    """Table 3 (N, N mm), every entry to the printed digits.  Reading: M12/2 per jack and
    the full 12 kg weight; cruise at the closed flap; landing (closed, M12_min) /
    (deployed, M12_max); landing G12G printed as algebraic (min, max) = (deployed, closed)."""
    assert p["n_jacks"] == 2 and p["weight_share"] == 1.0
    t3 = atf.table3(p)
    for k, printed in ref.DOC_TABLE3["cruise"].items():
        assert round(t3["cruise"][k]) == printed, (k, t3["cruise"][k])
    for k, printed in ref.DOC_TABLE3["landing"].items():
        closed, deployed = t3["landing"][k]
        got = (round(closed), round(deployed))
        if k == "G12G":  # Section e, mistake 4: algebraic min/max order
            got = (round(min(closed, deployed)), round(max(closed, deployed)))
            assert deployed < closed
        assert got == tuple(printed), (k, closed, deployed, printed)
    # F34y' = F43y' = 0: the nut force is along the screw (massless nut and screw)
    assert abs(t3["cruise"]["F34y"]) < 1e-9 and max(map(abs, t3["landing"]["F34y"])) < 1e-9


def test_table3_other_readings_miss(p):
    """Table 3 needs exactly the mixed reading: a consistent half split of the weight, or the
    full moment on one jack, misses the printed cruise F_input = 1623 N (Section e, mistake 5)."""
    half = atf.table3({**p, "weight_share": 0.5})["cruise"]
    full = atf.table3({**p, "n_jacks": 1.0})["cruise"]
    assert round(half["F_input"]) == 1631 and round(half["T_R"]) == 4723
    assert round(full["F_input"]) == 3261
    assert round(half["G12G"]) != -2204 and round(full["G12F"]) != 3533


def test_text_numbers_motor_torque(p, runs):
    """Section 5.2: "required maximum motor torque is 4.7 N m", 7.1 N m with safety 1.5:
    the largest T_R over the stroke of both scenarios (cruise, closed flap)."""
    peak = max(float(np.max(r.outputs["T_R"][0])) for r in runs.values())
    assert round(peak, 1) == 4.7 and round(1.5 * peak, 1) == 7.1
    assert float(runs["cruise"].outputs["T_R"][0][0]) == pytest.approx(peak, rel=1e-12)


# --------------------------------------------------------------------------- forces over the stroke
@pytest.mark.parametrize("scenario", ["cruise", "landing"])
def test_forces_over_stroke_match_reference(scenario):
    """Eqs. (3.5.1), (3.4.7)-(3.4.16), (3.6.9)-(3.6.10) over the stroke (Figs. 46, 48):
    engine (loop + unit-gradient slots, multipliers by virtual power) vs the closed form."""
    pe = atf.params(scenario)
    sw = ref.stroke_sweep(ref.params(), scenario, n=61)
    f = atf.forces(pe, sw["s34"])
    for k in ("F_input", "G12G", "G12F", "T_R", "T_L", "M12"):
        _close(f[k], sw[k], atol=1e-12 * np.max(np.abs(sw[k])))
    _close(f["theta12"], ref.positions(sw["s34"], ref.params())["theta12"], rel=1e-12)


def test_multipliers_are_the_slot_reactions(p):
    """Section 3.4 in the engine's form: unit-gradient slot rows, so -lambda_G = G12G and
    -lambda_F = G12F in newtons; tau = F_input; F42 = -lambda_A along the screw."""
    s = ref.design(ref.params())["s34_i"]
    mf = ref.statics_multiplier_form(s, 375.0, ref.params())
    f = atf.forces(p, s)
    lam = f["lam"][0]
    _close([lam[2], lam[3], f["F_input"][0]], [mf["lam_G"], mf["lam_F"], mf["tau"]])
    _close(lam[0] + 1j * lam[1], mf["lam_A"])
    # unit gradients of the slot rows in x = (q, u) at the solution
    q = jnp.asarray([f["theta12"][0], f["theta13"][0], 0.0, 0.0])
    pj = {k: jnp.asarray(v) for k, v in p.items()}
    jac = jax.jit(jax.jacfwd(atf.MECHANISM.residual))(q, jnp.asarray([s]), pj)
    _close(np.linalg.norm(np.asarray(jac)[2:], axis=1), [1.0, 1.0], rel=1e-12)


# --------------------------------------------------------------------------- run_scene
def test_run_scene_table_columns_and_values(runs):
    """``jaxmech run arc_track_flap``: the CSV columns and their values vs the reference."""
    for scenario, res in runs.items():
        tab = res.table()
        for col in ("s34[m]", "theta12[rad]", "theta13[rad]", "theta12_dot[rad/s]", "theta12_ddot[rad/s^2]",
                    "theta13_dot[rad/s]", "theta13_ddot[rad/s^2]", "F_input[N]", "G12G[N]", "G12F[N]",
                    "T_R[N m]", "T_L[N m]"):
            assert col in tab, col
        assert len(tab["s34[m]"]) == 21 and np.all(tab["status[-]"] == 0)
        st = ref.statics(tab["s34[m]"], ref.air_moment(tab["s34[m]"], scenario, ref.params()), ref.params())
        for k in ("F_input", "G12G", "G12F"):
            _close(tab[f"{k}[N]"], st[k])
        _close(tab["T_R[N m]"], st["T_R"])
        _close(tab["T_L[N m]"], st["T_L"])


def test_accelerations_below_a_tenth_of_a_percent_of_g(p, runs):
    """Section 5.2 / Fig. 31: |a_A|, |a_D| < 0.1 % g at 35 mm/s (max 0.0948 % for D, closed),
    from the engine's implicit second derivatives; vs the reference's rigid-rotation form."""
    res = runs["cruise"]
    s = np.asarray(res.motion.u[:, 0])
    kin = ref.kinematics(s, ref.params())
    aA, aD = (np.asarray(res.outputs[k][0]) for k in ("aA_over_g", "aD_over_g"))
    _close(aA, kin["aA_over_g"], rel=1e-8)
    _close(aD, kin["aD_over_g"], rel=1e-8)
    assert np.max(aA) < 1e-3 and np.max(aD) < 1e-3
    assert round(100 * float(np.max(aD)), 4) == 0.0948
    acc = atf.accelerations(p, n=21)
    _close(acc["aD_over_g"], aD, rel=1e-12)


# --------------------------------------------------------------------------- corrections
def test_eq_3_3_2_omega13(runs):
    """Eq. (3.3.2) prints omega13 = (s34_dot/s34) tan(psi); the engine's theta13_dot is
    s34_dot / (s34 tan psi) = -0.137504 rad/s at s34_i (Fig. 46), not -1.38315."""
    tab = runs["cruise"].table()
    s, sd = tab["s34[m]"][0], tab["s34_dot[m/s]"][0]
    psi = tab["theta13[rad]"][0] - tab["theta12[rad]"][0]
    w13 = tab["theta13_dot[rad/s]"][0]
    assert round(w13, 6) == -0.137504
    _close(w13, sd / (s * math.tan(psi)), rel=1e-10)
    assert round(sd / s * math.tan(psi), 5) == -1.38315


def test_eq_3_3_3_alpha12_sign(p, runs):
    """Eq. (3.3.3)'s second term has the wrong sign: the engine's theta12_ddot at s34_i is
    -0.014002 rad/s^2 (the printed formula and Fig. 46: +0.014002), so Fig. 46's a_A
    components are wrong: engine (2.4582, -6.0613) mm/s^2, sheet (-4.1828, -5.0286)."""
    res = runs["cruise"]
    tab = res.table()
    a12 = tab["theta12_ddot[rad/s^2]"][0]
    assert round(a12, 6) == -0.014002
    doc = ref.kinematics(tab["s34[m]"][0], ref.params(), doc_alpha12_sign=True)
    assert round(float(doc["alpha12"]), 6) == 0.014002
    aA = complex(res.motion.points["A"][2][0]) / MM
    assert (round(aA.real, 4), round(aA.imag, 4)) == (2.4582, -6.0613)
    assert (round(doc["aA"].real / MM, 4), round(doc["aA"].imag / MM, 4)) == (-4.1828, -5.0286)
    # |a| does not depend on the sign of alpha12: the 0.1 % g conclusion stands
    assert abs(aA) == pytest.approx(abs(doc["aA"]) / MM, rel=1e-10)


def test_section_3_6_lead_angle(p):
    """Section 3.6 prints tan(lambda) = 1/(2 pi r); it is l/(2 pi r) = 0.0796 (4.55 deg):
    only that gives Table 3's T_R = 4700 and T_L = 526 N mm for L = 1622.9 N."""
    L = 1622.897651956071
    T_R, T_L = (float(x) / MM for x in atf.screw_torques(L, p))
    assert (round(T_R), round(T_L)) == (4700, 526)
    tl = p["l"] / (2 * math.pi * p["r"])
    assert round(math.degrees(math.atan(tl)), 2) == 4.55
    r_mm, f = p["r"] / MM, p["f"]
    for tan_l in (1 / (2 * math.pi * r_mm), 1 / (2 * math.pi * p["r"])):  # printed, either unit
        assert round(r_mm * L * (f + tan_l) / (1 - f * tan_l)) != 4700


def test_section_3_4_signs_of_3_4_11(p):
    """Eqs. (3.4.11), (3.4.15): the chain is F_input = F42 = -F24 = G13, so along the screw
    F24 + F_input = 0 (printed: F24 - F_input = 0).  Engine: F24 = lambda_A = -F_input e_s."""
    f = atf.forces(p, atf.geometry(p)["s34_i"])
    lam = f["lam"][0]
    F24 = lam[0] + 1j * lam[1]
    e_s = np.exp(1j * (p["alpha0"] + f["theta13"][0]))
    _close(F24, -f["F_input"][0] * e_s, rel=1e-12)


def test_section_5_2_weight_share_of_f_input(p):
    """Section 5.2: "weight contributes at most 8 % of F_input" holds only with the sheet's
    metric |W|/(M12 + |W|) (7.37 %); against eq. (3.5.1)'s numerator M12 + m g r_D cos(theta_D)
    it reaches 8.64 % (landing, deployed)."""
    pe = atf.params("landing")
    f = atf.forces(pe)
    W = f["F_input"] - f["M12"] / (pe["a2"] * np.sin(f["theta13"] - f["theta12"]))  # weight part of F_input
    share = np.abs(W / f["F_input"])
    assert round(100 * float(np.max(share)), 2) == 8.64 and int(np.argmax(share)) == len(share) - 1
    Wm = np.abs(W * pe["a2"] * np.sin(f["theta13"] - f["theta12"]))
    sheet = Wm / (f["M12"] + Wm)
    assert round(100 * float(np.max(sheet)), 2) == 7.37


def test_atan2_argument_order_and_landing_interpolation(p):
    """theta_D = ATAN2(x; y) in Excel's order is arctan2(y, x): theta_D,i = 95.04 deg.  Landing
    moments are linear in s34 (Fig. 48: 124 896 N mm per jack at s34_i + 10 mm), not in theta12."""
    assert round(math.degrees(float(atf.geometry(p)["theta_D_i"])), 2) == 95.04
    assert round(math.degrees(math.atan2(p["x_D"], p["y_D"])), 2) == -5.04  # the other order
    pe = atf.params("landing")
    s = float(atf.geometry(pe)["s34_i"]) + 0.010
    assert round(float(atf.air_moment(s, pe)) / MM) == 124896


# --------------------------------------------------------------------------- validity (Sec. 5.3)
def test_validity_checks_raise_with_the_fix(p):
    """Section 5.3's red cells as ValueError, wired as Scene.validate."""
    with pytest.raises(ValueError, match=r"c1 = .* must be smaller than b1.*lower c1 or raise b1"):
        atf.SCENE.params(c1=0.36)
    with pytest.raises(ValueError, match=r"longer than the screw.*a3 = 0\.2 m.*lengthen the screw"):
        atf.SCENE.params(a3=0.2)
    with pytest.raises(ValueError, match=r"s34 = 0\.07 m is outside the slot range.*leave their slots"):
        atf.forces(p, 0.07)
    with pytest.raises(ValueError, match=r"s34 = 0\.23 m is outside"):
        atf.validate(p, [0.1, 0.23])
    with pytest.raises(ValueError, match=r"a1 = .* must exceed a2"):
        atf.SCENE.params(a2=0.3)
    with pytest.raises(ValueError, match="scenario must be one of"):
        atf.scene_for("takeoff")
    atf.validate(p, [float(atf.geometry(p)["s34_i"]), float(atf.geometry(p)["s34_f"])])  # ends are fine


# --------------------------------------------------------------------------- design (Ch. 4)
@pytest.mark.parametrize("inputs", [atf.THESIS_INPUTS, {**atf.THESIS_INPUTS, "a2": 0.2, "beta3": 40 * DEG,
                                                         "a1": 0.3}])
def test_design_method_round_trip(inputs):
    """Chapter 4: collinear initial and final nut positions, delta s = 2 a2 sin(beta3/2):
    the engine turns the flap by exactly beta3, theta13_f = theta13_i, the pins sit at the
    slot ends, and A_i, A_f lie on the screw line at s34_i and s34_i + delta s."""
    pd = atf.design(**inputs)
    if inputs is atf.THESIS_INPUTS:
        assert pd == {k: pytest.approx(v, rel=1e-15) for k, v in atf.SCENE.defaults.items()}
        assert pd["a3"] == 0.25  # step 9: 1.1 s34_f rounded up to cm
    g = atf.geometry(pd)
    _close(g["delta_s"], 2 * pd["a2"] * math.sin(pd["beta3"] / 2), rel=1e-14)
    f = atf.forces(pd, [float(g["s34_i"]), float(g["s34_f"])])
    _close(f["theta12"][1] - f["theta12"][0], pd["beta3"], rel=1e-12)
    _close(f["theta13"][1], f["theta13"][0], rel=1e-12)
    _close(f["theta12"][0], g["theta12_i"], rel=1e-12)  # closed form acos(h/a1) - beta3/2
    pts = f["points"]
    _close(pts["F"], [g["F1_i"], g["F1_f"]], rel=1e-12)
    _close(pts["G"], [g["F2_i"], g["F2_f"]], rel=1e-12)
    _close(pts["A"], [g["A_i"], g["A_f"]], rel=1e-12)
    assert pd["a3"] > float(g["s34_f"])


def test_fairing_depth(p):
    """Section 5.2 / Ch. 4: the arc track saves about h = a2 cos(beta3/2) = 228.89 mm of
    fairing depth (least distance A0 - screw line, at both stroke ends); the lowest part
    is the screw tip B at y = 211.59 mm."""
    fd = atf.fairing_depth(p)
    r = ref.fairing_depth(ref.params())
    assert round(fd["h"] / MM, 2) == 228.89
    _close(fd["screw_line_distance"], fd["h"], rel=1e-12)
    assert fd["lowest_part"] == "screw tip B" == r["lowest_part"]
    assert round(fd["y_min"] / MM, 2) == 211.59
    _close(fd["y_min"], r["y_min"], rel=1e-12)


def test_drawing_spec_names_defined_points(p):
    """The drawing spec refers to the mechanism's named points or fixed complex numbers;
    the chord is A_i A_f of the design method."""
    d = atf.SCENE.drawing(p)
    assert {"links", "ground", "slots", "chords", "trace"} <= set(d)
    used = {n for pair in d["links"] + d["chords"] for n in pair} | set(d["ground"]) | set(d["trace"])
    used |= {s["centre"] for s in d["slots"] if "centre" in s} | {n for s in d["slots"] if "line" in s for n in s["line"]}
    assert {n for n in used if isinstance(n, str)} <= set(atf.MECHANISM.points)
    assert sorted(s["radius"] for s in d["slots"] if "radius" in s) == [p["c1"], p["b1"]]
    g = ref.design(ref.params())
    _close(d["chords"][0], [g["A_i"], g["A_f"]], rel=1e-12)
