"""A linkage's centres of mass and inertias follow its drawing: a link's uniform shape (a
bar between two joints, a plate spanned by three) is derived from its joints' positions,
so a sweep over lengths and angles moves them as a new drawing would.  Truths: the bar's
midpoint and ``m L^2 / 12``, the triangle's centroid and ``m (a^2 + b^2 + c^2) / 36``,
written out here; and the same design drawn directly."""

import cmath

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

POINTS = {"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)}
LINKS = {"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "O6 F"}
MASS = {"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 2.5, "link6": 2.0}
#: the drawing's geometric parameters (what a design sweep varies)
GEOMETRY = ("len_O2_A", "len_A_B", "len_O4_B", "len_O4_E", "ang_B_O4_E", "len_E_F", "len_O6_F", "x_O4", "x_O6", "y_O6")


def watt(points=POINTS, **kw):
    return jm.Linkage(points=points, links=LINKS, ground="O2 O4 O6", driver="crank", mass=MASS, gravity=9.81, **kw)


def z(points, name):
    return complex(*points[name])


def test_derived_parameters_are_not_parameters():
    lk = watt()
    assert not [k for k in lk.params if k.startswith("J_") or "_G_" in k]
    assert set(GEOMETRY) <= set(lk.params)
    # given explicitly, they are parameters of their own again, and stay put
    fixed = watt(inertia={"crank": 0.5}, centre={"crank": "A"})
    assert fixed.params["J_crank"] == 0.5
    m, g, J = fixed.mass_properties({"len_O2_A": 2.0})["crank"]
    assert J == 0.5 and abs(g - z(POINTS, "A")) < 1e-15


def test_centre_and_inertia_follow_a_changed_length():
    lk = watt()
    a, e = 1.3 * abs(z(POINTS, "A")), 1.2 * abs(z(POINTS, "E") - z(POINTS, "O4"))
    props = lk.mass_properties({"len_O2_A": a, "len_O4_E": e})
    # the crank, a uniform bar O2-A: its midpoint along the drawing's crank angle, m L^2 / 12
    phi = cmath.phase(z(POINTS, "A"))
    m, g, J = props["crank"]
    assert abs(g - 0.5 * a * cmath.exp(1j * phi)) < 1e-14
    assert abs(J - MASS["crank"] * a**2 / 12) < 1e-14
    # the rocker, a uniform triangle O4 B E whose side O4-E grew: its centroid, m (a^2+b^2+c^2)/36
    o4, b = z(POINTS, "O4"), z(POINTS, "B")
    e_new = o4 + e * cmath.exp(1j * cmath.phase(z(POINTS, "E") - o4))
    m, g, J = props["rocker"]
    sides = abs(b - o4) ** 2 + abs(e_new - o4) ** 2 + abs(e_new - b) ** 2
    assert abs(g - (o4 + b + e_new) / 3) < 1e-13
    assert abs(J - MASS["rocker"] * sides / 36) < 1e-13 * J
    # link5 keeps its length (its inertia) and rides on the moved E (at the drawing's angles)
    m, g, J = props["link5"]
    ef = z(POINTS, "F") - z(POINTS, "E")
    assert abs(J - MASS["link5"] * abs(ef) ** 2 / 12) < 1e-14 and abs(g - (e_new + 0.5 * ef)) < 1e-13


@pytest.mark.parametrize("scale", [0.95, 1.04])
def test_inverse_dynamics_of_a_swept_design_equals_the_design_drawn_directly(scale):
    """The crank lengthened (A moved along it) and the rocker's E moved: the drawing's
    geometric parameters of the new drawing, given to the old linkage, give the new
    linkage's torque and every reaction (masses and inertias included)."""
    moved = dict(POINTS)
    moved["A"] = tuple(scale * np.asarray(POINTS["A"]))
    o4 = np.asarray(POINTS["O4"])
    moved["E"] = tuple(o4 + scale * (np.asarray(POINTS["E"]) - o4))
    old, new = watt(), watt(moved)
    swept = {k: new.params[k] for k in GEOMETRY}
    drive, t = jm.ConstantSpeed(new.input_at_drawing[0], 2 * np.pi), np.linspace(0.0, 1.0, 25)
    a = old.inverse_dynamics(drive, t, p=swept)
    b = new.inverse_dynamics(drive, t)
    assert np.all(np.asarray(a.status) == jm.Status.CONVERGED) and np.all(np.asarray(b.status) == jm.Status.CONVERGED)
    scale_tau = np.max(np.abs(np.asarray(b.tau)))
    np.testing.assert_allclose(np.asarray(a.tau), np.asarray(b.tau), rtol=0, atol=1e-10 * scale_tau)
    for joint in new.joints:
        fa, fb = np.asarray(a.reaction(joint)), np.asarray(b.reaction(joint))
        np.testing.assert_allclose(fa, fb, rtol=0, atol=1e-10 * np.max(np.abs(fb)))
    # and it is not what the old drawing's masses give: the test can fail
    assert np.max(np.abs(np.asarray(old.inverse_dynamics(drive, t).tau) - np.asarray(b.tau))) > 1e-3 * scale_tau


def test_a_linkage_is_taken_wherever_a_scene_is():
    """``sweep_scene``, ``run_scene`` and ``scene_figure`` take the linkage itself (its
    ``Linkage.scene()``); a swept design's torque is the linkage's own inverse dynamics."""
    from jaxmech.design import scene_figure
    from jaxmech.scenes import run_scene
    from jaxmech.sweep import sweep_scene

    lk = watt()
    table = {"len_O2_A": np.array([0.95, lk.params["len_O2_A"], 1.03])}  # the middle one: the drawing
    res = sweep_scene(lk, table=table, points=9, progress=False)
    assert res.scene == lk.scene().name and np.all(res.status == 0)
    one = run_scene(lk, points=9, len_O2_A=1.03)
    torque = [k for k in res.columns if k.startswith("effort_")][0]
    # the torque of the swept design, against the linkage's inverse dynamics at the same drive
    drive = jm.ConstantSpeed(lk.input_at_drawing[0], 1.0)
    t = np.asarray(one.table()["t[s]"])
    direct = lk.inverse_dynamics(drive, t, p={"len_O2_A": 1.03})
    np.testing.assert_allclose(res.columns[torque][2], np.asarray(direct.tau[:, 0]), rtol=0, atol=1e-10 * np.max(np.abs(direct.tau)))
    fig = scene_figure(lk, lambda c, p: c[torque][-1], points=9)
    value, ok = fig(lk.params)
    assert bool(ok) and abs(float(value) - float(res.columns[torque][1][-1])) <= 1e-10 * abs(float(value))
