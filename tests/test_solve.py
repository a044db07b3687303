"""Position solve against closed forms, statuses, implicit derivatives, NaN isolation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import jaxmech as jm
from jaxmech.scenes.classic import fourbar_mechanism as FB
from jaxmech.scenes.classic import slider_crank_mechanism as SC

from helpers import (
    SIXBAR_P,
    central_diff,
    fourbar_closed,
    fourbar_feasible,
    inverted_closed,
    inverted_feasible,
    inverted_slider_mechanism as ISC,
    sixbar_mechanism,
    slider_closed,
)

N_RANDOM = 10_000
POS_TOL = 1e-12  # rad, or relative for lengths
DERIV_RTOL = 1e-9


def _rng(seed):
    return np.random.default_rng(seed)


def _rel(a, b):
    scale = np.maximum(np.abs(b), 1.0)
    return np.abs(np.asarray(a) - np.asarray(b)) / scale


# ----------------------------------------------------------------------------- closed forms
def test_random_fourbars_match_closed_form():
    """10^4 random four-bars: positions to 1e-12 rad; dq/du and d2q/du2 to 1e-9 relative."""
    r = _rng(0)
    a, b, c, d = (r.uniform(0.5, 3.0, N_RANDOM) for _ in range(4))
    th2 = r.uniform(0, 2 * np.pi, N_RANDOM)
    feasible, f = fourbar_feasible(th2, a, b, c, d)
    margin = np.minimum(np.abs(f - (b + c)), np.abs(f - np.abs(b - c))) / f
    t3, t4 = fourbar_closed(th2, a, b, c, d)
    # a guess 0.2 rad off the truth (both angles, so it stays on its branch) to exercise Newton
    guess = np.stack([np.nan_to_num(t3) + 0.2, np.nan_to_num(t4) + 0.2], -1)
    p = dict(a=a, b=b, c=c, d=d)
    sol = jm.solve(FB, th2, p, guess)
    ok = np.asarray(sol.ok)
    clear = margin > 1e-6  # no claim within roundoff of the assembly boundary
    st = np.asarray(sol.status)
    # Every assemblable design closes; a few guesses whose perturbation crosses into the other
    # assembly's basin (near sin(theta4 - theta3) = 0) are flagged BRANCH, never silently wrong.
    assert np.all(np.isin(st[feasible & clear], [jm.Status.CONVERGED, jm.Status.BRANCH])), jm.status_counts(st[feasible & clear])
    flipped = feasible & clear & (st == jm.Status.BRANCH)
    assert flipped.mean() < 0.01
    assert np.all(np.abs(np.sin(np.asarray(t4) - np.asarray(t3)))[flipped] < 0.3)
    assert np.all(st[~feasible & clear] == jm.Status.INFEASIBLE)
    sel = feasible & clear & ok
    err3 = np.abs(np.angle(np.exp(1j * (np.asarray(sol["theta3"])[sel] - np.asarray(t3)[sel]))))
    err4 = np.abs(np.angle(np.exp(1j * (np.asarray(sol["theta4"])[sel] - np.asarray(t4)[sel]))))
    # conditioning bounds what any method can do: compare where the closed form is well posed
    well = np.asarray(sol.cond)[sel] < 1e3
    assert well.mean() > 0.95
    assert np.max(err3[well]) < POS_TOL and np.max(err4[well]) < POS_TOL

    # derivatives per unit input vs autodiff of the closed form (no solver involved)
    idx = np.flatnonzero(sel)[:2000]
    def cf(t, a, b, c, d):
        return jnp.stack(fourbar_closed(t, a, b, c, d))
    d1_cf = jax.vmap(jax.jacfwd(cf))(th2[idx], a[idx], b[idx], c[idx], d[idx])
    d2_cf = jax.vmap(jax.jacfwd(jax.jacfwd(cf)))(th2[idx], a[idx], b[idx], c[idx], d[idx])
    d1, d2 = jax.vmap(lambda q, u, a_, b_, c_, d_: jm.input_derivatives(FB, q, u, dict(a=a_, b=b_, c=c_, d=d_)))(
        sol.q[idx], jnp.asarray(th2[idx])[:, None], a[idx], b[idx], c[idx], d[idx]
    )
    cond_ok = np.asarray(sol.cond)[idx] < 1e3
    assert np.max(_rel(d1[:, :, 0], d1_cf)[cond_ok]) < DERIV_RTOL
    assert np.max(_rel(d2[:, :, 0, 0], d2_cf)[cond_ok]) < DERIV_RTOL


def test_random_slider_cranks_match_closed_form():
    r = _rng(1)
    a = r.uniform(0.05, 0.3, N_RANDOM)
    b = r.uniform(0.1, 0.6, N_RANDOM)
    e = r.uniform(-0.2, 0.2, N_RANDOM)
    th2 = r.uniform(0, 2 * np.pi, N_RANDOM)
    arg = (e - a * np.sin(th2)) / b
    feasible = np.abs(arg) <= 1
    clear = np.abs(np.abs(arg) - 1) > 1e-6
    t3, x = slider_closed(th2, a, b, e)
    guess = np.stack([np.nan_to_num(t3) * 0.8, np.nan_to_num(x) * 1.1], -1)  # stays on cos(theta3) > 0
    sol = jm.solve(SC, th2, dict(a=a, b=b, e=e), guess)
    st = np.asarray(sol.status)
    assert np.all(st[feasible & clear] == jm.Status.CONVERGED), jm.status_counts(st[feasible & clear])
    assert np.all(st[~feasible & clear] == jm.Status.INFEASIBLE), jm.status_counts(st[~feasible & clear])
    sel = feasible & clear & (np.asarray(sol.cond) < 1e3)
    assert sel.sum() > 0.9 * (feasible & clear).sum()
    assert np.max(np.abs(np.asarray(sol["theta3"])[sel] - np.asarray(t3)[sel])) < POS_TOL
    assert np.max(np.abs(np.asarray(sol["x"])[sel] - np.asarray(x)[sel]) / np.abs(np.asarray(x)[sel]).clip(b[sel])) < POS_TOL

    idx = np.flatnonzero(sel)[:2000]
    cf = lambda t, a, b, e: jnp.stack(slider_closed(t, a, b, e))  # noqa: E731
    d1_cf = jax.vmap(jax.jacfwd(cf))(th2[idx], a[idx], b[idx], e[idx])
    d2_cf = jax.vmap(jax.jacfwd(jax.jacfwd(cf)))(th2[idx], a[idx], b[idx], e[idx])
    d1, d2 = jax.vmap(lambda q, u, a_, b_, e_: jm.input_derivatives(SC, q, u, dict(a=a_, b=b_, e=e_)))(
        sol.q[idx], jnp.asarray(th2[idx])[:, None], a[idx], b[idx], e[idx]
    )
    assert np.max(_rel(d1[:, :, 0], d1_cf)) < DERIV_RTOL
    assert np.max(_rel(d2[:, :, 0, 0], d2_cf)) < DERIV_RTOL


def test_random_inverted_slider_cranks_match_closed_form():
    """The arc-track thesis's inverted slider-crank, driven by the nut travel s34 (m)."""
    r = _rng(2)
    a1 = r.uniform(0.1, 0.4, N_RANDOM)
    a2 = r.uniform(0.1, 0.4, N_RANDOM)
    alpha0 = r.uniform(0, 2 * np.pi, N_RANDOM)
    s = r.uniform(0.01, 0.8, N_RANDOM)
    feasible = inverted_feasible(s, a1, a2)
    clear = (np.abs(s - np.abs(a2 - a1)) > 1e-6 * s) & (np.abs(s - a1 - a2) > 1e-6 * s)
    t12, t13 = inverted_closed(s, a1, a2, alpha0)
    guess = np.stack([np.nan_to_num(t12) + 0.05, np.nan_to_num(t13, nan=1.0) * 0.95], -1)  # keeps sin(theta13) > 0
    sol = jm.solve(ISC, s, dict(a1=a1, a2=a2, alpha0=alpha0), guess)
    st = np.asarray(sol.status)
    assert np.all(np.isin(st[feasible & clear], [jm.Status.CONVERGED, jm.Status.BRANCH])), jm.status_counts(st[feasible & clear])
    flipped = feasible & clear & (st == jm.Status.BRANCH)
    assert flipped.mean() < 0.01
    assert np.all(np.isnan(np.asarray(sol.q)[flipped]))  # flagged and NaN, never a silent wrong branch
    assert np.all(st[~feasible & clear] == jm.Status.INFEASIBLE), jm.status_counts(st[~feasible & clear])
    sel = feasible & clear & (np.asarray(sol.cond) < 1e3)
    assert sel.sum() > 0.9 * (feasible & clear).sum()
    for got, want in ((sol["theta12"], t12), (sol["theta13"], t13)):
        err = np.abs(np.angle(np.exp(1j * (np.asarray(got)[sel] - np.asarray(want)[sel]))))
        assert np.max(err) < POS_TOL

    idx = np.flatnonzero(sel)[:2000]
    cf = lambda s_, a1_, a2_, al_: jnp.stack(inverted_closed(s_, a1_, a2_, al_))  # noqa: E731
    d1_cf = jax.vmap(jax.jacfwd(cf))(s[idx], a1[idx], a2[idx], alpha0[idx])
    d2_cf = jax.vmap(jax.jacfwd(jax.jacfwd(cf)))(s[idx], a1[idx], a2[idx], alpha0[idx])
    d1, d2 = jax.vmap(lambda q, u, x1, x2, x3: jm.input_derivatives(ISC, q, u, dict(a1=x1, a2=x2, alpha0=x3)))(
        sol.q[idx], jnp.asarray(s[idx])[:, None], a1[idx], a2[idx], alpha0[idx]
    )
    assert np.max(_rel(d1[:, :, 0] * a1[idx, None], d1_cf * a1[idx, None])) < DERIV_RTOL
    assert np.max(_rel(d2[:, :, 0, 0] * a1[idx, None] ** 2, d2_cf * a1[idx, None] ** 2)) < DERIV_RTOL


# ----------------------------------------------------------------------------- statuses
def _toggle_design():
    # Non-Grashof (triple-rocker): the crank cannot turn fully; its limits are toggles where
    # the coupler and rocker are collinear, f = b + c.
    return dict(a=2.0, b=1.5, c=1.2, d=2.2)


def _toggle_angle(p):
    cos_t = (p["a"] ** 2 + p["d"] ** 2 - (p["b"] + p["c"]) ** 2) / (2 * p["a"] * p["d"])
    return float(np.arccos(cos_t))


def test_fourbar_driven_into_toggle_reports_singular():
    p = _toggle_design()
    t_lim = _toggle_angle(p)
    th = np.linspace(t_lim - 0.3, t_lim, 301)  # the last input is exactly the toggle
    t3, t4 = fourbar_closed(th[0], **p)
    sol = jm.solve_stroke(FB, th, p, jnp.array([t3, t4]))
    st = np.asarray(sol.status)
    assert st[-1] == jm.Status.SINGULAR
    assert np.all(st[:-5] == jm.Status.CONVERGED)
    # conditioning grows without bound towards the toggle (as distance^-1/2)
    cond = np.asarray(sol.cond)
    assert cond[-2] > 10 * cond[0] and cond[-1] > 1e7
    # beyond the toggle: cannot be assembled
    beyond = jm.solve(FB, t_lim + 0.05, p, sol.q[-5])
    assert int(beyond.status) == jm.Status.INFEASIBLE
    assert np.all(np.isnan(np.asarray(beyond.q)))


def test_scale_awareness_mm_m_km():
    """The same design in millimetres, metres and kilometres: same angles, same statuses."""
    r = _rng(3)
    n = 500
    base = dict(a=r.uniform(0.5, 3, n), b=r.uniform(0.5, 3, n), c=r.uniform(0.5, 3, n), d=r.uniform(0.5, 3, n))
    th2 = r.uniform(0, 2 * np.pi, n)
    guess = np.tile([0.5, 1.5], (n, 1))
    sols = [jm.solve(FB, th2, {k: v * s for k, v in base.items()}, guess) for s in (1e3, 1.0, 1e-3)]
    for s in sols[1:]:
        np.testing.assert_array_equal(np.asarray(s.status), np.asarray(sols[0].status))
        ok = np.asarray(s.ok)
        np.testing.assert_allclose(np.asarray(s.q)[ok], np.asarray(sols[0].q)[ok], rtol=0, atol=1e-11)


def test_branch_is_kept_along_stroke_and_checked():
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    th = np.linspace(0, 2 * np.pi, 2001)
    for sign in (1.0, -1.0):
        t3, t4 = fourbar_closed(0.0, **p, sign=sign)
        sol = jm.solve_stroke(FB, th, p, jnp.array([t3, t4]), options=jm.SolverOptions(anchors=64))
        assert np.all(np.asarray(sol.ok))
        assert np.all(np.sign(np.asarray(sol.branch)) == sign)
        c3, c4 = fourbar_closed(th, **p, sign=sign)
        assert np.max(np.abs(np.angle(np.exp(1j * (np.asarray(sol["theta4"]) - np.asarray(c4)))))) < 1e-12


def test_guess_on_other_branch_is_flagged_not_silent():
    """A guess near the crossed assembly that Newton pulls to the open one says BRANCH."""
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    # theta4 - theta3 slightly negative (crossed indicator) but close to the open solution's basin
    t3, t4 = fourbar_closed(1.0, **p, sign=1.0)
    sol = jm.solve(FB, 1.0, p, jnp.array([t4 + 0.05, t4]))
    assert int(sol.status) in (jm.Status.BRANCH, jm.Status.CONVERGED)
    if int(sol.status) == jm.Status.CONVERGED:  # then it must be on the guess's (crossed) branch
        assert float(sol.branch) < 0
    else:
        assert np.all(np.isnan(np.asarray(sol.q)))


def test_failed_samples_are_nan_and_isolated():
    p = dict(a=jnp.array([1.0, 1.0, 10.0, 1.0]), b=3.0, c=2.5, d=3.5)
    u = jnp.array([0.3, jnp.nan, 0.3, 0.3])
    sol = jm.solve(FB, u, p, jnp.array([0.5, 1.5]))
    st = np.asarray(sol.status)
    assert list(st) == [jm.Status.CONVERGED, jm.Status.NONFINITE, jm.Status.INFEASIBLE, jm.Status.CONVERGED]
    q = np.asarray(sol.q)
    assert np.all(np.isfinite(q[[0, 3]])) and np.all(np.isnan(q[[1, 2]]))

    # A status-masked batch figure: its gradient is the good samples' alone, and finite.
    def figure(a):
        s = jm.solve(FB, u, dict(p, a=a), jnp.array([0.5, 1.5]))
        th4 = jnp.where(s.ok, s.q[:, 1], 0.0)
        return jnp.sum(th4)

    g = jax.grad(figure)(p["a"])
    assert np.all(np.isfinite(np.asarray(g)))
    assert g[1] == 0 and g[2] == 0
    g_good = jax.grad(lambda a0: jm.solve(FB, 0.3, dict(p, a=a0), jnp.array([0.5, 1.5])).q[1])(1.0)
    np.testing.assert_allclose(g[0], g_good, rtol=1e-13)


# ----------------------------------------------------------------------------- derivatives
def test_check_grads_second_order_fwd_and_rev():
    g = jnp.array([0.7, 1.7])

    def f(u, a, d):
        return jm.solve(FB, u, dict(a=a, b=3.0, c=2.5, d=d), g).q

    check_grads(f, (0.5, 1.0, 3.5), order=2, modes=("fwd", "rev"))
    check_grads(lambda u, e: jm.solve(SC, u, dict(a=0.1, b=0.35, e=e), jnp.array([0.1, 0.44])).q, (0.4, 0.03), order=2, modes=("fwd", "rev"))


def test_parameter_derivatives_match_finite_differences():
    """d q / d p for every parameter of the four-bar, six-bar and inverted slider-crank, 1e-8 relative."""
    cases = [
        (FB, 0.7, dict(a=1.0, b=3.0, c=2.5, d=3.5), jnp.array([0.7, 1.7])),
        (sixbar_mechanism, 0.3, SIXBAR_P, jnp.array([0.6, 1.9, 1.06, 2.15])),
        (ISC, 0.15, dict(a1=0.275, a2=0.24, alpha0=1.1345), jnp.array([0.5, 1.5])),
    ]
    for mech, u, p, g in cases:
        sol = jm.solve(mech, u, p, g)
        assert int(sol.status) == jm.Status.CONVERGED
        pj = {k: jnp.asarray(v) for k, v in p.items()}
        q_of_p = lambda pp: jm.solve(mech, u, pp, sol.q).q  # noqa: E731
        auto = jax.jacfwd(q_of_p)(pj)
        rev = jax.jacrev(q_of_p)(pj)
        for name in p:
            fd = central_diff(lambda x: q_of_p(dict(pj, **{name: x})), p[name], h=1e-3)
            scale = np.maximum(np.abs(fd), 1e-2)
            assert np.max(np.abs(np.asarray(auto[name]) - fd) / scale) < 1e-8, (mech.name, name)
            np.testing.assert_allclose(rev[name], auto[name], rtol=1e-12, atol=1e-14)


def test_derivatives_not_through_iterations_root_guess():
    """Started exactly at the root, Newton takes no step; derivatives must still be right
    (differentiating the iterations would give zero)."""
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    t3, t4 = fourbar_closed(0.8, **p)
    root = jnp.array([t3, t4])
    sol = jm.solve(FB, 0.8, p, root)
    assert int(sol.steps) == 0 and int(sol.status) == jm.Status.CONVERGED
    d = jax.jacfwd(lambda u: jm.solve(FB, u, p, root).q)(0.8)
    want = jax.jacfwd(lambda u: jnp.stack(fourbar_closed(u, **p)))(0.8)
    assert np.max(np.abs(np.asarray(d) - np.asarray(want))) < 1e-12
    assert np.max(np.abs(np.asarray(d))) > 0.1


def test_two_loop_sixbar_stroke_closes_and_derivatives():
    th = np.linspace(0.3, 0.3 + 2 * np.pi, 721)
    sol, d1, d2 = jm.stroke_kinematics(sixbar_mechanism, th, SIXBAR_P, jnp.array([0.6, 1.9, 1.06, 2.15]))
    assert np.all(np.asarray(sol.ok))
    res = jax.vmap(lambda q, u: sixbar_mechanism.residual(q, u, SIXBAR_P))(sol.q, jnp.asarray(th)[:, None])
    assert np.max(np.abs(np.asarray(res))) < 1e-13
    # dq/du vs differences of the solved stroke itself (independent of the implicit rule)
    i = 300
    fd = central_diff(lambda t: jm.solve(sixbar_mechanism, t, SIXBAR_P, sol.q[i]).q, th[i], h=1e-3)
    np.testing.assert_allclose(np.asarray(d1[i, :, 0]), fd, rtol=1e-9, atol=1e-11)
    # the named result: its second derivative against differences of the first's
    kin = jm.stroke_kinematics(sixbar_mechanism, th[i - 1 : i + 2], SIXBAR_P, sol.q[i - 1])
    assert isinstance(kin, jm.StrokeKinematics) and kin.solution.q.shape == (3, 4)
    fd2 = central_diff(lambda t: jm.stroke_kinematics(sixbar_mechanism, jnp.stack([t]), SIXBAR_P, sol.q[i]).dq_du[0, :, 0], th[i], h=1e-3)
    np.testing.assert_allclose(np.asarray(kin.d2q_du2[1, :, 0, 0]), fd2, rtol=1e-7, atol=1e-9)


# ----------------------------------------------------------------------------- continuation and linear algebra
@pytest.mark.parametrize("n", [1, 2, 3, 4, 6, 9])
def test_small_solves_and_condition_numbers_match_numpy(n):
    """The unrolled (n <= 4) and looped (n > 4) eliminations against LAPACK via numpy."""
    from jaxmech.solver.linalg import cond1, solve_small

    rng = _rng(n)
    a = rng.normal(size=(n, n)) + 0.5 * n * np.eye(n)
    a[[0, -1]] = a[[-1, 0]]  # the largest entries off the diagonal: pivoting is exercised
    b, bb = rng.normal(size=n), rng.normal(size=(n, 3))
    np.testing.assert_allclose(np.asarray(solve_small(jnp.asarray(a), jnp.asarray(b))), np.linalg.solve(a, b), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(np.asarray(solve_small(jnp.asarray(a), jnp.asarray(bb))), np.linalg.solve(a, bb), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(float(cond1(jnp.asarray(a))), np.linalg.cond(a, 1), rtol=1e-10)
    if n in (3, 6):  # the unrolled and the looped elimination, both differentiated
        check_grads(lambda a_, b_: solve_small(a_, b_), (jnp.asarray(a), jnp.asarray(b)), order=1, modes=("fwd", "rev"))


def _toggle_stroke():
    """A non-Grashof four-bar whose crank cannot turn fully (b + c = 4.2 is reached at
    theta2 = 2.25 rad): the end of the stroke is infeasible."""
    p = {"a": 1.0, "b": 2.0, "c": 2.2, "d": 3.5}
    th = np.linspace(1.5, 3.0, 2001)
    t3, t4 = fourbar_closed(th[0], **p)
    return th, p, jnp.array([t3, t4])


def test_stroke_agrees_with_independent_pointwise_solves():
    """Every stroke point (solved from its anchor's predictor, one block at a time) against a
    pointwise solve of the same input from a guess 0.1 rad off the closed form (the last
    assemblable pose beyond the toggle), on a clean stroke and on one that runs into the
    unassemblable range: same statuses, positions to 1e-13, derivatives to 1e-9."""
    for th, p, g in [(np.linspace(0.0, 2 * np.pi, 2001), {"a": 1.0, "b": 3.0, "c": 2.5, "d": 3.5}, jnp.array([0.2, 1.2])), _toggle_stroke()]:
        sol, d1, d2 = jm.stroke_kinematics(FB, th, p, g)
        t3, t4 = fourbar_closed(th, **p)
        last = np.flatnonzero(np.isfinite(t3))[-1]
        guess = np.stack([np.where(np.isfinite(t3), t3, t3[last]), np.where(np.isfinite(t4), t4, t4[last])], -1) + 0.1
        pw = jm.solve(FB, th, p, guess)
        e1, e2 = jax.vmap(lambda q, u: jm.input_derivatives(FB, q, u, p))(pw.q, jnp.asarray(th)[:, None])
        np.testing.assert_array_equal(np.asarray(sol.status), np.asarray(pw.status))
        ok = np.asarray(pw.ok)
        np.testing.assert_array_equal(np.isnan(np.asarray(sol.q)), np.isnan(np.asarray(pw.q)))
        assert np.all(np.isnan(np.asarray(d1)[~ok])) and np.all(np.isnan(np.asarray(d2)[~ok]))
        for x, y, tol in [(sol.q, pw.q, 1e-13), (d1, e1, DERIV_RTOL), (d2, e2, DERIV_RTOL)]:
            np.testing.assert_allclose(np.asarray(x)[ok], np.asarray(y)[ok], rtol=tol, atol=tol)
    st = np.asarray(sol.status)
    assert (st == jm.Status.CONVERGED).any() and (st == jm.Status.INFEASIBLE).any()


def test_stroke_kinematics_accuracy_and_parameter_gradient():
    """Stroke velocities and accelerations against the closed form, and the gradient of a
    figure built from them (through the implicit function theorem at the stroke's roots)
    against sixth-order central differences."""
    p = {"a": 1.0, "b": 3.0, "c": 2.5, "d": 3.5}
    th = np.linspace(0.0, 2 * np.pi, 2001)
    sol, d1, d2 = jm.stroke_kinematics(FB, th, p, jnp.array([0.2, 1.2]))
    assert np.all(np.asarray(sol.steps)[1:] == 1)  # one Newton step per point from its anchor's predictor (point 0: from the user's guess)
    grad_closed = jax.vmap(jax.grad(lambda t: fourbar_closed(t, **p)[1]))
    hess_closed = jax.vmap(jax.grad(jax.grad(lambda t: fourbar_closed(t, **p)[1])))
    np.testing.assert_allclose(np.asarray(d1[:, 1, 0]), np.asarray(grad_closed(jnp.asarray(th))), rtol=DERIV_RTOL, atol=DERIV_RTOL)
    np.testing.assert_allclose(np.asarray(d2[:, 1, 0, 0]), np.asarray(hess_closed(jnp.asarray(th))), rtol=DERIV_RTOL, atol=DERIV_RTOL)

    def figure(c):
        _, e1, e2 = jm.stroke_kinematics(FB, th, {**p, "c": c}, jnp.array([0.2, 1.2]))
        return jnp.sum(e1[:, 1, 0] ** 2) + jnp.sum(e2[:, 0, 0, 0])

    _, g = jax.jvp(figure, (2.5,), (1.0,))  # forward mode; reverse mode: test_check_grads_...
    fd = central_diff(lambda c: float(figure(c)), 2.5, h=1e-3)
    np.testing.assert_allclose(float(g), fd, rtol=1e-7)


def test_predictor_drops_terms_its_series_cannot_be_trusted_with():
    """Near a singular position q'' is huge: the second-order term must then be dropped, and
    a predicted step above max_step dropped altogether (a flap design starting near a toggle
    was predicted 2000 rad away and converged 319 turns off before this guard)."""
    from jaxmech.continuation.solve import predict

    q, s = jnp.array([0.3, 1.0]), jnp.array([1.0, 1.0])
    d1 = jnp.array([[1.0], [-0.5]])
    smooth = jnp.array([[[0.4]], [[0.2]]])
    du = jnp.array([0.01])
    exact2 = q + d1 @ du + 0.5 * smooth[:, :, 0] @ du**2
    np.testing.assert_allclose(np.asarray(predict(q, d1, smooth, du, s, 1.0)), np.asarray(exact2), rtol=1e-15)
    wild = 1e8 * smooth  # second-order term 100x the first: first order only
    np.testing.assert_allclose(np.asarray(predict(q, d1, wild, du, s, 1.0)), np.asarray(q + d1 @ du), rtol=1e-15)
    fast = 1e3 * d1  # a 10 rad first-order step: no prediction at all
    np.testing.assert_array_equal(np.asarray(predict(q, fast, smooth, du, s, 1.0)), np.asarray(q))
