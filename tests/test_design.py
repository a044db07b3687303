"""Sensitivities against finite differences and closed forms, peaks over a stroke, and a
multi-start fit that identifies four-bar lengths from noisy synthetic data."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402
import pytest  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from jaxmech import Status  # noqa: E402
from jaxmech.design import fit, peak, scene_figure, sensitivities  # noqa: E402
from jaxmech.scenes import run_scene  # noqa: E402
from jaxmech.scenes.classic import FOURBAR, SLIDER_CRANK  # noqa: E402

from helpers import fourbar_closed  # noqa: E402

POINTS = 41
GRAD_RTOL = 1e-6  # the brief's agreement with central differences
FD_REL_STEP = 1e-5  # central difference: truncation ~1e-10, solver roundoff ~1e-11


def central_fd(fn, p, name, rel=FD_REL_STEP):
    h = rel * abs(p[name])
    return (fn({**p, name: p[name] + h}) - fn({**p, name: p[name] - h})) / (2 * h)


def _final_transmission(cols, p):
    return cols["transmission_angle[rad]"][-1]


def _peak_coupler(cols, p):
    return peak(cols["theta3[rad]"], "argmax")


# ----------------------------------------------------------------------- peak
def test_peak_modes_bounds_and_gradients():
    x = jnp.array([0.1, 0.7, 0.3, jnp.nan, 0.65])
    assert peak(x) == pytest.approx(0.7)
    g = jax.grad(lambda v: peak(v))(x)
    np.testing.assert_array_equal(g, [0, 1, 0, 0, 0])  # no NaN from the NaN sample
    t = 0.01
    s = peak(x, "smooth", temperature=t)
    assert 0.7 <= s <= 0.7 + t * np.log(4)  # the stated bound T log N (N valid samples)
    gs = jax.grad(lambda v: peak(v, "smooth", temperature=t))(x)
    assert np.all(np.isfinite(gs)) and gs[3] == 0 and abs(np.sum(gs) - 1) < 1e-12
    assert np.isnan(peak(jnp.array([jnp.nan, jnp.nan])))
    # Along an axis, with a mask.
    m = jnp.array([[1.0, 5.0, 2.0], [3.0, 1.0, 9.0]])
    np.testing.assert_array_equal(peak(m, where=jnp.array([True, False, True])), [2.0, 9.0])
    with pytest.raises(ValueError, match="mode"):
        peak(x, "mean")


# ----------------------------------------------------------------------- four-bar
@pytest.fixture(scope="module")
def fourbar_transmission():
    fig = scene_figure(FOURBAR, _final_transmission, points=POINTS)
    # design 2 (c = 1.0) cannot be assembled over the whole crank turn
    designs = {"a": [1.0, 1.1, 1.0], "b": [3.0, 3.0, 3.0], "c": [2.5, 2.4, 1.0], "d": [3.5, 3.6, 3.5]}
    return fig, designs, sensitivities(fig, designs)


def test_fourbar_final_transmission_angle_vs_fd_and_closed_form(fourbar_transmission):
    fig, designs, s = fourbar_transmission
    np.testing.assert_array_equal(s.ok, [True, True, False])

    def by_run_scene(p):
        return run_scene(FOURBAR, points=POINTS, **p).table()["transmission_angle[rad]"][-1]

    def closed(a, b, c, d):
        t3, t4 = fourbar_closed(2 * jnp.pi, a, b, c, d)
        return jnp.arccos(jnp.abs(jnp.cos(t4 - t3)))

    for i in range(2):
        p = {k: v[i] for k, v in designs.items()}
        assert s.value[i] == pytest.approx(by_run_scene(p), rel=1e-12)
        exact = jax.grad(closed, argnums=(0, 1, 2, 3))(*(p[k] for k in "abcd"))
        for k, g_exact in zip("abcd", exact):
            fd = central_fd(by_run_scene, p, k)
            np.testing.assert_allclose(s.grad[k][i], fd, rtol=GRAD_RTOL)
            np.testing.assert_allclose(s.grad[k][i], g_exact, rtol=1e-9)
            np.testing.assert_allclose(s.elasticity[k][i], p[k] * fd / s.value[i], rtol=GRAD_RTOL)
    # The failed design: reported as failed, NaN, nothing else touched.
    assert np.isnan(s.value[2]) and all(np.isnan(s.grad[k][2]) for k in "abcd")
    text = s.table()
    assert "elasticity" in text and "failed" in text and all(k in text for k in "abcd")


def test_failed_design_puts_no_nan_in_a_batch_gradient(fourbar_transmission):
    fig, designs, s = fourbar_transmission
    batch = {k: jnp.asarray(v) for k, v in designs.items()}
    # Sum over the batch: the failed design's value is NaN, its gradient must be zero.
    total = jax.jit(jax.grad(lambda pb: jnp.sum(jax.vmap(lambda p: fig(p)[0])(pb))))
    g = total(batch)
    for k in "abcd":
        assert np.all(np.isfinite(g[k])) and g[k][2] == 0.0
        np.testing.assert_allclose(g[k][:2], s.grad[k][:2], rtol=1e-12)


def test_fourbar_peak_coupler_angle_vs_fd():
    fig = scene_figure(FOURBAR, _peak_coupler, points=POINTS)
    designs = {"a": [1.0, 0.9], "b": [3.0, 3.2], "c": [2.5, 2.6], "d": [3.5, 3.4]}
    s = sensitivities(fig, designs)

    def by_run_scene(p):
        return np.max(run_scene(FOURBAR, points=POINTS, **p).table()["theta3[rad]"])

    for i in range(2):
        p = {k: v[i] for k, v in designs.items()}
        assert s.value[i] == pytest.approx(by_run_scene(p), rel=1e-12)
        for k in "abcd":
            np.testing.assert_allclose(s.grad[k][i], central_fd(by_run_scene, p, k), rtol=GRAD_RTOL)


# ----------------------------------------------------------------------- slider-crank
def test_slider_crank_peak_coupler_angle_vs_fd_and_envelope():
    # 101 points over one turn put a sample exactly at theta2 = 3 pi / 2, where
    # sin(theta3) = (e + a) / b is largest: the envelope theorem gives the exact gradient.
    fig = scene_figure(SLIDER_CRANK, _peak_coupler, points=101)
    designs = {"a": [0.1, 0.12], "b": [0.35, 0.4], "e": [0.03, -0.02]}
    s = sensitivities(fig, designs)

    def by_run_scene(p):
        return np.max(run_scene(SLIDER_CRANK, points=101, **p).table()["theta3[rad]"])

    for i in range(2):
        p = {k: v[i] for k, v in designs.items()}
        a, b, e = p["a"], p["b"], p["e"]
        top = np.arcsin((e + a) / b)
        assert s.value[i] == pytest.approx(top, rel=1e-12)
        exact = {"a": 1 / (b * np.cos(top)), "e": 1 / (b * np.cos(top)), "b": -(e + a) / (b * b * np.cos(top))}
        for k in "abe":
            np.testing.assert_allclose(s.grad[k][i], central_fd(by_run_scene, p, k), rtol=GRAD_RTOL)
            np.testing.assert_allclose(s.grad[k][i], exact[k], rtol=1e-9)


# ----------------------------------------------------------------------- fitting
SIGMA = 1e-3  # rad, noise of the synthetic rocker-angle measurements
TRUE = {"b": 3.0, "c": 2.5}


def test_fit_identifies_fourbar_lengths_within_noise():
    rng = np.random.default_rng(7)
    clean = run_scene(FOURBAR, points=POINTS, **TRUE).table()["theta4[rad]"]
    data = clean + SIGMA * rng.standard_normal(POINTS)

    def chi2(cols, p):
        return 0.5 * jnp.sum(jnp.square((cols["theta4[rad]"] - data) / SIGMA))

    objective = scene_figure(FOURBAR, chi2, points=POINTS)
    # Start 0 cannot be assembled (c < a + d - b); the others can.
    starts = {"b": [3.3, 2.8, 3.2, 2.9], "c": [1.0, 2.2, 2.8, 3.4]}
    res = fit(objective, starts, bounds={"b": (2.0, 4.0), "c": (0.5, 4.0)}, optimizer=optax.lbfgs(), steps=100)
    report = res.report()
    assert res.reason[0] == Status.INFEASIBLE and res.steps[0] == 0
    assert "infeasible at the start" in report
    assert f"start {res.best} won" in report and "<- winner" in report
    assert res.reason[res.best] == Status.CONVERGED

    # Independent truth 1: scipy's least squares on run_scene gives the same minimiser.
    def residual(x):
        return (run_scene(FOURBAR, points=POINTS, b=x[0], c=x[1]).table()["theta4[rad]"] - data) / SIGMA

    ls = least_squares(residual, x0=[2.9, 2.6], xtol=1e-14, ftol=1e-14, gtol=1e-14)
    best = res.best_params
    np.testing.assert_allclose([best["b"], best["c"]], ls.x, rtol=1e-7)
    # Independent truth 2: within 4 standard deviations of the truth (Gauss-Newton covariance).
    cov = np.linalg.inv(ls.jac.T @ ls.jac)
    for j, k in enumerate(("b", "c")):
        assert abs(best[k] - TRUE[k]) <= 4 * np.sqrt(cov[j, j])
    assert res.value[res.best] == pytest.approx(0.5 * np.sum(ls.fun**2), rel=1e-9)


def test_fit_checks_arguments():
    with pytest.raises(ValueError, match="bounds for unknown"):
        fit(lambda p: p["x"] ** 2, {"x": [1.0]}, bounds={"y": (0, 1)})
    with pytest.raises(ValueError, match="low <= high"):
        fit(lambda p: p["x"] ** 2, {"x": [1.0]}, bounds={"x": (1, 0)})


def test_fit_reasons_on_a_cheap_objective():
    # f = (x - 2)^2 + penalty for x <= 1.5 ... defined only for x > 0 (log).
    def objective(p):
        return jnp.square(p["x"] - 2.0) + jnp.log(p["x"])

    res = fit(
        objective, {"x": [1.0, -1.0, 3.0]}, optimizer=optax.adam(0.05), steps=30,
        penalty=lambda p: p["x"] - 1.5, penalty_weight=1e4,
    )
    assert res.reason[1] == Status.INFEASIBLE  # log(-1) is NaN at the start
    assert res.reason[0] == Status.MAX_STEPS and res.steps[0] == 30
    assert res.best in (0, 2) and "won" in res.report()
    assert res.history.shape == (31, 3)
