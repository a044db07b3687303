"""A linkage's drawing from what a textbook gives (ground pivots, link lengths, plate
angles, straight guides and an input value), built point by point as a draughtsman does
with compasses: ``drawing_from_lengths``, whose points ``Linkage(points=...)`` takes.

Each point is placed from points already placed, by one of four closed forms:

- the driver's point: its ground pivot plus the crank's length in the input's direction;
- a plate angle: a corner of a rigid plate at its distance from a placed corner, turned by
  the plate's angle from the direction to another placed corner (no choice to make);
- a dyad: two lengths to placed points, an intersection of two circles (two answers, the
  point's assembly mode ``modes[point] = +1`` or ``-1``);
- a guide: a length to a placed point and a fixed straight line the point runs on, an
  intersection of the circle and the line (two answers, ``modes`` again).

No iteration and no solver: the drawing is the closed forms' to round-off (Python floats,
double precision), the same as one measured off the linkage.  Every length and angle that
is not used to place a point (an over-determined drawing) is checked against the drawing
the others make.
"""

from __future__ import annotations

import cmath
import dataclasses
import math
from collections.abc import Mapping

from ..units import to_si

__all__ = ["drawing_from_lengths"]

#: Relative disagreement (of the drawing's largest length) allowed between a length, angle
#: or guide given but not used to place a point and the drawing the others make.
CONSISTENT = 1e-9


def _si(v, unit: str, what: str) -> float:
    """A number, or a string with a unit (``"280mm"``, ``"30deg"``), in SI; finite."""
    try:
        x = float(to_si(v, unit) if isinstance(v, str) else v)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{what}: {v!r} is not a number in {unit} ({err})") from None
    if math.isfinite(x):
        return x
    raise ValueError(f"{what}: must be finite, got {v!r}")


def _points_named(key, count: int, what: str) -> tuple[str, ...]:
    """`count` distinct point names from a tuple or a string (``"A B"``, ``"A-B"``)."""
    names = tuple(key.replace("-", " ").replace(",", " ").split()) if isinstance(key, str) else tuple(key)
    if len(names) != count or len(set(names)) != count or not all(isinstance(n, str) and n.isidentifier() for n in names):
        raise ValueError(f"{what}: give {count} distinct point names (identifiers) as a tuple or a string, got {key!r}")
    return names


def _xy(v, what: str) -> complex:
    """A position ``(x, y)`` (m) or ``x + iy`` as a complex number."""
    try:
        x, y = (v.real, v.imag) if isinstance(v, complex) else v
    except (TypeError, ValueError):
        raise ValueError(f"{what}: give (x, y) in m, got {v!r}") from None
    return complex(_si(x, "m", what), _si(y, "m", what))


@dataclasses.dataclass
class _Given:
    """What the user gave, read and checked; `placed` grows as the points are placed."""

    placed: dict  # point -> complex position (m)
    lengths: list  # [(a, b, length m)] in the order given
    angles: list  # [(d, c, e, angle rad)]: the angle at c from c->d to c->e, CCW
    guides: dict  # point -> (a point of the line (complex), its direction (unit complex))
    modes: dict  # point -> +1 or -1
    driver: tuple | None  # (pivot, point, input angle rad)
    how: dict = dataclasses.field(default_factory=dict)  # point -> "dyad" / "guide" (those that took a mode)

    def length(self, a: str, b: str):
        return next((L for x, y, L in self.lengths if {x, y} == {a, b}), None)

    def reach(self, x: str) -> list:
        """``[(placed point, length)]``: the lengths from `x` to placed points, in the order given."""
        return [(b if a == x else a, L) for a, b, L in self.lengths if x in (a, b) and (b if a == x else a) in self.placed]


def _read_lengths(lengths) -> list:
    if not isinstance(lengths, Mapping) or not lengths:
        raise ValueError("lengths: give {(point, point): length} (m, or a string with a unit: '280mm')")
    out, seen = [], set()
    for key, v in lengths.items():
        a, b = _points_named(key, 2, f"lengths[{key!r}]")
        if frozenset((a, b)) in seen:
            raise ValueError(f"lengths: {a}-{b} is given twice")
        seen.add(frozenset((a, b)))
        L = _si(v, "m", f"lengths[{key!r}]")
        if L <= 0:
            raise ValueError(f"lengths[{key!r}]: a length must be positive, got {L}")
        out.append((a, b, L))
    return out


def _read_guides(guides, ground: dict) -> dict:
    out = {}
    for x, spec in dict(guides or {}).items():
        if not isinstance(spec, Mapping) or "angle" not in spec or "through" not in spec:
            raise ValueError(f"guides[{x!r}]: give {{'through': a ground point or (x, y), 'angle': direction}}, got {spec!r}")
        through = spec["through"]
        if isinstance(through, str) and through not in ground:
            raise ValueError(f"guides[{x!r}]: through={through!r} is not a ground point; give one of {list(ground)} or (x, y)")
        base = ground[through] if isinstance(through, str) else _xy(through, f"guides[{x!r}].through")
        out[x] = (base, cmath.exp(1j * _si(spec["angle"], "rad", f"guides[{x!r}].angle")))
    return out


def _read_driver(driver, value, ground: dict, given: _Given):
    if driver is None:
        if value is not None:
            raise ValueError("input: given without driver=; name the crank as driver=(ground pivot, point)")
        return None
    pivot, x = _points_named(driver, 2, "driver")
    if pivot not in ground:
        raise ValueError(f"driver={driver!r}: the crank's pivot {pivot!r} is not a ground point (ground: {list(ground)})")
    if given.length(pivot, x) is None:
        raise ValueError(f"driver={driver!r}: give the crank's length in lengths[({pivot!r}, {x!r})]")
    if value is None:
        raise ValueError(f"driver={driver!r}: give input= the crank's angle (rad or '60deg'), from {pivot} to {x}, CCW from +x")
    return pivot, x, _si(value, "rad", "input")


def _read(ground, lengths, angles, guides, driver, value, modes) -> _Given:
    if not isinstance(ground, Mapping) or not ground:
        raise ValueError("ground: give the ground pivots as {name: (x, y)} (m)")
    placed = {_points_named(k, 1, f"ground[{k!r}]")[0]: _xy(v, f"ground[{k!r}]") for k, v in ground.items()}
    angle_list = []
    for key, v in dict(angles or {}).items():
        d, c, e = _points_named(key, 3, f"angles[{key!r}]")
        angle_list.append((d, c, e, _si(v, "rad", f"angles[{key!r}]")))
    mode_of = {}
    for x, s in dict(modes or {}).items():
        if s not in (1, -1):
            raise ValueError(f"modes[{x!r}]: an assembly mode is +1 or -1, got {s!r}")
        mode_of[x] = int(s)
    given = _Given(placed, _read_lengths(lengths), angle_list, _read_guides(guides, placed), mode_of, None)
    given.driver = _read_driver(driver, value, placed, given)
    for x in list(given.guides) + list(mode_of):
        if x in placed:
            raise ValueError(f"{x!r} is a ground point: it needs no guide and no mode")
    return given


# --------------------------------------------------------------------------- the closed forms
def _by_driver(given: _Given, x: str):
    if given.driver is None or given.driver[1] != x:
        return None
    pivot, _, angle = given.driver
    return given.placed[pivot] + given.length(pivot, x) * cmath.exp(1j * angle)


def _by_angle(given: _Given, x: str):
    """A plate's corner: at its distance from the angle's vertex, turned by the angle from
    (or to) the direction to the angle's other placed corner."""
    for d, c, e, angle in given.angles:
        other = e if x == d else d
        L = given.length(c, x)
        if x in (d, e) and c in given.placed and other in given.placed and L is not None:
            toward = cmath.phase(given.placed[other] - given.placed[c])
            return given.placed[c] + L * cmath.exp(1j * (toward + angle if x == e else toward - angle))
    return None


def _mode(given: _Given, x: str, choice: str) -> int:
    if x not in given.modes:
        raise ValueError(f"point {x!r} has two positions, {choice}; choose one with modes={{{x!r}: +1}} or -1")
    return given.modes[x]


def _by_dyad(given: _Given, x: str):
    """A dyad's joint: on the circles about two placed points, left (+1) or right (-1) of the
    line from the first of them to the second (the first two of `x`'s lengths, in the order
    given, whose other ends are placed)."""
    reach = given.reach(x)
    if len(reach) < 2:
        return None
    (k1, r1), (k2, r2) = reach[:2]
    p1, p2 = given.placed[k1], given.placed[k2]
    d = abs(p2 - p1)
    a = (r1 * r1 - r2 * r2 + d * d) / (2 * d) if d > 0 else math.inf
    h2 = r1 * r1 - a * a
    if not h2 >= -1e-12 * max(r1, r2) ** 2:  # round-off of a dyad drawn straight is a straight dyad
        raise ValueError(f"point {x!r} cannot be placed: the dyad {k1}-{x} = {r1:.6g} m, {x}-{k2} = {r2:.6g} m does not close "
                         f"across {k1}-{k2} = {d:.6g} m (it closes where |{r1:.6g} - {r2:.6g}| <= {d:.6g} <= {r1:.6g} + {r2:.6g}); "
                         "check the lengths and the input")
    sign = _mode(given, x, f"on the circles {k1}-{x} = {r1:.6g} m and {k2}-{x} = {r2:.6g} m: +1 to the left of the line "
                           f"{k1} -> {k2}, -1 to its right")
    given.how[x] = "dyad"
    return p1 + (a + 1j * sign * math.sqrt(max(h2, 0.0))) * (p2 - p1) / d


def _by_guide(given: _Given, x: str):
    """A slider's point: on its guide line and on the circle about a placed point, the
    intersection farther along the guide's direction (+1) or the nearer one (-1)."""
    reach = given.reach(x)
    if x not in given.guides or not reach:
        return None
    (k, r), (base, e) = reach[0], given.guides[x]
    rel = base - given.placed[k]
    along = (rel * e.conjugate()).real
    disc = along * along - abs(rel) ** 2 + r * r
    if not disc >= -1e-12 * r * r:
        raise ValueError(f"point {x!r} cannot be placed: {k}-{x} = {r:.6g} m does not reach its guide "
                         f"({abs((rel * e.conjugate()).imag):.6g} m from {k}); check the lengths, the guide and the input")
    sign = _mode(given, x, f"on its guide and the circle {k}-{x} = {r:.6g} m: +1 the one farther along the guide's "
                           "direction, -1 the nearer")
    given.how[x] = "guide"
    return base + (-along + sign * math.sqrt(max(disc, 0.0))) * e


def _stuck(given: _Given, todo: list) -> str:
    what = "; ".join(f"{x} has lengths to {[b if a == x else a for a, b, _ in given.lengths if x in (a, b)]}" for x in todo)
    return (f"points {todo} cannot be placed from the points placed ({list(given.placed)}): {what}.  A point is placed by "
            "two lengths to placed points (a dyad), a length and a plate angle (angles=), a length and a guide (guides=), "
            "or as the driver's point; give the missing length, angle or driver")


# --------------------------------------------------------------------------- checks
def _check_consistent(given: _Given):
    """Every length, angle and guide agrees with the drawing (those not used to place a
    point, in an over-determined drawing); every mode given was used."""
    pts = given.placed
    tol = CONSISTENT * max(L for *_, L in given.lengths)
    for a, b, L in given.lengths:
        if abs(abs(pts[b] - pts[a]) - L) > tol:
            raise ValueError(f"lengths[({a!r}, {b!r})] = {L:.9g} m, but the other lengths put {a} and {b} "
                             f"{abs(pts[b] - pts[a]):.9g} m apart: the lengths over-determine the drawing and disagree")
    for d, c, e, angle in given.angles:
        drawn = cmath.phase((pts[e] - pts[c]) / (pts[d] - pts[c]))
        if abs(cmath.phase(cmath.exp(1j * (drawn - angle)))) * max(abs(pts[e] - pts[c]), abs(pts[d] - pts[c])) > tol:
            raise ValueError(f"angles[({d!r}, {c!r}, {e!r})] = {angle:.9g} rad, but the lengths draw {drawn:.9g} rad there")
    for x, (base, e) in given.guides.items():
        if abs(((pts[x] - base) * e.conjugate()).imag) > tol:
            raise ValueError(f"guides[{x!r}]: the lengths put {x} off its guide")
    for x in given.modes:
        if x not in given.how:
            raise ValueError(f"modes[{x!r}]: {x!r} is placed without a choice of two positions (or is no point of the "
                             "drawing); a mode is given only to a dyad's or a guide's point")


def drawing_from_lengths(ground: Mapping, lengths: Mapping, *, angles: Mapping | None = None, guides: Mapping | None = None,
                         driver=None, input=None, modes: Mapping | None = None) -> dict[str, tuple[float, float]]:
    """The points of a linkage's drawing, ``{name: (x, y)}`` (m), from its ground pivots,
    lengths, plate angles, guides and input value, for ``jm.Linkage(points=...)``.

    **Arguments**

    - `ground`: ``{point: (x, y)}``: the points whose coordinates are known (m; strings
      with a unit, ``"280mm"``, are accepted everywhere a number is).
    - `lengths`: ``{(a, b): length}`` (m): the distance between two points of one link (a
      bar's length, a plate's side, the crank's length), keyed by a tuple or ``"a b"``.
    - `angles`: ``{(d, c, e): angle}`` (rad, or ``"30deg"``): a plate's fixed angle at its
      corner `c`, counter-clockwise from the direction ``c -> d`` to ``c -> e`` (what
      ``Linkage`` calls the parameter ``ang_d_c_e``).
    - `guides`: ``{point: {"through": ground point or (x, y), "angle": direction}}``: the
      point runs on that fixed straight line (a slider on a ground guide; give ``Linkage``
      the same direction in ``sliders``).
    - `driver`, `input`: the crank as ``(ground pivot, point)`` and its angle (rad or
      ``"60deg"``), the direction from the pivot to the point, counter-clockwise from +x
      (``Linkage``'s ``theta_<crank>`` when the point is the first other point of the
      crank).  A linkage driven by an actuator needs none: its length is a length.
    - `modes`: ``{point: +1 or -1}``: the assembly mode of each point that has two
      positions.  A dyad's point, placed by two lengths to placed points ``k1`` and
      ``k2`` (the first two of its lengths, in the order given, whose other ends are placed
      before it): +1 to the left of the line from ``k1`` to ``k2`` (the triangle
      ``k1 k2 point`` counter-clockwise), -1 to its right.  A guided point: +1 the
      intersection farther along the guide's direction, -1 the nearer one.  The message for
      a missing mode names ``k1`` and ``k2``.

    The points are placed one at a time, each from points already placed: the driver's
    point, then (as they become possible) a plate's corner by its angle, a dyad's point by
    two circles, a guided point by a circle and its line.  A length, angle or guide not
    needed to place a point is checked against the drawing (relative ``CONSISTENT``).

    **Returns** ``{point: (x, y)}``, the ground points first, then in the order placed.

    **Raises** ``ValueError`` naming the point and its lengths for a dyad that does not
    close (or a length that does not reach its guide), the points that cannot be placed
    from known points and what they lack, a missing or superfluous mode, and lengths or
    angles that disagree with the drawing the others make.
    """
    given = _read(ground, lengths, angles, guides, driver, input, modes)
    named = [x for a, b, _ in given.lengths for x in (a, b)] + [x for t in given.angles for x in t[:3]] + list(given.guides)
    todo = [x for x in dict.fromkeys(named) if x not in given.placed]
    while todo:
        for x in todo:
            at = next((p for rule in (_by_driver, _by_angle, _by_dyad, _by_guide) if (p := rule(given, x)) is not None), None)
            if at is not None:
                given.placed[x] = at
                todo.remove(x)
                break
        else:
            raise ValueError(_stuck(given, todo))
    _check_consistent(given)
    return {x: (p.real, p.imag) for x, p in given.placed.items()}
