"""Positions written as sums of link vectors, evaluated and printed from one description.

A position in a linkage is a sum of terms, each either a ground point ``x_P + i y_P`` or a
link vector ``l e^{i (theta_1 + theta_2 + ...)}``: a length (a parameter, or a coordinate or
input: a slider's travel, an actuator's length) along a sum of angles (a link's angle
coordinate, the drawing's fixed angles).  The same terms are evaluated (``value``) and
printed the way an engineer writes them (``show``), so ``Linkage.equations()`` prints
exactly what is solved.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from ..mechanism.mechanism import cis

__all__ = ["Term", "value", "show", "negate", "angle_value"]


@dataclasses.dataclass(frozen=True)
class Term:
    """One term of a position: ``sign * (x + i y)`` for a ground point (`xy`: the two
    parameter names), else ``sign * length * e^{i sum(angle)}`` (`angle`: ``((sign, name),
    ...)``, names of coordinates, inputs or parameters)."""

    sign: int
    length: str | None = None
    angle: tuple[tuple[int, str], ...] = ()
    xy: tuple[str, str] | None = None


def negate(terms) -> tuple[Term, ...]:
    """``-terms``."""
    return tuple(dataclasses.replace(t, sign=-t.sign) for t in terms)


def angle_value(angle, values):
    """The sum of signed names in `angle` (rad), read from `values` (a name -> value lookup)."""
    total = None
    for s, name in angle:
        v = values(name) if s > 0 else -values(name)
        total = v if total is None else total + v
    return 0.0 if total is None else total


def lookup(coords, inputs, derived=None):
    """``values(q, u, p)``: a name -> value lookup over coordinates, inputs, parameters and
    the plates' derived angles ``{angle: (len_E_P1, len_E_P2, ang_P1_E_P2)}`` (the angle at
    ``P1`` from ``P2`` to ``E`` of that triangle: ``topology._Builder.frame``)."""
    cset, iset, derived = frozenset(coords), frozenset(inputs), derived if derived is not None else {}

    def values(q, u, p):
        def look(n):
            if n in cset:
                return q[n]
            if n in iset:
                return u[n]
            if n in derived:
                la, lb, a = (look(k) for k in derived[n])
                return jnp.arctan2(lb * jnp.sin(a), la - lb * jnp.cos(a))
            return p[n]

        return look

    return values


def value(terms, values):
    """The complex position (m) of `terms`, names read by ``values(name)``."""
    out = None
    for t in terms:
        if t.xy is not None:
            v = values(t.xy[0]) + 1j * values(t.xy[1])
        else:
            v = values(t.length) * cis(angle_value(t.angle, values))
        v = v if t.sign > 0 else -v
        out = v if out is None else out + v
    return jnp.asarray(0j) if out is None else out


def show_angle(angle) -> str:
    """``theta_rocker + ang_B_O4_E`` for an angle sum."""
    text = ""
    for s, name in angle:
        text += (" - " if s < 0 else " + ") + name if text else ("-" if s < 0 else "") + name
    return text or "0"


def show(terms) -> str:
    """The terms as an engineer writes them: ``x_O2 + i y_O2 + len_O2_A e^{i theta_crank}``."""
    text = ""
    for t in terms:
        if t.xy is not None:
            body = f"{t.xy[0]} + i {t.xy[1]}" if t.sign > 0 or not text else f"({t.xy[0]} + i {t.xy[1]})"
        else:
            ang = show_angle(t.angle)
            body = f"{t.length} e^{{i {ang}}}" if len(t.angle) <= 1 else f"{t.length} e^{{i ({ang})}}"
        if not text:
            text = body if t.sign > 0 else f"-{body}"
        else:
            text += (" + " if t.sign > 0 else " - ") + body
    return text or "0"
