"""The live view (``jaxmech.viz.live``): what ``update`` draws is the run's geometry, a design that
cannot be assembled is shown (not raised), and the widgets call the same function."""

import jax

jax.config.update("jax_enable_x64", True)

import math  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech.viz.live import live_view, sliders, update  # noqa: E402

N = 101  # the four-bar's compiled stroke of the CLI and plot tests
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def view():
    return live_view("fourbar", points=N, output="transmission_angle", index=25)


def test_update_draws_the_new_design(view):
    """After ``update(view, a=1.2)`` the crank is drawn from O2 to A = a e^{i theta2} and the
    rocker's end B lies at c from O4, the transmission curve is the run's (in degrees)."""
    status = update(view, a=1.2)
    assert view.ok and status == "fourbar: {'CONVERGED': 101}" and view.png.startswith(PNG)
    th2 = 2 * math.pi * 25 / (N - 1)
    crank = next(ln for ln in view.drawer.ax.lines if ln.get_gid() == "link")
    np.testing.assert_allclose(crank.get_xydata(), [[0, 0], [1.2 * math.cos(th2), 1.2 * math.sin(th2)]], atol=1e-12)
    x, y = view.curve.get_data()
    np.testing.assert_allclose(x[25], math.degrees(th2), rtol=1e-14)
    # transmission angle at the drawn pose from the drawn points: angle A-B-O4
    A, B, O4 = (complex(*pt) for pt in (crank.get_xydata()[1], *_rocker(view)))
    mu = abs(np.angle((A - B) / (O4 - B)))
    assert y[25] == pytest.approx(math.degrees(min(mu, math.pi - mu)), rel=1e-9)


def _rocker(view):
    links = [ln for ln in view.drawer.ax.lines if ln.get_gid() == "link"]
    o4, b = links[2].get_xydata()
    return b, o4


def test_unassemblable_design_is_shown_not_raised(view):
    # a good design first, here: pytest-xdist may run this test before the one that drew it
    assert update(view, a=1.2) == "fourbar: {'CONVERGED': 101}"
    status = update(view, a=10.0)  # the crank longer than the other three links allow
    assert not view.ok and status.startswith("cannot draw this design: ") and "cannot be assembled" in status
    assert view.result.params["a"] == 1.2  # the last good design stays drawn
    assert view.status_text.get_text().startswith("cannot draw") and view.png.startswith(PNG)
    assert update(view, a=1.0) == "fourbar: {'CONVERGED': 101}" and view.ok


def test_update_names_the_closest_parameter(view):
    with pytest.raises(ValueError, match="has no parameter 'aa'; did you mean 'a'"):
        update(view, aa=1.0)


def test_sliders_call_update(view):
    ui = sliders(view, ["a", "b"])
    a = ui.children[0].children[0].children[0]
    assert a.description == "a [m]" and a.min == pytest.approx(0.7) and a.max == pytest.approx(1.3)
    a.value = 1.1  # what dragging the slider does
    assert view.params["a"] == 1.1 and view.result.params["a"] == 1.1 and ui.children[2].value == view.png
