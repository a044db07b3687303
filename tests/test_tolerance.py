"""jaxmech.design.tolerance on figures whose spread is known in closed form."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech.design.tolerance import analyse, monte_carlo  # noqa: E402


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
