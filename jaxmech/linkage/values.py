"""Reading what a person writes in a linkage's drawing: names, numbers with a unit, points.

A number is SI, or a string with a unit (``"280mm"``, ``"30deg"``, ``"2 kN/m"``).  A unit of
one quantity is ``units.to_si``'s; a compound one (a stiffness ``N/m`` or ``N m/rad``, a
damping ``N s/m`` or ``N m s/rad``) is read factor by factor: each word of the numerator
and the denominator is a unit of force, length, time or angle (``"2 kN/mm"`` is 2e6 N/m,
``"0.5 N m/deg"`` is 28.6 N m/rad).
"""

from __future__ import annotations

import math
import re

from ..units import split_quantity, to_si

__all__ = ["read_names", "read_number", "read_point", "wrap_angle"]

#: The compound units read word by word: stiffnesses and dampings.
COMPOUND = ("N/m", "N m/rad", "N s/m", "N m s/rad")

#: The quantities a word of a compound unit may measure, each with its SI base factors
#: ("N m" is one quantity, so that "Nm" and "kN m" read as in ``units``).
_FACTORS = (("N m", ("N", "m")), ("N", ("N",)), ("m", ("m",)), ("s", ("s",)), ("rad", ("rad",)))


def read_names(value, what: str) -> tuple[str, ...]:
    """Point or link names from a list or a string ``"A B C"`` (commas allowed)."""
    if isinstance(value, str):
        value = value.replace(",", " ").split()
    try:
        names = tuple(value)
    except TypeError:
        raise ValueError(f"{what}: give point names as a list or a string 'A B C', got {value!r}") from None
    for n in names:
        if not isinstance(n, str) or not n.isidentifier():
            raise ValueError(f"{what}: {n!r} is not a valid name (use Python identifiers: letters, digits, _)")
    return names


def _word(word: str, si: str) -> tuple[tuple[str, ...], float]:
    """``(SI base units, factor to SI)`` of one word of a compound unit of `si`."""
    for quantity, base in _FACTORS:
        try:
            return base, to_si(f"1 {word}", quantity)
        except ValueError:
            continue
    raise ValueError(f"unit {word!r} in a quantity in {si} is not a unit of force, length, time or angle")


def _side(text: str, si: str) -> tuple[list, float]:
    """The sorted SI base units of one side of a ``/`` and its factor to SI."""
    base, factor = [], 1.0
    for word in re.split(r"[\s*]+", text.strip()):
        if word:
            b, f = _word(word, si)
            base += b
            factor *= f
    return sorted(base), factor


def _compound(text: str, si: str) -> float:
    """The SI value of ``"2 kN/m"`` for a quantity in `si` (``"N/m"``): the words of each side
    of the ``/`` converted one by one, their base units checked against `si`'s."""
    value, given = split_quantity(text)
    if not given:
        return value
    num, _, den = given.partition("/")
    want_num, want_den = si.partition("/")[0], si.partition("/")[2]
    (bn, fn), (bd, fd) = _side(num, si), _side(den, si)
    if (bn, bd) != (_side(want_num, si)[0], _side(want_den, si)[0]):
        raise ValueError(f"unit {given!r} does not fit a quantity in {si}; give a number in {si} or a unit like it")
    return value * fn / fd


def read_number(v, unit: str, what: str) -> float:
    """A finite number: `v` in SI `unit`, or a string with a unit; ``ValueError`` naming `what`."""
    try:
        x = (_compound(v, unit) if unit in COMPOUND else to_si(v, unit)) if isinstance(v, str) else float(v)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{what}: {v!r} is not a number in {unit} ({err})") from None
    if not math.isfinite(x):
        raise ValueError(f"{what}: must be finite, got {v!r}")
    return x


def read_point(v, what: str, unit: str = "m") -> complex:
    """``(x, y)`` (numbers in `unit`, or strings with a unit) as a complex number."""
    if isinstance(v, complex):
        return v
    try:
        x, y = v
    except (TypeError, ValueError):
        raise ValueError(f"{what}: give (x, y) in {unit}, got {v!r}") from None
    return complex(read_number(x, unit, what), read_number(y, unit, what))


def wrap_angle(a: float) -> float:
    """`a` (rad) wrapped to ``(-pi, pi]``."""
    return math.atan2(math.sin(a), math.cos(a))
