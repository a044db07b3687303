"""The classic four-bar and slider-crank scenes and the landing gear seed scene, written again
as linkage files (examples/linkages/fourbar.toml, slider_crank.toml, landing_gear.toml), give
the hand-written scenes' tables to round-off.

Each file is drawn at its scene's stroke start with its default parameters; its scene
(``scene_from_file``) has other names and conventions (absolute link angles ``theta_<link>``
from the link's tree-entry joint, a slider's travel, an actuator's length), mapped here onto
the hand-written scene's columns: every column of the hand-written table is compared, its
outputs (transmission angle, moment arm, force ratio...) recomputed from the linkage's
coordinates.  The linkage scenes also carry the drive's effort and every joint's reaction,
which the hand-written scenes do not: they are checked against independent references
built from the hand-written scene's kinematics (numpy Newton-Euler for the four-bar with
masses and gravity, closed forms for the slider-crank's piston force and the gear's torque).

Tolerance (``RTOL``, relative to each column's largest magnitude over the stroke).  The two
scenes solve the same loop written differently (other term order and signs, lengths read off
the drawing's decimal coordinates, the drive's constants folded differently: the landing
gear's sample times differ by an ulp), so each converges to its own round-off: the loop
residual's rounding, ~eps times the loop's terms, magnified by the loop's conditioning (the
gear's transmission angle falls to 18.8 deg at gear-up) and by the two differentiations to
the accelerations.  Measured (x64, CPU), the largest difference of any compared quantity,
relative to its scale: four-bar 5.0e-16 (2.5 ulps), slider-crank 5.3e-16 (3 ulps, a joint
reaction), landing gear 5.8e-15 (50 ulps, phi_ddot), the four-bar's joint reactions against
numpy's Newton-Euler 1e-15.  ``RTOL = 1e-13`` (~450 ulps) leaves a factor of 17 for another
build's rounding, and is still far below any real discrepancy: a file's coordinate off in its
13th digit, a sign or a branch shows as 1e-12 or (much) more.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
import pytest

from jaxmech.linkage.files import load_linkage
from jaxmech.scenes import get_scene, run_scene
from jaxmech.scenes.linkage_scene import scene_from_file

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "linkages"
#: Samples per stroke: the counts other tests run these hand-written scenes with (their
#: compiled strokes are shared: tests/test_design.py, tests/seeds/test_landing_gear.py).
POINTS = {"fourbar": 41, "slider_crank": 41, "landing_gear": 21}
SCENES = tuple(POINTS)
RTOL = 1e-13  # see the module docstring
EPS = np.finfo(float).eps


@functools.lru_cache(maxsize=None)
def linkage(name: str):
    return scene_from_file(EXAMPLES / f"{name}.toml")


@functools.lru_cache(maxsize=None)
def linkage_run(name: str, **overrides):
    # parameters are traced: a run with other masses or loads compiles nothing new
    return run_scene(linkage(name), points=POINTS[name], **overrides)


@functools.lru_cache(maxsize=None)
def hand_run(name: str):
    return run_scene(get_scene(name), points=POINTS[name])


def assert_close(actual, expected, what: str, scale=None):
    """``max |actual - expected| <= RTOL * scale`` (scale: ``max |expected|`` by default;
    zero: both exactly zero)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, what
    assert np.all(np.isfinite(actual)) and np.all(np.isfinite(expected)), what
    scale = np.max(np.abs(expected)) if scale is None else scale
    if scale == 0:  # a column zero throughout (the drive's acceleration): zero in both
        assert np.all(actual == 0), what
        return
    err = np.max(np.abs(actual - expected)) / scale
    assert err <= RTOL, f"{what}: differs by {err:.3g} of its scale {scale:.6g} (tolerance {RTOL:g})"


# --------------------------------------------------------------------------- the linkage's table as the hand-written scene's
def _rates(cols, hand, lk, table, sign=1.0, shift=0.0, unit="rad"):
    cols[f"{hand}[{unit}]"] = sign * table[f"{lk}[{unit}]"] + shift
    cols[f"{hand}_dot[{unit}/s]"] = sign * table[f"{lk}_dot[{unit}/s]"]
    cols[f"{hand}_ddot[{unit}/s^2]"] = sign * table[f"{lk}_ddot[{unit}/s^2]"]


def fourbar_columns(res) -> dict:
    # theta2 = theta_crank (O2 -> A), theta3 = theta_coupler (A -> B), theta4 = theta_rocker (O4 -> B)
    L = res.table()
    cols = {"t[s]": L["t[s]"], "status[-]": L["status[-]"]}
    for hand, lk in (("theta2", "theta_crank"), ("theta3", "theta_coupler"), ("theta4", "theta_rocker")):
        _rates(cols, hand, lk, L)
    th3, th4 = L["theta_coupler[rad]"], L["theta_rocker[rad]"]
    cols["transmission_angle[rad]"] = np.arccos(np.abs(np.cos(th4 - th3)))  # at B, coupler to rocker
    return cols


def slider_crank_columns(res) -> dict:
    # theta2 = theta_crank, theta3 = theta_rod (A -> B); x = B's x: the guide's base (B at
    # the drawing) plus the piston's travel along +x
    L = res.table()
    cols = {"t[s]": L["t[s]"], "status[-]": L["status[-]"]}
    _rates(cols, "theta2", "theta_crank", L)
    _rates(cols, "theta3", "theta_rod", L)
    _rates(cols, "x", "s_piston", L, shift=res.params["x_B_on_ground"], unit="m")
    return cols


def landing_gear_columns(res) -> dict:
    # x = cyl (C to P); the clockwise gear angle theta = -theta_leg (B -> P, CCW); phi (P -> C)
    # = theta_cyl (C -> P) + pi: the cylinder stays in the third quadrant, no wrap needed
    from jaxmech.scenes.landing_gear import FT

    L = res.table()
    cols = {"t[s]": L["t[s]"], "status[-]": L["status[-]"]}
    _rates(cols, "x", "cyl", L, unit="m")
    _rates(cols, "theta", "theta_leg", L, sign=-1.0)
    _rates(cols, "phi", "theta_cyl", L, shift=np.pi)
    theta, phi = cols["theta[rad]"], cols["phi[rad]"]
    arm = -1.0 / np.asarray(res.motion.dq_du)[:, 0, 0]  # dx/dtheta = -1 / (dtheta_leg/dcyl)
    cols.update({
        "transmission_angle[rad]": np.pi - theta - phi,  # at P, P -> B to P -> C
        "moment_arm[m]": arm,
        "force_ratio[-]": arm[0] / arm,
        "x_ft[ft]": cols["x[m]"] / FT,
        "theta_deg[deg]": np.degrees(theta),
        "phi_deg[deg]": np.degrees(phi),
    })
    return cols


AS_HAND = {"fourbar": fourbar_columns, "slider_crank": slider_crank_columns, "landing_gear": landing_gear_columns}

#: The hand-written scene's parameters as the linkage's (the drawing's lengths, to the ulp).
SAME_PARAMETERS = {
    "fourbar": {"a": "len_O2_A", "b": "len_A_B", "c": "len_O4_B", "d": "x_O4"},
    "slider_crank": {"a": "len_O2_A", "b": "len_A_B", "e": "y_B_on_ground"},
    "landing_gear": {"d": "len_B_P", "h": "x_C", "AB": "len_B_A", "beta": "ang_P_B_A"},
}
#: What is zero in both: ground points on the x axis, straight links, the guide's direction.
ZERO_PARAMETERS = {
    "fourbar": ("x_O2", "y_O2", "y_O4", "ang_B_A_P"),
    "slider_crank": ("x_O2", "y_O2", "ang_guide_piston"),
    "landing_gear": ("x_B", "y_B", "y_C"),
}


# --------------------------------------------------------------------------- the tests
@pytest.mark.parametrize("name", SCENES)
def test_file_is_the_scene(name):
    """The drawing's parameters, stroke and speed are the hand-written scene's defaults."""
    mine, hand = linkage(name), get_scene(name)
    p, ph = mine.defaults, hand.defaults
    for h, k in SAME_PARAMETERS[name].items():
        assert p[k] == pytest.approx(ph[h], rel=2 * EPS, abs=2 * EPS), (h, k)
    for k in ZERO_PARAMETERS[name]:
        assert abs(p[k]) <= 2 * EPS, k
    assert tuple(map(float, mine.stroke(p))) == tuple(map(float, hand.stroke(ph)))
    assert mine.speed == hand.speed


@pytest.mark.parametrize("name", SCENES)
def test_table_matches_hand_written_scene(name):
    """Every column of the hand-written scene's table, from the linkage's, to round-off."""
    hand = hand_run(name).table()
    mine = AS_HAND[name](linkage_run(name))
    assert set(mine) == set(hand)  # every column of the hand-written table is compared
    assert np.all(hand["status[-]"] == 0)
    np.testing.assert_array_equal(mine["status[-]"], hand["status[-]"])
    for k, v in hand.items():
        if k != "status[-]":
            assert_close(mine[k], v, f"{name}: {k}")


@pytest.mark.parametrize("name", SCENES)
def test_points_match_hand_written_scene(name):
    """Every point both scenes name: positions, velocities and accelerations (each relative
    to its largest magnitude over all those points)."""
    mine, hand = linkage_run(name).motion.points, hand_run(name).motion.points
    common = sorted(set(mine) & set(hand))
    assert len(common) == len(hand), f"{name}: the linkage lacks {set(hand) - set(mine)}"
    for k, what in enumerate(("position", "velocity", "acceleration")):
        scale = max(np.max(np.abs(np.asarray(hand[x][k]))) for x in common)
        for x in common:
            assert_close(mine[x][k], hand[x][k], f"{name}: {what} of {x}", scale=scale)


@pytest.mark.parametrize("name", SCENES)
def test_unloaded_efforts_are_zero(name):
    """Massless, unloaded (as the hand-written scenes): the drive's effort and every joint's
    reaction are in the table and zero, exactly, at every sample."""
    lk = load_linkage(EXAMPLES / f"{name}.toml")
    table = linkage_run(name).table()
    expected = [f"effort_{lk.mechanism.inputs[0]}"]
    for j in lk.joints:
        col = re.sub(r"\W+", "_", j).strip("_")
        expected += [f"F_{col}_x", f"F_{col}_y"] + ([f"M_{col}"] if " on " in j else [])  # a slider's moment
    loads = [k for k in table if k.startswith(("effort_", "F_", "M_"))]
    assert [k.split("[")[0] for k in loads] == expected
    for k in loads:
        assert np.all(table[k] == 0.0), k


# The four-bar's bodies for the dynamics check: uniform bars, (mass kg, length m), and the
# pins on each with the sign of the pin's reaction on it (a joint's reaction is the force of
# its first body on its second: O2 ground on crank, A crank on coupler, B coupler on rocker,
# O4 ground on rocker).
FOURBAR_BODIES = {
    "crank": (1.0, 1.0, (("O2", 1.0), ("A", -1.0))),
    "coupler": (3.0, 3.0, (("A", 1.0), ("B", -1.0))),
    "rocker": (2.5, 2.5, (("B", 1.0), ("O4", 1.0))),
}
FOURBAR_ENDS = {"crank": ("O2", "A"), "coupler": ("A", "B"), "rocker": ("O4", "B")}
FOURBAR_ANGLES = {"crank": "theta2", "coupler": "theta3", "rocker": "theta4"}
G = 9.81


def test_fourbar_effort_and_reactions_newton_euler():
    """The four-bar with uniform bars and gravity (set as parameters of the file's scene):
    the crank torque and the four pins' reactions against the per-body Newton-Euler
    equations solved with numpy on the hand-written scene's kinematics (its points' positions
    and accelerations, its angular accelerations)."""
    over, inertia = {"g": G}, {}
    for link, (m, length, _) in FOURBAR_BODIES.items():
        # a uniform bar's inertia follows from its length in the linkage (derived)
        over[f"m_{link}"], inertia[link] = m, m * length**2 / 12
    table = linkage_run("fourbar", **over).table()
    hand = hand_run("fourbar")
    ht = hand.table()
    pos, vel, acc = ({k: np.asarray(v[i]) for k, v in hand.motion.points.items()} for i in range(3))
    n = len(ht["t[s]"])
    # unknowns: the reactions at O2, A, B, O4 (Fx, Fy each) and the crank torque; per body
    # rows m a_G - m g = sum F, J alpha = sum (r - G) x F (+ the torque on the crank)
    col = {"O2": 0, "A": 2, "B": 4, "O4": 6}
    A = np.zeros((n, 9, 9))
    rhs = np.zeros((n, 9))
    gvec = -1j * G
    power = 0.0  # the reference's own check: tau omega = sum m a_G . v_G + J alpha omega - m g . v_G
    for k, (link, (m, _, pins)) in enumerate(FOURBAR_BODIES.items()):
        e1, e2 = FOURBAR_ENDS[link]
        G_, vG, aG = (0.5 * (x[e1] + x[e2]) for x in (pos, vel, acc))  # the bar's midpoint
        omega, alpha = ht[f"{FOURBAR_ANGLES[link]}_dot[rad/s]"], ht[f"{FOURBAR_ANGLES[link]}_ddot[rad/s^2]"]
        J = inertia[link]
        f = m * (aG - gvec)
        rhs[:, 3 * k], rhs[:, 3 * k + 1], rhs[:, 3 * k + 2] = f.real, f.imag, J * alpha
        for joint, sign in pins:
            c, r = col[joint], pos[joint] - G_
            A[:, 3 * k, c] = A[:, 3 * k + 1, c + 1] = sign
            A[:, 3 * k + 2, c], A[:, 3 * k + 2, c + 1] = -sign * r.imag, sign * r.real  # r x F
        power = power + np.real(np.conj(vG) * f) + J * alpha * omega
    A[:, 2, 8] = 1.0  # the drive's torque on the crank
    z = np.linalg.solve(A, rhs[..., None])[..., 0]
    assert_close(z[:, 8] * ht["theta2_dot[rad/s]"], power, "the reference's torque against the power balance")
    assert_close(table["effort_theta_crank[N m]"], z[:, 8], "crank torque")
    for joint, c in col.items():
        F = z[:, c] + 1j * z[:, c + 1]
        scale = np.max(np.abs(F))  # x and y against the force's magnitude
        assert_close(table[f"F_{joint}_x[N]"], F.real, f"F_{joint}_x", scale)
        assert_close(table[f"F_{joint}_y[N]"], F.imag, f"F_{joint}_y", scale)


def test_slider_crank_piston_force():
    """A force (Fx, Fy) on the piston (the file's Fx_B, Fy_B): the rod is a two-force member,
    so every pin carries T e^{i theta3} with T = -Fx / cos(theta3); the guide takes the rest
    normal to itself, with no moment; the crank torque is -Fx x_dot / omega (virtual power)."""
    Fx, Fy = -100.0, 30.0
    table = linkage_run("slider_crank", Fx_B=Fx, Fy_B=Fy).table()
    ht = hand_run("slider_crank").table()
    th3 = ht["theta3[rad]"]
    rod = -Fx / np.cos(th3) * np.exp(1j * th3)
    scale = np.max(np.abs(rod))
    assert_close(table["effort_theta_crank[N m]"], -Fx * ht["x_dot[m/s]"] / ht["theta2_dot[rad/s]"], "crank torque")
    for joint in ("O2", "A", "B"):
        assert_close(table[f"F_{joint}_x[N]"], rod.real, f"F_{joint}_x", scale)
        assert_close(table[f"F_{joint}_y[N]"], rod.imag, f"F_{joint}_y", scale)
    assert_close(table["F_piston_on_ground_x[N]"], 0.0 * th3, "guide force along the guide", scale)
    assert_close(table["F_piston_on_ground_y[N]"], -Fy + Fx * np.tan(th3), "guide's normal force")
    # (the moment against the rod's force times its length, 0.35 m)
    assert_close(table["M_piston_on_ground[N m]"], 0.0 * th3, "guide's moment", scale * 0.35)


def test_landing_gear_cylinder_force():
    """A torque M on the gear leg (the file's M_leg, counter-clockwise): the cylinder pushes
    with M / (dx/dtheta), the hand-written scene's moment arm, along C -> P, and the pivot B
    takes the opposite force."""
    M = 50.0
    table = linkage_run("landing_gear", M_leg=M).table()
    ht = hand_run("landing_gear").table()
    push = M / ht["moment_arm[m]"]
    assert_close(table["effort_cyl[N]"], push, "cylinder force")
    F = push * -np.exp(1j * ht["phi[rad]"])  # on the leg at P, along C -> P (phi is P -> C)
    scale = np.max(np.abs(F))
    assert_close(table["F_cyl_x[N]"], F.real, "F_cyl_x", scale)
    assert_close(table["F_cyl_y[N]"], F.imag, "F_cyl_y", scale)
    assert_close(table["F_B_x[N]"], -F.real, "F_B_x", scale)
    assert_close(table["F_B_y[N]"], -F.imag, "F_B_y", scale)
