"""``theta_<link>`` is the direction from the link's first listed point to its second, as
drawn, whatever point the spanning tree enters the link through (its first, its second, a
plate's third, a slot's base) and for the driver too: checked against the solved points at
every pose of a stroke (as a continuous angle on the drawing's branch), for the same
linkages listed in several orders, whose solved points must not depend on the listing."""

import jax

jax.config.update("jax_enable_x64", True)

import cmath  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

TOL = 1e-12
S = np.linspace(0.0, 2 * np.pi, 9)

# Watt: the ternary rocker O4 B E between the four-bar and the dyad E-F-O6; listed "B E O4"
# or "E B O4" the tree enters it through its third point O4, "E O4 B" through its second.
WATT = dict(points={"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2),
                    "O6": (7.0, 1.0)},
            links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "F O6"}, ground="O2 O4 O6")
# Stephenson III: the floating ternary coupler A B C, entered through A.
STEPH = dict(points={"O2": (0, 0), "A": (0.4, 0.9), "B": (3.0, 1.8), "O4": (3.4, 0), "C": (1.8, 3.0), "D": (4.2, 3.9),
                     "O6": (5.6, 1.9)},
             links={"crank": "O2 A", "coupler": "A B C", "rocker": "O4 B", "link5": "C D", "link6": "O6 D"}, ground="O2 O4 O6")
# A quick-return drive: the crank's pin A in a straight slot of the plate O4 C D.
QR = dict(points={"O2": (0.0, 0.3), "A": (0.1, 0.3), "O4": (0.0, 0.0), "C": (0.0, 0.6), "D": (-0.2, 0.5)},
          links={"crank": "O2 A", "rocker": "O4 C D"}, ground="O2 O4", slots={"A": {"on": "rocker", "angle": math.atan2(0.3, 0.1)}})

CASES = {  # name: (drawing, the link listed another way, its listing, stroke)
    "watt rocker B E O4": (WATT, "rocker", "B E O4", "rock"),
    "watt rocker E O4 B": (WATT, "rocker", "E O4 B", "rock"),
    "watt rocker E B O4": (WATT, "rocker", "E B O4", "rock"),
    "watt link6 O6 F": (WATT, "link6", "O6 F", "rock"),
    "stephenson coupler B C A": (STEPH, "coupler", "B C A", "rock"),
    "stephenson coupler C B A": (STEPH, "coupler", "C B A", "rock"),
    "quick return rocker C D O4": (QR, "rocker", "C D O4", "turn"),
    "watt driver A O2": (WATT, "crank", "A O2", "rock"),
}


def linkage(drawing, link=None, order=None):
    links = dict(drawing["links"]) if link is None else {**drawing["links"], link: order}
    return jm.Linkage(**{**drawing, "links": links}, driver="crank")


def stroke(lk, kind):
    u0 = float(lk.input_at_drawing[0])
    return u0 + (0.9 * np.sin(S) if kind == "rock" else S)


def solved(lk, u, p=None):
    """The statuses, every coordinate and every point's position along the inputs `u`."""
    sol = lk.solve(u, p)
    mech, params = lk.mechanism, lk.params if p is None else {**lk.params, **p}
    q = np.asarray(sol.q)
    pts = {x: np.asarray(jax.vmap(lambda qk, uk, x=x: mech.point(x, qk, uk, params))(q, u[:, None])) for x in lk.points}
    return sol, pts


def assert_as_drawn(lk, u, sol, pts):
    """Every link's angle (the driver's: the input) is the direction from its first listed
    point to its second, continuous along the stroke and on the drawing's branch at its
    start (the stroke starts at the drawing)."""
    assert jm.status_counts(sol.status) == {"CONVERGED": len(u)}
    for link, names in lk.links.items():
        a, b = names[:2]
        name = f"theta_{link}"
        got = np.asarray(u) if name in lk.mechanism.inputs else np.asarray(sol[name])
        drawn = cmath.phase(lk.points[b] - lk.points[a])
        want = np.unwrap(np.angle(pts[b] - pts[a]))
        assert abs(got[0] - drawn) <= TOL, link
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL, err_msg=link)


@pytest.mark.parametrize("name", list(CASES))
def test_link_angles_as_drawn_and_positions_whatever_the_listing(name):
    drawing, link, order, kind = CASES[name]
    ref, other = linkage(drawing), linkage(drawing, link, order)
    u_ref = stroke(ref, kind)
    sol_ref, pts_ref = solved(ref, u_ref)
    assert_as_drawn(ref, u_ref, sol_ref, pts_ref)
    u = stroke(other, kind)
    if link == "crank":  # the driver listed from its tip: its input is half a turn from the pivot's
        assert abs(np.angle(np.exp(1j * (u - u_ref - np.pi)))).max() <= 1e-15
    sol, pts = solved(other, u)
    assert_as_drawn(other, u, sol, pts)
    scale = max(np.max(np.abs(v)) for v in pts_ref.values())
    for x in pts_ref:  # the physics does not depend on how a link is listed
        assert np.max(np.abs(pts[x] - pts_ref[x])) <= TOL * scale, x


def test_plate_angle_follows_a_changed_drawing():
    """The plate's angle at its first point (entered through its third) follows its sides:
    with another length from the entry, ``theta_rocker`` is still the direction B -> E."""
    lk = linkage(WATT, "rocker", "B E O4")
    assert "ang_E_B_O4" not in lk.params  # derived from the plate's sides, not one more parameter
    p = {"len_O4_E": 1.1 * lk.params["len_O4_E"], "ang_B_O4_E": lk.params["ang_B_O4_E"] - 0.05}
    u = stroke(lk, "rock")
    sol, pts = solved(lk, u, p)
    assert jm.status_counts(sol.status) == {"CONVERGED": len(u)}
    np.testing.assert_allclose(np.angle(np.exp(1j * (np.asarray(sol["theta_rocker"]) - np.angle(pts["E"] - pts["B"])))), 0.0,
                               rtol=0, atol=TOL)
    assert abs(abs(pts["E"][3] - pts["O4"][3]) - p["len_O4_E"]) <= TOL
