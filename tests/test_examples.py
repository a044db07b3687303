"""Worked studies in examples/: four-bar path synthesis and the tolerance study, checked
against truths they do not use (a known mechanism's coupler curve by numpy circle
intersection; batched Monte Carlo)."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from matplotlib.figure import Figure  # noqa: E402

from examples import path_synthesis as ps  # noqa: E402
from examples import tolerance_study as ts  # noqa: E402

from jaxmech.design import synthesize_path  # noqa: E402
from jaxmech.design.tolerance import analyse  # noqa: E402

MC_SAMPLES = 10_000
# The sample standard deviation of M normal draws has a relative standard error
# 1/sqrt(2(M-1)) = 0.71 %; the 5 % band is 7 of those, so a miss is a real
# disagreement of the linear theory, not sampling noise.
STD_RTOL = 0.05


def _numpy_coupler(p, alpha):
    # Independent of the library: circle intersection in numpy on the design's assembly mode
    # (the sign of sin(theta4 - theta3)).
    th2 = alpha - p["phi"]
    A = p["a"] * np.exp(1j * th2)
    AO = p["d"] - A
    cos_ = (p["b"] ** 2 + np.abs(AO) ** 2 - p["c"] ** 2) / (2 * p["b"] * np.abs(AO))
    th3 = np.angle(AO) + p.get("mode", 1.0) * np.arccos(cos_)
    return p["x0"] + 1j * p["y0"] + np.exp(1j * p["phi"]) * (A + (p["px"] + 1j * p["py"]) * np.exp(1j * th3))


def test_path_synthesis_passes_through_a_reachable_curve():
    targets, alpha = ps.target_curve("coupler", 10)
    np.testing.assert_allclose(targets, _numpy_coupler(ps.CRANK_ROCKER, alpha), rtol=0, atol=1e-13)
    res = synthesize_path(targets, "closed", alpha=alpha, starts=256, shapes=1000)  # the library's function
    pts = _numpy_coupler(res.design, alpha)
    assert np.max(np.abs(pts - targets)) < 1e-9  # through every target at its crank angle
    assert res.error < 1e-9 and res.starts_at_best() >= 1
    # the drawing's pins: A on the crank circle, B at b from A and c from the rocker pivot
    O2, O4, A, B = ps.pins(res.design, alpha)
    d = res.design
    np.testing.assert_allclose(np.abs(A - O2), d["a"], rtol=1e-12)
    np.testing.assert_allclose(np.abs(B - A), d["b"], rtol=1e-12)
    np.testing.assert_allclose(np.abs(B - O4), d["c"], rtol=1e-12)
    ax = Figure().subplots()
    ps.draw(ax, res, np.stack([targets.real, targets.imag], axis=1), "timed")  # (N, 2) targets drawn as complex ones
    assert len(ax.lines) == 1 + 10 + 3 and "starts at the best" in ax.get_title()


def test_tolerance_first_order_matches_monte_carlo_for_small_tolerances():
    study = ts.tolerance_study(ts.fourbar_figures, ts.FOURBAR_DESIGNS, 1e-4, samples=MC_SAMPLES, names=ts.FOURBAR_NAMES)
    for fig, row in study.items():
        assert np.all(row["failed"] == 0), fig
        np.testing.assert_allclose(row["std_linear"], row["std_mc"], rtol=STD_RTOL, err_msg=fig)
        assert np.all(row["worst"] >= row["rss"])  # sum |J t| >= sqrt(sum (J t)^2)
    with pytest.raises(ValueError, match="not design parameters"):
        analyse(ts.fourbar_figures, ts.FOURBAR_DESIGNS, {"q": 1e-3})
