"""``jm.drawing_from_lengths``: a linkage's drawing from its lengths, plate angles, ground
pivots, guides and input value, handed to ``jm.Linkage``.

Each linkage is built twice, from the coordinates of a drawing and from the lengths
measured off that drawing, and the two are compared point by point (to 1e-12 m) and along a
solved stroke of the input (to 1e-12).  The assembly modes are checked against independent
truths written here: Freudenstein's closed form of the four-bar's rocker angle (both
roots), the offset slider-crank's closed-form piston position (both sides), and for the
Watt six-bar the mirror image of a dyad's joint across the line of its two neighbours at
every sample.
"""

import jax

jax.config.update("jax_enable_x64", True)

import cmath  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

TOL = 1e-12
N = 73  # samples of a whole turn of the crank


def positions(lk, u):
    """Every point's position (complex, m) along a stroke of the crank's angle `u`, solved
    from the drawing: ``{point: (N,)}``; and the solve's statuses all converged."""
    sol = lk.solve(u)
    assert jm.status_counts(sol.status) == {"CONVERGED": len(u)}
    mech, p = lk.mechanism, lk.params
    q, uu = np.asarray(sol.q), np.asarray(u, float)[:, None]
    return {x: np.asarray(jax.vmap(lambda qk, uk, x=x: mech.point(x, qk, uk, p))(q, uu)) for x in lk.points}


def measured(points, pairs):
    """``{(a, b): |b - a|}`` off a drawing."""
    return {(a, b): abs(complex(*points[b]) - complex(*points[a])) for a, b in pairs}


def same_points(got, want):
    assert set(got) == set(want)
    for x in want:
        assert abs(complex(*got[x]) - complex(*want[x])) <= TOL, (x, got[x], want[x])


def mirror(p, a, b):
    """`p` reflected across the line through `a` and `b` (complex)."""
    e = (b - a) / abs(b - a)
    return a + e * np.conj((p - a) / e)


# --------------------------------------------------------------------------- four-bar
FOUR = {"O2": (0.2, -0.1), "A": (0.55, 0.75), "B": (2.9, 1.7), "O4": (3.3, -0.2)}
FOUR_LINKS = {"crank": "O2 A", "coupler": "A B", "rocker": "O4 B"}


def fourbar_from_lengths(mode):
    d = measured(FOUR, [("O2", "A"), ("A", "B"), ("O4", "B")])
    u0 = cmath.phase(complex(*FOUR["A"]) - complex(*FOUR["O2"]))
    return jm.drawing_from_lengths(ground={k: FOUR[k] for k in ("O2", "O4")}, lengths=d, driver=("O2", "A"),
                                   input=u0, modes={"B": mode})


def freudenstein(u, mode_sign):
    """The rocker's angle (rad, global) at crank angles `u` by Freudenstein's closed form,
    ground rotated onto +x: the root with ``+sqrt`` or ``-sqrt`` of the half-angle quadratic."""
    O2, O4 = complex(*FOUR["O2"]), complex(*FOUR["O4"])
    a, b, c, d = (abs(complex(*FOUR[y]) - complex(*FOUR[x])) for x, y in (("O2", "A"), ("A", "B"), ("O4", "B"), ("O2", "O4")))
    g = cmath.phase(O4 - O2)
    t2 = u - g
    k1, k2, k3 = d / a, d / c, (a * a - b * b + c * c + d * d) / (2 * a * c)
    A = np.cos(t2) - k1 - k2 * np.cos(t2) + k3
    B = -2 * np.sin(t2)
    C = k1 - (k2 + 1) * np.cos(t2) + k3
    return 2 * np.arctan2(-B + mode_sign * np.sqrt(B * B - 4 * A * C), 2 * A) + g


def test_fourbar_from_lengths_is_the_drawn_fourbar_in_both_modes():
    """Mode +1 (B left of A -> O4) is the drawing; -1 puts B at its mirror image across
    A O4.  Along a whole turn each equals its drawn linkage and one Freudenstein root."""
    plus, minus = fourbar_from_lengths(+1), fourbar_from_lengths(-1)
    same_points(plus, FOUR)
    B = mirror(complex(*FOUR["B"]), complex(*FOUR["A"]), complex(*FOUR["O4"]))
    same_points(minus, {**FOUR, "B": (B.real, B.imag)})
    u = cmath.phase(complex(*FOUR["A"]) - complex(*FOUR["O2"])) + np.linspace(0.0, 2 * np.pi, N)
    drawn = positions(jm.Linkage(points=FOUR, links=FOUR_LINKS, ground="O2 O4", driver="crank"), u)
    O4 = complex(*FOUR["O4"])
    roots = {}
    for mode, pts in ((+1, plus), (-1, minus)):
        got = positions(jm.Linkage(points=pts, links=FOUR_LINKS, ground="O2 O4", driver="crank"), u)
        theta4 = np.angle(got["B"] - O4)
        err = {s: np.max(np.abs(np.angle(np.exp(1j * (theta4 - freudenstein(u, s)))))) for s in (+1, -1)}
        roots[mode] = min(err, key=err.get)
        assert err[roots[mode]] <= TOL, err
        if mode == +1:
            for x in FOUR:
                assert np.max(np.abs(got[x] - drawn[x])) <= TOL, x
        else:
            np.testing.assert_allclose(got["B"], mirror(drawn["B"], got["A"], O4), rtol=0, atol=TOL)
    assert roots[+1] != roots[-1]  # the two modes are the two roots, the whole turn through


# --------------------------------------------------------------------------- Watt six-bar
WATT = {"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)}
WATT_LINKS = {"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "O6 F"}
WATT_MASS = {"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 2.5, "link6": 2.0}


def watt(points):
    return jm.Linkage(points=points, links=WATT_LINKS, ground="O2 O4 O6", driver="crank", mass=WATT_MASS, gravity=9.81)


def watt_from_lengths(plate, f_mode=+1):
    """The six-bar from its six lengths and its rocker's plate angle at O4 (`plate`
    "angle"), or from the plate's three sides ("sides", E then a dyad's point)."""
    P = {k: complex(*v) for k, v in WATT.items()}
    d = measured(WATT, [("O2", "A"), ("A", "B"), ("O4", "B"), ("O4", "E"), ("E", "F"), ("O6", "F")])
    kw = dict(ground={k: WATT[k] for k in ("O2", "O4", "O6")}, driver="O2 A", input=cmath.phase(P["A"]), modes={"B": +1, "F": f_mode})
    if plate == "angle":
        return jm.drawing_from_lengths(lengths=d, angles={("B", "O4", "E"): cmath.phase((P["E"] - P["O4"]) / (P["B"] - P["O4"]))}, **kw)
    d[("B", "E")] = abs(P["E"] - P["B"])  # E: a dyad of O4 and B, right of the line O4 -> B
    return jm.drawing_from_lengths(lengths=d, **{**kw, "modes": {**kw["modes"], "E": -1}})


@pytest.mark.parametrize("plate", ["angle", "sides"])
def test_watt_sixbar_from_lengths_is_the_drawn_sixbar(plate):
    pts = watt_from_lengths(plate)
    same_points(pts, WATT)
    lk, drawn = watt(pts), watt(WATT)
    for k, v in drawn.params.items():
        assert abs(lk.params[k] - v) <= TOL * max(1.0, abs(v)), k
    u = drawn.input_at_drawing[0] + np.linspace(0.0, 2 * np.pi, N)
    got, want = positions(lk, u), positions(drawn, u)
    for x in WATT:
        assert np.max(np.abs(got[x] - want[x])) <= TOL, x


def test_watt_sixbar_other_mode_is_the_mirror_assembly():
    """F's other mode: F mirrored across E O6 at every sample of a stroke; the rest the same."""
    lk = watt(watt_from_lengths("angle", f_mode=-1))
    u = lk.input_at_drawing[0] + np.linspace(0.0, 1.0, 21)
    got, want = positions(lk, u), positions(watt(WATT), u)
    for x in ("A", "B", "E"):
        assert np.max(np.abs(got[x] - want[x])) <= TOL, x
    assert np.max(np.abs(got["F"] - mirror(want["F"], want["E"], want["O6"]))) <= TOL
    assert np.min(np.abs(got["F"] - want["F"])) > 0.5  # a different assembly, not the same one


# --------------------------------------------------------------------------- slider-crank
R, L_ROD, OFFSET = 0.1, 0.35, 0.03  # m: crank, rod, the guide's height above the crank's pivot


def slider_crank(mode, theta0=math.radians(70.0)):
    pts = jm.drawing_from_lengths(ground={"O2": (0, 0)}, lengths={"O2 A": R, "A B": L_ROD},
                                  guides={"B": {"through": (0.0, OFFSET), "angle": 0.0}},
                                  driver=("O2", "A"), input=theta0, modes={"B": mode})
    return pts, jm.Linkage(points=pts, links={"crank": "O2 A", "rod": "A B", "piston": "B"}, ground="O2",
                           driver="crank", sliders={"piston": {"angle": 0.0}})


@pytest.mark.parametrize("mode", [+1, -1])
def test_offset_slider_crank_from_lengths_is_the_closed_form(mode):
    """The piston at ``x_B = R cos t + mode sqrt(L^2 - (R sin t - e)^2)``, ``y_B = e``, in the
    drawing and along a whole turn; the drawing equals the one drawn from coordinates."""
    theta0 = math.radians(70.0)
    pts, lk = slider_crank(mode, theta0)
    x_b = lambda t: R * np.cos(t) + mode * np.sqrt(L_ROD**2 - (R * np.sin(t) - OFFSET) ** 2)  # noqa: E731
    same_points(pts, {"O2": (0.0, 0.0), "A": (R * math.cos(theta0), R * math.sin(theta0)), "B": (x_b(theta0), OFFSET)})
    u = theta0 + np.linspace(0.0, 2 * np.pi, N)
    got = positions(lk, u)
    np.testing.assert_allclose(got["B"], x_b(u) + 1j * OFFSET, rtol=0, atol=TOL)
    np.testing.assert_allclose(got["A"], R * np.exp(1j * u), rtol=0, atol=TOL)


def test_a_tilted_guide_through_a_ground_point():
    """A guide at 30 deg through a ground point: the point is on the line at its length,
    mode +1 the farther along the guide's direction."""
    e = cmath.exp(1j * math.radians(30.0))
    kw = dict(ground={"O2": (0, 0), "Q": (0.05, -0.2)}, lengths={"O2 A": 0.1, "A B": 0.4},
              guides={"B": {"through": "Q", "angle": "30deg"}}, driver="O2 A", input="100deg")
    far, near = (complex(*jm.drawing_from_lengths(**kw, modes={"B": s})["B"]) for s in (+1, -1))
    A = 0.1 * cmath.exp(1j * math.radians(100.0))
    for B in (far, near):
        assert abs(abs(B - A) - 0.4) <= TOL and abs(((B - complex(0.05, -0.2)) / e).imag) <= TOL
    assert ((far - near) / e).real > 0.1


# --------------------------------------------------------------------------- refusals
def test_refusals_name_the_point_and_the_fix():
    ground, lengths = {"O2": (0, 0), "O4": (3.5, 0)}, {"O2 A": 1.0, "A B": 3.0, "O4 B": 2.5}
    kw = dict(ground=ground, driver=("O2", "A"), input="60deg")
    with pytest.raises(ValueError, match=r"point 'B' cannot be placed: the dyad A-B = 1 m, B-O4 = 1 m does not close across A-O4"):
        jm.drawing_from_lengths(lengths={"O2 A": 1.0, "A B": 1.0, "O4 B": 1.0}, modes={"B": 1}, **kw)
    with pytest.raises(ValueError, match=r"point 'B' has two positions.*A-B = 3 m.*left of the line A -> O4.*modes=\{'B': \+1\}"):
        jm.drawing_from_lengths(lengths=lengths, **kw)
    with pytest.raises(ValueError, match=r"points \['B', 'E'\] cannot be placed .*B has lengths to \['A', 'E'\]"):
        jm.drawing_from_lengths(lengths={"O2 A": 1.0, "A B": 3.0, "E B": 1.0}, modes={"B": 1}, **kw)
    with pytest.raises(ValueError, match=r"modes\['A'\]: 'A' is placed without a choice"):
        jm.drawing_from_lengths(lengths=lengths, modes={"B": 1, "A": -1}, **kw)
    with pytest.raises(ValueError, match=r"modes\['B'\]: an assembly mode is \+1 or -1, got 0"):
        jm.drawing_from_lengths(lengths=lengths, modes={"B": 0}, **kw)
    with pytest.raises(ValueError, match=r"lengths\[\('O2', 'O4'\)\] = 3.6 m, but the other lengths put O2 and O4 3.5 m apart"):
        jm.drawing_from_lengths(lengths={**lengths, "O2 O4": 3.6}, modes={"B": 1}, **kw)
    with pytest.raises(ValueError, match=r"driver=.*pivot 'A' is not a ground point"):
        jm.drawing_from_lengths(ground=ground, lengths=lengths, driver="A O2", input=0.0)
    with pytest.raises(ValueError, match=r"input: given without driver="):
        jm.drawing_from_lengths(ground=ground, lengths=lengths, input=0.0, modes={"B": 1})
    with pytest.raises(ValueError, match=r"lengths\['A'\]: give 2 distinct point names"):
        jm.drawing_from_lengths(lengths={"A": 1.0}, **kw)
    with pytest.raises(ValueError, match=r"point 'B' cannot be placed: A-B = 0.1 m does not reach its guide"):
        jm.drawing_from_lengths(ground={"O2": (0, 0)}, lengths={"O2 A": 0.1, "A B": 0.1}, driver="O2 A", input=0.0,
                                guides={"B": {"through": (0, 0.5), "angle": 0.0}}, modes={"B": 1})
