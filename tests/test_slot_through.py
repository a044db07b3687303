"""A straight slot given by a point it passes through (``through=``, as a slider's guide):
the same linkage as the slot given by its angle, in Python and in a linkage file."""

import jax

jax.config.update("jax_enable_x64", True)

import math  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

# The quick-return drive of docs/from_a_drawing.md: the crank's pin A in a slot of the rocker
# O4 C along the line through O4 and A.  Aimed from A at O4, the slot's direction is
# atan2(0 - 0.3, 0 - 0.1) = 251.565... deg (global, in the drawing).
POINTS = {"O2": (0.0, 0.3), "A": (0.1, 0.3), "O4": (0.0, 0.0), "C": (0.0, 0.6)}
LINKS = {"crank": "O2 A", "rocker": "O4 C"}
ANGLE = math.atan2(0.0 - 0.3, 0.0 - 0.1)  # rad
U = np.radians(np.linspace(0.0, 360.0, 25))


def quick_return(slot):
    return jm.Linkage(POINTS, LINKS, ground="O2 O4", driver="crank", slots={"A": {"on": "rocker", **slot}},
                      mass={"crank": 0.2, "rocker": 1.5}, moments={"rocker": -5.0}, gravity=9.81, name="qr")


def assert_same(a: jm.Linkage, b: jm.Linkage):
    assert list(a.params) == list(b.params)
    for k in a.params:
        assert a.params[k] == pytest.approx(b.params[k], rel=1e-14, abs=1e-15), k
    sa, sb = a.statics(U), b.statics(U)
    np.testing.assert_allclose(np.asarray(sa.q), np.asarray(sb.q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sa.tau), np.asarray(sb.tau), rtol=1e-11, atol=1e-12)


def test_slot_through_a_point_equals_the_slot_at_its_angle():
    through, angle = quick_return({"through": "O4"}), quick_return({"angle": ANGLE})
    assert through.slot_angles["A"] == pytest.approx(ANGLE, abs=1e-15)
    assert_same(through, angle)
    # and the travel is measured from A towards O4: at the drawing's input, the pin has not moved
    assert abs(float(through.solve(np.array([0.0]))["s_A"][0])) < 1e-12


def test_slot_through_in_a_file(tmp_path):
    path = tmp_path / "qr.toml"
    path.write_text('name = "qr"\nground = "O2 O4"\ndriver = "crank"\ngravity = 9.81\n'
                    "[points]\n" + "".join(f"{k} = [{x}, {y}]\n" for k, (x, y) in POINTS.items())
                    + '[links]\ncrank = "O2 A"\nrocker = "O4 C"\n'
                    + '[slots]\nA = { on = "rocker", through = "O4" }\n'
                    + '[mass]\ncrank = 0.2\nrocker = 1.5\n[moments]\nrocker = -5.0\n')
    assert_same(jm.load_linkage(path), quick_return({"angle": f"{math.degrees(ANGLE)!r}deg"}))


def test_slot_through_its_own_pin_is_refused():
    with pytest.raises(ValueError, match=r"slots\['A'\]: through= 'A' is where 'A' is"):
        quick_return({"through": "A"})
