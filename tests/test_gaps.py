"""Strokes across gaps (stretches where a design cannot be assembled), toggle statuses in any
unit system, and one branch sign per loop.

Property tests over random four-bars, slider-cranks and Watt six-bars whose strokes leave
and re-enter the assemblable range: every pose that exists on the requested branch and is
well conditioned (1-norm condition number of the scaled Jacobian below 1e6, computed here
from the closed-form pose) must be CONVERGED and agree with the closed form to 1e-10 rad;
no sample where no pose exists may say CONVERGED or BRANCH; consecutive converged angles,
across gaps included, differ by less than half a turn (angles are right as numbers, not
only modulo 2 pi); and the same design in metres, millimetres and kilometres gives the same
status for every sample.  The truths are closed-form circle intersections, independent of
the solver.
"""

import dataclasses

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import HealthCheck, Phase, assume, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import jaxmech as jm  # noqa: E402
from helpers import sixbar_mechanism  # noqa: E402
from jaxmech.scenes.classic import fourbar_mechanism, slider_crank_mechanism  # noqa: E402

S = jm.Status
N = 241  # stroke points: one compiled program per mechanism serves every example
WELL = 1e6  # "well conditioned": the acceptance's condition-number bound
ACCURACY = 1e-10  # rad
UNITS = (1.0, 1e-3, 1e3)  # metres, kilometres, millimetres

PROPERTY = settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    database=None,
    phases=(Phase.explicit, Phase.generate),  # no shrinking: a failure prints its example as found
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)

SIXBAR = dataclasses.replace(
    sixbar_mechanism,
    branch=lambda q, u, p: {
        "loop 1": jnp.sin(q.theta4 - q.theta3),
        "loop 2": jnp.sin(q.theta6 - q.theta5),
    },
)


# ----------------------------------------------------------------------- closed forms
def dyad(p1, r1, p2, r2, sign):
    """Joint ``F`` with ``|F - p1| = r1``, ``|F - p2| = r2`` (circle intersection) whose
    indicator ``sin(angle(F - p2) - angle(F - p1))`` has the sign ``sign``; NaN where the
    dyad cannot close."""
    v = p2 - p1
    dist = np.abs(v)
    with np.errstate(invalid="ignore", divide="ignore"):  # coincident pivots: NaN, no pose
        x = (dist**2 + r1**2 - r2**2) / (2 * dist)
        h2 = r1**2 - x**2
        h = np.where(h2 >= 0, np.sqrt(np.abs(h2)), np.nan)
        f1, f2 = (p1 + v / dist * (x + 1j * t * h) for t in (1.0, -1.0))
    ind = np.sin(np.angle(f1 - p2) - np.angle(f1 - p1))
    return np.where(np.sign(ind) == sign, f1, f2)


def cond1(j):
    return np.array([np.linalg.cond(x, 1) for x in j])


def fourbar_truth(us, p, sign):
    """``q (N, 2)`` on the branch sin(theta4 - theta3) = ``sign``, and the condition number."""
    a, b, c, d = (p[k] for k in "abcd")
    A = a * np.exp(1j * us)
    B = dyad(A, b, d + 0j, c, sign)
    t3, t4 = np.angle(B - A), np.angle(B - d)
    L = max(a, b, c, d)
    j = np.stack([np.stack([-b * np.sin(t3), c * np.sin(t4)], -1), np.stack([b * np.cos(t3), -c * np.cos(t4)], -1)], -2) / L
    return np.stack([t3, t4], -1), cond1(np.nan_to_num(j))


def slider_truth(us, p, sign):
    """``(theta3, x)`` on the branch cos(theta3) = ``sign``, and the condition number."""
    a, b, e = p["a"], p["b"], p["e"]
    s3 = (e - a * np.sin(us)) / b
    with np.errstate(invalid="ignore"):
        t3 = np.where(sign > 0, np.arcsin(s3), np.pi - np.arcsin(s3))
    x = a * np.cos(us) + b * np.cos(t3)
    L = max(a, b, abs(e))
    # columns scaled like the solver's: angle (1), length (L); residual scale L
    j = np.stack([np.stack([-b * np.sin(t3) / L, -np.ones_like(t3)], -1), np.stack([b * np.cos(t3) / L, 0 * t3], -1)], -2)
    return np.stack([t3, x], -1), cond1(np.nan_to_num(j))


def sixbar_truth(us, p, signs):
    """Watt six-bar: loop 1 as the four-bar, loop 2 the dyad E -> F <- O6 with sign
    sin(theta6 - theta5) = ``signs[1]``."""
    q1, _ = fourbar_truth(us, p, signs[0])
    t3, t4 = q1[:, 0], q1[:, 1]
    E = p["d"] + p["e"] * np.exp(1j * (t4 + p["gamma"]))
    O6 = p["h"] + 1j * p["k"]
    F = dyad(E, p["f"], O6, p["g"], signs[1])
    t5, t6 = np.angle(F - E), np.angle(F - O6)
    b, c, e, f, g = (p[k] for k in "bcefg")
    L = max(abs(v) for k, v in p.items() if k != "gamma")
    z = np.zeros_like(t3)
    ie = lambda r, t: (-r * np.sin(t), r * np.cos(t))  # noqa: E731 - d/dt of r e^{it} as (re, im)
    c3, c4, c4e, c5, c6 = ie(b, t3), ie(-c, t4), ie(e, t4 + p["gamma"]), ie(f, t5), ie(-g, t6)
    rows = [
        [c3[0], c4[0], z, z],
        [c3[1], c4[1], z, z],
        [z, c4e[0], c5[0], c6[0]],
        [z, c4e[1], c5[1], c6[1]],
    ]
    j = np.stack([np.stack(r, -1) for r in rows], -2) / L
    return np.stack([t3, t4, t5, t6], -1), cond1(np.nan_to_num(j))


# ----------------------------------------------------------------------- the property
def check_stroke(mech, us, p, truth, others, angles, scaled):
    """Solve the stroke from the closed-form pose at ``us[0]`` and check the property.
    ``truth``: ``(q, cond)`` on the requested branch; ``others``: poses on the other branches."""
    q_true, cond = truth
    exists = np.all(np.isfinite(q_true), axis=-1)
    anywhere = exists | np.any([np.all(np.isfinite(q), axis=-1) for q in others], axis=0)
    sol = jm.solve_stroke(mech, us, p, q_true[0])
    st_ = np.asarray(sol.status)
    q = np.asarray(sol.q)
    ok = st_ == S.CONVERGED
    well = exists & (cond < WELL)
    assert np.all(ok[well]), f"well-conditioned poses not found: {jm.status_counts(st_[well & ~ok])} at {us[well & ~ok][:5]}"
    assert not np.any(ok & ~exists), "CONVERGED where the requested branch has no pose"
    err = np.abs(np.angle(np.exp(1j * (q[ok][:, angles] - q_true[ok][:, angles]))))
    assert np.max(err, initial=0) < ACCURACY, f"max angle error {np.max(err):.3g} rad"
    lengths = [j for j in range(q.shape[1]) if j not in angles]
    if lengths:
        scale = max(abs(v) for v in p.values())
        assert np.max(np.abs(q[ok][:, lengths] - q_true[ok][:, lengths]), initial=0) < ACCURACY * scale
    assert not np.any(np.isin(st_[~anywhere], [S.CONVERGED, S.BRANCH])), "a pose reported where none exists"
    # Right as numbers: neighbours within half a turn; across a gap no whole turn is added
    # (the first pose after a gap within half a turn of the last before it).
    both = ok[:-1] & ok[1:]
    steps = np.abs(np.diff(q[:, angles], axis=0))[both]
    assert np.max(steps, initial=0) < np.pi, f"a jump of {np.max(steps):.3g} rad between neighbours"
    across = np.abs(np.diff(q[ok][:, angles], axis=0))
    assert np.max(across, initial=0) <= np.pi, f"a jump of {np.max(across):.3g} rad across a gap"
    # The same design in other units: the same status everywhere.
    for k in scaled:
        pk = {n: (v * k if n in mech.lengths else v) for n, v in p.items()}
        gk = q_true[0] * np.where(mech.coord_is_length(), k, 1.0)
        st_k = np.asarray(jm.solve_stroke(mech, us, pk, gk).status)
        np.testing.assert_array_equal(st_k, st_, err_msg=f"statuses differ at length scale x{k}")


def stroke_through_gap(exists):
    """Whether a stroke starts assemblable, leaves the range and comes back."""
    gone = np.flatnonzero(~exists)
    return exists[0] and gone.size > 0 and np.any(exists[gone[0] :])


lengths = st.floats(0.4, 3.0)


@PROPERTY
@given(a=lengths, b=lengths, c=lengths, d=lengths, t0=st.floats(0, 2 * np.pi), sign=st.sampled_from([1.0, -1.0]))
def test_fourbar_strokes_across_gaps(a, b, c, d, t0, sign):
    p = dict(a=a, b=b, c=c, d=d)
    us = t0 + np.linspace(0.0, 4 * np.pi, N)
    truth = fourbar_truth(us, p, sign)
    exists = np.all(np.isfinite(truth[0]), axis=-1)
    assume(stroke_through_gap(exists) and truth[1][0] < 1e4)
    check_stroke(fourbar_mechanism, us, p, truth, [fourbar_truth(us, p, -sign)[0]], [0, 1], UNITS[1:])


@PROPERTY
@given(a=st.floats(0.5, 2.0), b=st.floats(0.3, 2.0), e=st.floats(-1.0, 1.0), t0=st.floats(0, 2 * np.pi), sign=st.sampled_from([1.0, -1.0]))
def test_slider_crank_strokes_across_gaps(a, b, e, t0, sign):
    p = dict(a=a, b=b, e=e)
    us = t0 + np.linspace(0.0, 4 * np.pi, N)
    truth = slider_truth(us, p, sign)
    exists = np.all(np.isfinite(truth[0]), axis=-1)
    assume(stroke_through_gap(exists) and truth[1][0] < 1e4)
    check_stroke(slider_crank_mechanism, us, p, truth, [slider_truth(us, p, -sign)[0]], [0], UNITS[1:])


@PROPERTY
@given(
    ls=st.lists(st.floats(0.5, 3.0), min_size=7, max_size=7),
    h=st.floats(2.0, 6.0),
    k=st.floats(-2.0, 3.0),
    gamma=st.floats(-1.0, 1.0),
    t0=st.floats(0, 2 * np.pi),
    signs=st.tuples(st.sampled_from([1.0, -1.0]), st.sampled_from([1.0, -1.0])),
)
# a one-point island: the first loop closes at point 3 alone between two gaps, 0.056 from its
# toggle, where Newton from every pose nearby landed on the loop's other mode (BRANCH)
@example(ls=[1.7078881681803042, 0.9, 0.75, 1.6143521530878466, 1.989833601230989, 1.701127240615796, 2.9385850421650175],
         h=2.091149283418641, k=0.75, gamma=-6.103515625e-05, t0=6.050165264851943, signs=(-1.0, 1.0))
# a 17-point island between gaps of 12 and 13 points, farther than RIGHT_REACH from any
# converged point: reached by no fill, its two-sided solves from across the gaps stall
# (INFEASIBLE on both turns until the repair's probes)
@example(ls=[1.2097661030852533, 2.21, 1.2771876053450457, 2.886584211987885, 1.9, 1.2866945694725183, 1.8697002290690476],
         h=3.209127895013677, k=1.8261680458464973, gamma=-0.41687299907784847, t0=1.627434608328106, signs=(1.0, 1.0))
def test_sixbar_strokes_across_gaps(ls, h, k, gamma, t0, signs):
    p = dict(zip("abcdefg", ls), h=h, k=k, gamma=gamma)
    us = t0 + np.linspace(0.0, 4 * np.pi, N)
    truth = sixbar_truth(us, p, signs)
    exists = np.all(np.isfinite(truth[0]), axis=-1)
    assume(stroke_through_gap(exists) and truth[1][0] < 1e4)
    others = [sixbar_truth(us, p, (s1, s2))[0] for s1 in (1.0, -1.0) for s2 in (1.0, -1.0) if (s1, s2) != signs]
    check_stroke(SIXBAR, us, p, truth, others, [0, 1, 2, 3], UNITS[1:2])


# ----------------------------------------------------------------------- toggles
@pytest.mark.parametrize("p", [dict(a=2.0, b=1.5, c=1.2, d=2.5), dict(a=1.3, b=0.9, c=2.1, d=2.2)])
def test_toggle_status_is_unit_free_within_1e12_rad(p):
    """Samples from 1e-2 rad to 1e-13 rad of a toggle (the crank's limit, coupler and rocker
    stretched), on it and just past it: one status per sample in metres, millimetres and
    kilometres; CONVERGED wherever the pose exists and is well conditioned, SINGULAR (never
    MAX_STEPS or INFEASIBLE) inside the toggle band, and nothing CONVERGED past the limit."""
    a, b, c, d = (p[k] for k in "abcd")
    limit = np.arccos((a * a + d * d - (b + c) ** 2) / (2 * a * d))  # |A - O4| = b + c
    offsets = np.array([1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-11, 1e-12, 3e-13, 1e-13, 0.0, -1e-13, -1e-12, -1e-10, -1e-6])
    us = limit - offsets  # positive offsets: assemblable side
    lead = limit - np.linspace(0.5, 2e-2, 24)
    for sign in (1.0, -1.0):
        q_true, cond = fourbar_truth(us, p, sign)
        exists = np.all(np.isfinite(q_true), axis=-1)
        g = fourbar_truth(lead[:1], p, sign)[0][0]
        statuses = []
        for k in UNITS:
            pk = {n: v * k for n, v in p.items()}
            point = np.asarray(jm.solve(fourbar_mechanism, us, pk, fourbar_truth(us[:1], p, sign)[0][0]).status)
            stroke = np.asarray(jm.solve_stroke(fourbar_mechanism, np.concatenate([lead, us]), pk, g).status)[lead.size :]
            statuses += [point, stroke]
        for s_ in statuses[1:]:
            np.testing.assert_array_equal(s_, statuses[0])
        st_ = statuses[0]
        assert np.all(st_[exists & (cond < WELL)] == S.CONVERGED), st_
        assert np.all(np.isin(st_[exists], [S.CONVERGED, S.SINGULAR])), st_
        assert not np.any(np.isin(st_[~exists], [S.CONVERGED, S.BRANCH])), st_
        assert np.any(st_ == S.SINGULAR)  # the band is reached: the test sees the toggle


def test_singular_message_names_the_toggle_band():
    p = dict(a=2.0, b=1.5, c=1.2, d=2.5)
    limit = np.arccos((p["a"] ** 2 + p["d"] ** 2 - (p["b"] + p["c"]) ** 2) / (2 * p["a"] * p["d"]))
    g = fourbar_truth(np.array([limit - 1e-2]), p, 1.0)[0][0]
    sol = jm.solve(fourbar_mechanism, np.array([limit - 1e-2, limit - 1e-13]), p, g)
    assert list(np.asarray(sol.status)) == [S.CONVERGED, S.SINGULAR]
    msg = sol.message((1,))
    assert "toggle" in msg and "condition number" in msg and "cond_max" in msg
    with pytest.raises(RuntimeError, match="condition number"):
        jm.solve(fourbar_mechanism, np.array([limit - 1e-13]), p, g, throw=True)


# ----------------------------------------------------------------------- a branch per loop
#: A Watt six-bar whose second loop's requested assembly ("rocker 6 above its pivot",
#: sin(theta6) > 0) ceases to exist over part of the crank turn while loop 1's does not.
UPPER = dataclasses.replace(
    sixbar_mechanism,
    branch=lambda q, u, p: {"loop 1 (coupler-rocker)": jnp.sin(q.theta4 - q.theta3), "loop 2 (rocker 6 up)": jnp.sin(q.theta6)},
)
UPPER_P = dict(a=1.0, b=3.0, c=2.5, d=3.5, e=1.5, f=3.9, g=2.1, h=6.1, k=3.75, gamma=0.6)


def test_second_loop_flip_is_branch_naming_that_loop():
    us = np.linspace(0.0, 2 * np.pi, 73)
    both = [sixbar_truth(us, UPPER_P, (1.0, s2))[0] for s2 in (1.0, -1.0)]
    sin6 = np.stack([np.sin(q[:, 3]) for q in both])
    # the independent truth: loop 2 has poses everywhere, with rocker 6 up only in places
    assert np.all(np.isfinite(sin6))
    up = np.any(sin6 > 0, axis=0)
    assert up[0] and not np.all(up)
    start = both[int(np.argmax(sin6[:, 0]))][0]
    sol = jm.solve_stroke(UPPER, us, UPPER_P, start)
    st_ = np.asarray(sol.status)
    assert np.all(st_[up & np.all(np.abs(sin6) > 1e-3, axis=0)] == S.CONVERGED)
    flipped = ~up & np.all(sin6 < -1e-3, axis=0)
    assert np.all(st_[flipped] == S.BRANCH)
    assert np.all(np.asarray(sol.flipped)[flipped] == 0b10)  # loop 2 alone
    i = int(np.flatnonzero(flipped)[0])
    msg = sol.message((i,))
    assert "'loop 2 (rocker 6 up)' flipped" in msg and "loop 1" not in msg
    with pytest.raises(RuntimeError, match="loop 2 \\(rocker 6 up\\)"):
        jm.solve_stroke(UPPER, us, UPPER_P, start, throw=True)
    assert sol.branches == ("loop 1 (coupler-rocker)", "loop 2 (rocker 6 up)")
    assert np.asarray(sol.branch).shape == (us.size, 2)
