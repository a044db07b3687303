"""Stability suite: the solver near and past its limits.

Every case checks three things: the right status; no silent wrong branch (a sample marked
CONVERGED is on its guess's assembly branch and equals the closed form there); no NaN
outside the failed samples (and every failed sample is NaN).
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.scenes.classic import fourbar_mechanism as FB  # noqa: E402
from tests.helpers import fourbar_closed, fourbar_feasible  # noqa: E402

S = jm.Status
CRANK_ROCKER = dict(a=1.0, b=3.0, c=2.5, d=3.5)
#: Largest angle error allowed for a converged sample against the closed form (rad).
ANGLE_TOL = 1e-9


def _wrap(x):
    return np.angle(np.exp(1j * np.asarray(x, float)))


def _toggle_angle(p):
    """Crank angle at which coupler and rocker stretch straight (b + c = |O4 - A|)."""
    return float(np.arccos((p["a"] ** 2 + p["d"] ** 2 - (p["b"] + p["c"]) ** 2) / (2 * p["a"] * p["d"])))


def assert_honest(sol, theta2, p, sign=None, tol=ANGLE_TOL):
    """Converged samples: finite, on the branch `sign` (default: the one they report), equal
    to the closed form there.  Every other sample: NaN positions.  Returns the status array."""
    st = np.asarray(sol.status)
    q = np.asarray(sol.q)
    ok = st == S.CONVERGED
    assert np.all(np.isfinite(q[ok])), "a converged sample has non-finite positions"
    assert np.all(np.isnan(q[~ok])), "a failed sample carries finite positions"
    br = np.asarray(sol.branch)
    if sign is None:
        sign_arr = np.sign(br)
    else:
        sign_arr = np.broadcast_to(sign, st.shape)
        assert np.all(np.sign(br[ok]) == sign_arr[ok]), "converged on the other branch without saying so"
    th = np.broadcast_to(np.asarray(theta2, float), st.shape)
    pb = {k: np.broadcast_to(np.asarray(v, float), st.shape) for k, v in p.items()}
    t3, t4 = fourbar_closed(th[ok], **{k: v[ok] for k, v in pb.items()}, sign=sign_arr[ok])
    err = np.max(np.abs(_wrap(q[ok] - np.stack([t3, t4], -1))), initial=0.0)
    assert err < tol, f"converged sample differs from the closed form by {err:.2e} rad"
    return st


# ----------------------------------------------------------------------------- toggles
def test_toggle_stretched_straight_approach_and_beyond():
    """A crank-driven four-bar whose coupler and rocker stretch straight at theta_t: statuses
    stay honest at distances 1e-1 .. 1e-14 from the toggle, and beyond it nothing assembles."""
    p = dict(a=1.0, b=2.0, c=1.5, d=3.2)
    t_lim = _toggle_angle(p)
    dist = np.concatenate([10.0 ** -np.arange(1, 15), [0.0], -(10.0 ** -np.arange(1, 8))])
    th = t_lim - dist
    t3, t4 = fourbar_closed(t_lim - 0.1, **p)
    guess = np.tile([float(t3), float(t4)], (th.size, 1))
    sol = jm.solve(FB, th, p, guess)
    # near a toggle the closed form itself loses digits (sqrt of the distance): compare loosely
    st = assert_honest(sol, th, p, sign=1.0, tol=1e-6)
    before, at, beyond = st[:14], st[14], st[15:]
    assert np.all(before[:6] == S.CONVERGED)  # 1e-1 .. 1e-6 from the toggle: regular
    assert set(before.tolist()) <= {S.CONVERGED, S.SINGULAR}
    assert at in (S.SINGULAR, S.INFEASIBLE)
    assert np.all(beyond == S.INFEASIBLE)
    # the conditioning reported grows as the toggle nears
    cond = np.asarray(sol.cond)[:6]
    assert np.all(np.diff(cond) > 0)


def test_change_point_fourbar_does_not_switch_branch():
    """Grashof change-point design (s + l = p + q): at theta2 = 0 all links are collinear and
    both assembly branches meet.  A stroke into the change point keeps its branch or stops."""
    p = dict(a=1.0, b=3.0, c=2.0, d=2.0)
    th = np.linspace(1.0, 0.0, 401)
    for sign in (1.0, -1.0):
        t3, t4 = fourbar_closed(1.0, **p, sign=sign)
        sol = jm.solve_stroke(FB, th, p, jnp.array([t3, t4]), options=jm.SolverOptions(anchors=64))
        st = assert_honest(sol, th, p, sign=sign, tol=1e-6)
        assert np.all(st[:-20] == S.CONVERGED)
        assert st[-1] != S.CONVERGED  # exactly at the change point: singular, never a guess
        assert np.all(np.isin(st, [S.CONVERGED, S.SINGULAR, S.INFEASIBLE, S.MAX_STEPS]))


# ----------------------------------------------------------------------------- assembly
def test_designs_that_cannot_be_assembled():
    """A batch of designs and crank angles, some assemblable, some not (triangle inequality):
    the statuses follow the geometry exactly."""
    r = np.random.default_rng(11)
    n = 400
    p = dict(a=r.uniform(0.5, 2.5, n), b=r.uniform(0.5, 3, n), c=r.uniform(0.5, 3, n), d=r.uniform(0.5, 3, n))
    th = r.uniform(0, 2 * np.pi, n)
    feasible, f = fourbar_feasible(th, **p)
    margin = np.minimum(np.abs(f - (p["b"] + p["c"])), np.abs(f - np.abs(p["b"] - p["c"])))
    keep = margin > 1e-3  # stay away from toggles here (covered above)
    p = {k: v[keep] for k, v in p.items()}
    th, feasible = th[keep], feasible[keep]
    assert 0.2 < feasible.mean() < 0.9  # both kinds are in the batch
    # a guess on the open branch where it exists (perturbed), any guess elsewhere
    t3, t4 = fourbar_closed(th, **p)
    guess = np.where(feasible[:, None], np.stack([np.asarray(t3), np.asarray(t4)], -1) + 0.05, 0.5)
    sol = jm.solve(FB, th, p, guess)
    st = assert_honest(sol, th, p, sign=1.0)
    np.testing.assert_array_equal(st[feasible], S.CONVERGED)
    np.testing.assert_array_equal(st[~feasible], S.INFEASIBLE)


def test_large_stroke_steps_do_not_flip_branch_silently():
    """Coarse strokes (9 and 24 steps per turn) on a design that nearly toggles at
    theta2 = pi invite the predictor to jump branches: a converged sample must still be on
    the stroke's branch, and a sample that closed on the other one must say BRANCH."""
    p = dict(a=1.0, b=2.3, c=1.75, d=3.0)  # b + c = 4.05 just above a + d = 4: assembles all turn
    for n in (9, 24):
        th = np.linspace(0.0, 2 * np.pi, n)
        assert np.all(fourbar_feasible(th, **p)[0])
        for sign in (1.0, -1.0):
            t3, t4 = fourbar_closed(0.0, **p, sign=sign)
            sol = jm.solve_stroke(FB, th, p, jnp.array([t3, t4]), options=jm.SolverOptions(anchors=4))
            st = assert_honest(sol, th, p, sign=sign)
            assert np.all(np.isin(st, [S.CONVERGED, S.BRANCH]))
            assert np.mean(st == S.CONVERGED) > 0.5


# ----------------------------------------------------------------------------- guesses
def test_bad_and_random_initial_guesses():
    """Random guesses anywhere (and absurd ones): whatever converges is on the guess's branch
    (else BRANCH) and exact; everything else is NaN with a failure status."""
    r = np.random.default_rng(5)
    n = 2000
    th = r.uniform(0, 2 * np.pi, n)
    guess = r.uniform(-np.pi, np.pi, (n, 2))
    guess[:20] = 1e6 * r.standard_normal((20, 2))  # absurd angles
    guess[20:40, 1] = guess[20:40, 0]  # exactly on the branch boundary (indicator 0)
    sol = jm.solve(FB, th, CRANK_ROCKER, guess)
    st = assert_honest(sol, th, CRANK_ROCKER)  # branch checked against what it reports
    # the reported branch must be the guess's own (or the status says BRANCH)
    gsign = np.sign(np.sin(guess[:, 1] - guess[:, 0]))
    ok = st == S.CONVERGED
    nonzero = gsign != 0
    assert np.all(np.sign(np.asarray(sol.branch))[ok & nonzero] == gsign[ok & nonzero])
    assert np.all(np.isin(st, [S.CONVERGED, S.BRANCH, S.MAX_STEPS, S.INFEASIBLE]))
    assert ok.mean() > 0.5  # damping makes most far guesses safe
    assert np.all(np.isfinite(np.asarray(sol.residual)))


# ----------------------------------------------------------------------------- units and dtypes
def test_same_design_in_mm_m_km_gives_same_angles_and_statuses():
    """A stroke through a toggle and beyond, in three units: identical statuses, equal angles."""
    p = dict(a=1.0, b=2.0, c=1.5, d=3.2)
    t_lim = _toggle_angle(p)
    th = np.linspace(t_lim - 0.5, t_lim + 0.2, 71)
    t3, t4 = fourbar_closed(th[0], **p)
    sols = []
    for s in (1e-3, 1.0, 1e3):
        ps = {k: v * s for k, v in p.items()}
        sol = jm.solve_stroke(FB, th, ps, jnp.array([t3, t4]))
        assert_honest(sol, th, ps, sign=1.0, tol=1e-6)
        sols.append(sol)
    st0 = np.asarray(sols[1].status)
    assert np.any(st0 == S.CONVERGED) and np.any(st0 != S.CONVERGED)
    for sol in (sols[0], sols[2]):
        np.testing.assert_array_equal(np.asarray(sol.status), st0)
        ok = st0 == S.CONVERGED
        np.testing.assert_allclose(np.asarray(sol.q)[ok], np.asarray(sols[1].q)[ok], rtol=0, atol=1e-11)
        np.testing.assert_allclose(np.asarray(sol.residual), np.asarray(sols[1].residual), rtol=1e-6, atol=1e-14)


def test_float32_statuses_and_accuracy():
    """float32 arguments (x64 on): float32 results converged to float32 accuracy, derivatives
    finite and right, failures reported as in float64."""
    th = np.linspace(0, 2 * np.pi, 64, dtype=np.float32)
    p32 = {k: np.float32(v) for k, v in CRANK_ROCKER.items()}
    g = np.array([0.2, 1.2], np.float32)
    sol, d1, _ = jm.stroke_kinematics(FB, th, p32, g)
    assert sol.q.dtype == jnp.float32 and d1.dtype == jnp.float32
    assert np.all(np.asarray(sol.status) == S.CONVERGED)
    assert_honest(sol, th.astype(float), CRANK_ROCKER, sign=1.0, tol=2e-5)
    # dtheta4/dtheta2 against a float64 central difference of the closed form
    h = 1e-5
    t4p = fourbar_closed(th.astype(float) + h, **CRANK_ROCKER)[1]
    t4m = fourbar_closed(th.astype(float) - h, **CRANK_ROCKER)[1]
    np.testing.assert_allclose(np.asarray(d1)[:, 1, 0], _wrap(np.asarray(t4p) - np.asarray(t4m)) / (2 * h), atol=5e-4)
    # an unassemblable sample in float32: reported, NaN, no leak
    far = jm.solve(FB, np.float32(0.3), dict(p32, d=np.float32(9.0)), g)
    assert far.q.dtype == jnp.float32
    assert int(far.status) == S.INFEASIBLE and np.all(np.isnan(np.asarray(far.q)))


# ----------------------------------------------------------------------------- non-finite
def test_nan_and_inf_inputs_are_nonfinite_and_isolated():
    nan, inf = np.nan, np.inf
    th = np.array([0.3, nan, inf, -inf, 0.3, 0.3, 0.3])
    guess = np.tile([0.5, 1.5], (7, 1))
    guess[4] = [nan, 1.5]
    guess[5] = [inf, 1.5]
    sol = jm.solve(FB, th, CRANK_ROCKER, guess)
    st = assert_honest(sol, th, CRANK_ROCKER, sign=1.0)
    assert list(st) == [S.CONVERGED, S.NONFINITE, S.NONFINITE, S.NONFINITE, S.NONFINITE, S.NONFINITE, S.CONVERGED]


def test_nonfinite_parameters_eager_error_and_traced_status():
    with pytest.raises(ValueError, match="'b' must be finite"):
        jm.solve(FB, 0.3, dict(CRANK_ROCKER, b=np.nan), jnp.array([0.5, 1.5]))

    @jax.jit
    def traced(b):
        s = jm.solve(FB, 0.3, dict(CRANK_ROCKER, b=b), jnp.array([0.5, 1.5]))
        return s.status, s.q

    for bad in (np.nan, np.inf):
        st, q = traced(jnp.array([3.0, bad]))
        assert list(np.asarray(st)) == [S.CONVERGED, S.NONFINITE]
        assert np.all(np.isfinite(np.asarray(q)[0])) and np.all(np.isnan(np.asarray(q)[1]))


# ----------------------------------------------------------------------------- gradients of a mixed batch
def _masked_figure(p, th, guess):
    """Sum over designs x positions of sin(theta4) + 0.1 (dtheta4/dtheta2)^2, failed samples masked."""
    sol = jm.solve(FB, th[None, :], {k: v[:, None] for k, v in p.items()}, guess)
    d1 = jax.vmap(jax.vmap(lambda q, u, pp: jm.input_derivatives(FB, q, u, pp)[0], in_axes=(0, 0, None)), in_axes=(0, None, 0))(
        sol.q, th[:, None], p
    )
    ok = sol.status == S.CONVERGED
    return jnp.sum(jnp.where(ok, jnp.sin(sol.q[..., 1]) + 0.1 * d1[..., 1, 0] ** 2, 0.0)), sol.status


def test_mixed_batch_gradient_equals_good_designs_alone():
    """Good designs, an unassemblable one, one driven past its toggle and one with a NaN
    parameter, in one batch: the gradient (every parameter) of a status-masked figure equals
    the good designs' alone, and is finite everywhere."""
    th = jnp.linspace(0.0, 2 * np.pi, 24)
    # designs: good, good, good, infeasible (d too long), toggling part-way, NaN parameter
    rows = [(1.0, 3.0, 2.5, 3.5), (0.9, 3.1, 2.4, 3.4), (1.1, 2.9, 2.6, 3.6), (1.0, 1.0, 1.0, 6.0), (1.0, 2.0, 1.5, 3.2), (1.0, 3.0, 2.5, 3.5)]
    p_all = {k: jnp.array([r[i] for r in rows]) for i, k in enumerate("abcd")}
    nan_mask = jnp.arange(6) == 5
    # a guess on the open branch for each sample where one exists (closed form + 0.01 rad)
    t3, t4 = fourbar_closed(th[None, :], *(p_all[k][:, None] for k in "abcd"))
    guess = jnp.nan_to_num(jnp.stack([t3, t4], -1) + 0.01, nan=0.5)

    # one compiled function for both batches: the NaN mask is an argument
    @jax.jit
    def value_and_grad(p, nan_mask):
        return jax.value_and_grad(lambda p_: _masked_figure(dict(p_, a=jnp.where(nan_mask, jnp.nan, p_["a"])), th, guess), has_aux=True)(p)

    (v_all, st), g_all = value_and_grad(p_all, nan_mask)
    st = np.asarray(st)
    assert np.all(st[:3] == S.CONVERGED)
    assert np.all(st[3] == S.INFEASIBLE)  # never assembles
    assert np.any(st[4] != S.CONVERGED) and np.any(st[4] == S.CONVERGED)  # toggles part-way
    assert np.all(st[5] == S.NONFINITE)
    # the good designs alone, same shapes: every other row a NaN design (all masked out)
    good = jnp.arange(6) < 3
    (v_good, st_good), g_good = value_and_grad(p_all, ~good)
    assert np.all(np.asarray(st_good)[:3] == S.CONVERGED) and np.all(np.asarray(st_good)[3:] == S.NONFINITE)
    for k in "abcd":
        ga, gg = np.asarray(g_all[k]), np.asarray(g_good[k])
        assert np.all(np.isfinite(ga)), f"non-finite gradient in {k}: {ga}"
        np.testing.assert_allclose(ga[:3], gg[:3], rtol=1e-12, atol=1e-14)
        assert ga[3] == 0 and ga[5] == 0 and np.all(gg[3:] == 0)
        assert np.any(ga[4] != 0)  # the toggling design's converged samples do contribute
    # independent truth: the same figure from the closed form, on the good designs alone
    def closed_figure(p):
        def one(a, b, c, d, t):
            t4 = lambda t_: fourbar_closed(t_, a, b, c, d)[1]  # noqa: E731
            return jnp.sin(t4(t)) + 0.1 * jax.grad(t4)(t) ** 2

        per = jax.vmap(jax.vmap(one, in_axes=(None, None, None, None, 0)), in_axes=(0, 0, 0, 0, None))
        return jnp.sum(per(p["a"], p["b"], p["c"], p["d"], th))

    v_true, g_true = jax.value_and_grad(closed_figure)({k: v[:3] for k, v in p_all.items()})
    np.testing.assert_allclose(float(v_good), float(v_true), rtol=1e-12)
    for k in "abcd":
        np.testing.assert_allclose(np.asarray(g_all[k])[:3], np.asarray(g_true[k]), rtol=1e-9, atol=1e-12)
    ok4 = st[4] == S.CONVERGED
    assert ok4.any() and float(v_all) != float(v_good)
    assert np.isfinite(float(v_all)) and np.isfinite(float(v_good))
