"""jaxmech.design.tolerance on figures whose spread is known in closed form."""

import math
from statistics import NormalDist

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech.design.tolerance import analyse, monte_carlo, wilson_interval, yield_estimate  # noqa: E402


def _figures(p):
    return {"lin": 2 * p["x"] - 3 * p["y"], "prod": p["x"] * p["y"], "bad": jnp.where(p["x"] > 0, p["x"], jnp.nan)}


def test_linear_spread_worst_case_and_monte_carlo():
    designs = {"x": np.array([1.0, 2.0, -1.0]), "y": np.array([0.5, -1.0, 3.0])}
    tol = {"x": 0.03, "y": 0.06}
    res = analyse(_figures, designs, tol)
    # Closed forms: J(lin) = (2, -3); J(prod) = (y, x).
    np.testing.assert_allclose(res.worst["lin"], 2 * 0.03 + 3 * 0.06, rtol=1e-14)
    np.testing.assert_allclose(res.rss["lin"], np.hypot(2 * 0.03, 3 * 0.06), rtol=1e-14)
    np.testing.assert_allclose(res.rss["prod"], np.hypot(designs["y"] * 0.03, designs["x"] * 0.06), rtol=1e-14)
    np.testing.assert_allclose(res.std["lin"], res.rss["lin"] / 3, rtol=1e-14)
    assert list(res.ok) == [True, True, False]  # the third design's "bad" figure is NaN
    mc = monte_carlo(_figures, designs, tol, 20_000, chunk=5_000)
    # A linear figure: the sample std of 2e4 normal draws is within 4 standard errors
    # (1/sqrt(2 M) = 0.5 %) of the exact one.
    np.testing.assert_allclose(mc["lin"]["std"], res.std["lin"], rtol=4 / np.sqrt(2 * 20_000))
    assert mc["bad"]["failed"][2] == 20_000 and mc["bad"]["failed"][0] == 0
    with pytest.raises(ValueError, match=">= 0"):
        analyse(_figures, designs, {"x": -1.0})


def test_old_import_path_warns_and_gives_the_same_functions():
    import importlib
    import sys

    sys.modules.pop("jaxmech.tolerance", None)
    with pytest.warns(DeprecationWarning, match="jaxmech.design.tolerance"):
        old = importlib.import_module("jaxmech.tolerance")
    assert old.analyse is analyse and old.monte_carlo is monte_carlo


# --------------------------------------------------------------------------- yields
def _wilson_closed_form(k, n, confidence):
    """The Wilson (1927) score interval as usually printed, from the sample proportion:
    (p + z^2/(2n) -+ z sqrt(p(1-p)/n + z^2/(4n^2))) / (1 + z^2/n)."""
    z = NormalDist().inv_cdf(0.5 + confidence / 2)
    p = k / n
    centre = p + z * z / (2 * n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return (centre - half) / (1 + z * z / n), (centre + half) / (1 + z * z / n)


def test_wilson_interval_is_the_closed_form():
    cases = [(0, 10, 0.95), (10, 10, 0.95), (3, 10, 0.95), (81, 100, 0.95), (512, 1000, 0.9), (7, 2000, 0.99), (1, 1, 0.5)]
    k, n, c = (np.array(v) for v in zip(*cases))
    for (ki, ni, ci) in cases:
        lo, hi = wilson_interval(ki, ni, ci)
        np.testing.assert_allclose([lo, hi], _wilson_closed_form(ki, ni, ci), rtol=1e-12, atol=1e-15, err_msg=str((ki, ni, ci)))
    lo, hi = wilson_interval(k[:4], n[:4])  # arrays, default 95 %
    np.testing.assert_allclose(np.stack([lo, hi], 1), [_wilson_closed_form(*x, 0.95) for x in zip(k[:4], n[:4])], rtol=1e-12,
                               atol=1e-15)
    # Brown, Cai & DasGupta's no-success case: n = 10, k = 0 at 95 %: [0, 0.2775]
    assert wilson_interval(0, 10)[0] == 0.0 and round(float(wilson_interval(0, 10)[1]), 4) == 0.2775
    with pytest.raises(ValueError, match="confidence must be in"):
        wilson_interval(3, 10, 95)
    with pytest.raises(ValueError, match="0 <= within <= samples"):
        wilson_interval(11, 10)


def _line(p):
    return {"f": 2.0 * p["x"] + 1.0, "g": jnp.where(p["x"] > 0, p["x"], jnp.nan)}


def _normal_cdf(x):
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def test_yield_interval_covers_the_true_yield():
    """f = 2 x + 1 with x ~ N(0, 1) (t = 3 = 3 sigma): f ~ N(1, 2^2), so the yield of
    -1 <= f <= 4 is Phi(1.5) - Phi(-1) exactly; the first-order estimate is exact for a linear
    figure, and the 95 % Wilson interval of 200 samples covers the truth in at least 93 of 100
    seeded repetitions (coverage of a correct 95 % interval: 95 +- 2.2)."""
    truth = _normal_cdf((4 - 1) / 2) - _normal_cdf((-1 - 1) / 2)
    covered = 0
    for seed in range(100):
        est = yield_estimate(_line, {"x": 0.0}, {"x": 3.0}, {"f": (-1.0, 4.0)}, 200, seed=seed, chunk=200)
        y = est.figures["f"]
        assert y.within[0] == round(y.fraction[0] * 200) and y.low[0] <= y.fraction[0] <= y.high[0]
        covered += bool(y.low[0] <= truth <= y.high[0])
    assert covered >= 93, covered
    np.testing.assert_allclose(y.linear, truth, rtol=1e-12)  # first order: exact for a linear figure
    np.testing.assert_array_equal(est.joint.within, y.within)  # one figure: the joint yield is its own
    assert "all at once" in est.table()


def test_designs_that_fail_count_out_of_spec():
    """g = x where x > 0, NaN (the design fails) elsewhere; nominal x = 0 and -1.  With no
    limits at all, the yield is the fraction that evaluates: every sample is either within or
    failed, none lost to a NaN; the interval covers P(x > 0) = 1/2 and 1 - Phi(1)."""
    est = yield_estimate(_line, {"x": np.array([0.0, -1.0])}, {"x": 3.0}, {"g": (None, None), "f": (-np.inf, np.inf)}, 4000)
    g = est.figures["g"]
    np.testing.assert_array_equal(g.within + est.failed, 4000)
    assert np.all(est.failed > 0) and np.all(np.isfinite(g.fraction))
    for i, p in enumerate((0.5, 1 - _normal_cdf(1.0))):
        assert g.low[i] <= p <= g.high[i]
    np.testing.assert_array_equal(est.figures["f"].within, 4000)  # f never fails, all within (-inf, inf)
    np.testing.assert_array_equal(est.joint.within, g.within)
    assert np.isnan(est.joint.linear).all()  # two figures: no first-order joint yield
    assert np.isnan(g.linear[1]) and np.isnan(g.linear[0])  # nominal x = 0 and -1: g not differentiable / NaN there
    with pytest.raises(ValueError, match=r"spec names \['h'\]"):
        yield_estimate(_line, {"x": 0.0}, {"x": 3.0}, {"h": (0, 1)}, 10)
    with pytest.raises(ValueError, match=r"spec\['f'\] needs low <= high"):
        yield_estimate(_line, {"x": 0.0}, {"x": 3.0}, {"f": (1, 0)}, 10)
    with pytest.raises(ValueError, match=r"spec\['f'\] must be a pair"):
        yield_estimate(_line, {"x": 0.0}, {"x": 3.0}, {"f": 1.0}, 10)
