"""Units a person types (``--set`` values) and reads (plots, summaries): exact SI factors."""

import math

import numpy as np
import pytest

from jaxmech.units import for_reading, split_quantity, to_si


@pytest.mark.parametrize("text, unit, si", [
    ("0.3", "m", 0.3),                      # a bare number is SI
    ("275mm", "m", 0.275),
    ("2 ft", "m", 0.6096),                  # 1 ft = 0.3048 m exactly
    ("65deg", "rad", 65 * math.pi / 180),
    ("240 km/h", "m/s", 240 / 3.6),
    ("60 rpm", "rad/s", 2 * math.pi),
    ("28GPa", "Pa", 28e9),
    ("-4%", "-", -0.04),
    ("1.5e3 N mm", "N m", 1.5),
    ("12", "kg m^2", 12.0),                 # a unit without scaled spellings takes bare numbers
    ("12 kg m^2", "kg m^2", 12.0),          # ... and itself
])
def test_to_si(text, unit, si):
    assert to_si(text, unit) == pytest.approx(si, rel=1e-15)


def test_wrong_unit_names_the_accepted_ones():
    with pytest.raises(ValueError, match=r"unit 'mm' does not fit a quantity in rad; give a number in rad or with one of: rad, deg"):
        to_si("65mm", "rad")
    with pytest.raises(ValueError, match="'one' is not a number"):
        split_quantity("one")


def test_for_reading_turns_angles_to_degrees_only():
    v, u = for_reading(np.array([math.pi, -math.pi / 2]), "rad/s^2")
    assert u == "deg/s^2" and np.allclose(v, [180.0, -90.0], rtol=1e-15)
    assert for_reading(2.5, "m") == (2.5, "m") and for_reading(3.0, "N m") == (3.0, "N m")
