"""Units a person types and reads: values with a unit (``65deg``, ``275 mm``) to SI, and
SI angles to degrees for plots and summaries.

The library computes in SI (m, rad, s, kg, N); files (CSV) stay SI.  Only what a person
reads (plot axes, summary tables) shows angles in degrees, and only what a person types
(``jaxmech run --set``) may carry a unit other than SI.
"""

from __future__ import annotations

import math
import re

import numpy as np

__all__ = ["split_quantity", "to_si", "for_reading"]

_DEG = math.pi / 180.0

# SI unit -> {accepted spelling: factor to SI}.  A unit not listed accepts only itself.
_SCALES = {
    "m": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "km": 1e3, "ft": 0.3048, "in": 0.0254},
    "rad": {"rad": 1.0, "deg": _DEG},
    "s": {"s": 1.0, "ms": 1e-3, "min": 60.0},
    "kg": {"kg": 1.0, "g": 1e-3},
    "N": {"N": 1.0, "kN": 1e3},
    "N m": {"N m": 1.0, "Nm": 1.0, "N*m": 1.0, "N mm": 1e-3, "Nmm": 1e-3, "kN m": 1e3},
    "m/s": {"m/s": 1.0, "mm/s": 1e-3, "km/h": 1 / 3.6},
    "rad/s": {"rad/s": 1.0, "deg/s": _DEG, "rpm": 2 * math.pi / 60.0},
    "Pa": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9},
    "m^2": {"m^2": 1.0, "mm^2": 1e-6, "cm^2": 1e-4},
    "-": {"-": 1.0, "%": 1e-2},
    # a DC motor's (jaxmech simulate's [simulate.motor])
    "ohm": {"ohm": 1.0, "mohm": 1e-3, "kohm": 1e3},
    "H": {"H": 1.0, "mH": 1e-3, "uH": 1e-6},
    "V": {"V": 1.0, "mV": 1e-3, "kV": 1e3},
    "A": {"A": 1.0, "mA": 1e-3},
    "N m/A": {"N m/A": 1.0, "Nm/A": 1.0, "mN m/A": 1e-3, "V s/rad": 1.0},
}

_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan))\s*(.*?)\s*$", re.IGNORECASE)


def split_quantity(text: str) -> tuple[float, str]:
    """``"65deg"`` -> ``(65.0, "deg")``; ``"0.3"`` -> ``(0.3, "")`` (no unit: SI).

    **Raises** ``ValueError`` when ``text`` does not start with a number."""
    m = _NUMBER.match(text)
    if m is None:
        raise ValueError(f"{text!r} is not a number")
    return float(m.group(1)), " ".join(m.group(2).split())


def to_si(text: str, unit: str) -> float:
    """The SI value of ``text`` (a number, optionally followed by a unit) for a quantity
    whose SI unit is ``unit``; a bare number is taken as SI.

    ``to_si("65deg", "rad")`` is 1.1345 rad, ``to_si("275 mm", "m")`` is 0.275 m.

    **Raises** ``ValueError`` naming the accepted units when the unit does not fit.
    """
    value, given = split_quantity(text)
    if not given:
        return value
    scales = _SCALES.get(unit, {unit: 1.0})
    if given not in scales:
        raise ValueError(f"unit {given!r} does not fit a quantity in {unit}; give a number in {unit} or with one of: {', '.join(scales)}")
    return value * scales[given]


def for_reading(values, unit: str):
    """``(values, unit)`` as a person reads them: angles (``rad``, ``rad/s``, ``rad/s^2``)
    in degrees, everything else unchanged.  ``values`` may be a number or an array."""
    if unit == "rad" or unit.startswith("rad/"):
        return np.degrees(values), "deg" + unit[3:]
    return values, unit
