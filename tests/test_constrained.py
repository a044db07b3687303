"""jaxmech.design.constrained on a minimax problem whose answer is known in closed form."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech.design.constrained import Stated, minimize  # noqa: E402


def _state(x):
    # Two paraboloids; their maximum is least on the line x = 0.  Equality y = 0.5,
    # inequality x >= 0.2, and a region x > 0.9 that "cannot be assembled".
    f = jnp.stack([(x["x"] - 1) ** 2 + x["y"] ** 2, (x["x"] + 1) ** 2 + x["y"] ** 2])
    return Stated(peak=f, eq=jnp.stack([x["y"] - 0.5]), le=jnp.stack([0.2 - x["x"]]), ok=x["x"] < 0.9)


def test_minimax_with_equality_and_limit_meets_closed_form():
    # Optimum: x = 0.2 (the limit is active), y = 0.5, peak (1.2)^2 + 0.25 = 1.69.
    starts = {"x": np.array([0.5, 0.8, 2.0]), "y": np.array([0.0, 1.0, -1.0])}
    res = minimize(_state, starts, {"x": (-2.0, 3.0), "y": (-2.0, 2.0)}, peak_scale=1.0)
    assert res.best >= 0
    for i in range(3):
        assert res.violation[i] <= 1e-8
        assert res.params["x"][i] == pytest.approx(0.2, abs=1e-7)
        assert res.params["y"][i] == pytest.approx(0.5, abs=1e-8)
        assert res.value[i] == pytest.approx(1.69, abs=1e-7)
    assert "pulled" in res.message[2]  # start x = 2 cannot be assembled: moved towards start 0
    assert "won" in res.report()


def test_minimize_checks_its_arguments():
    with pytest.raises(ValueError, match="bounds missing"):
        minimize(_state, {"x": [0.5], "y": [0.0]}, {"x": (0.0, 1.0)})
    with pytest.raises(ValueError, match="method"):
        minimize(_state, {"x": [0.5], "y": [0.0]}, {"x": (0.0, 1.0), "y": (0.0, 1.0)}, method="BFGS")


def test_old_import_path_warns_and_gives_the_same_functions():
    import importlib
    import sys

    sys.modules.pop("jaxmech.constrained", None)
    with pytest.warns(DeprecationWarning, match="jaxmech.design.constrained"):
        old = importlib.import_module("jaxmech.constrained")
    assert old.minimize is minimize and old.Stated is Stated
