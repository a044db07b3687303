"""Mass properties of a uniform link from its joints: a point mass at one, a slender bar
between two (or between the farthest of collinear ones), a plate spanned by three or more
(the convex hull of the joints, as a lamina of uniform density).

The shape (which joints, in which order) is read once from the drawing (``mass_shape``);
the centre of mass and the inertia are then functions of the joints' positions
(``shape_properties``, traceable), so they follow the drawing's lengths and angles wherever
a sweep or a design moves them."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..mechanism.mechanism import cis
from .terms import angle_value, value

__all__ = ["shape_properties", "centre_function", "link_mass_properties", "derived_shapes"]


def _hull(names, z: np.ndarray) -> list:
    """The names of the convex hull's corners, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted({(float(v.real), float(v.imag)): n for n, v in zip(names, z)}.items())
    if len(pts) <= 2:
        return [n for _, n in pts]

    def cross(o, a, b):
        return (a[0][0] - o[0][0]) * (b[0][1] - o[0][1]) - (a[0][1] - o[0][1]) * (b[0][0] - o[0][0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return [n for _, n in lower[:-1] + upper[:-1]]


def mass_shape(names, points) -> tuple[str, tuple[str, ...]]:
    """``(kind, corners)`` of a uniform link through the named `points` (complex, m) at the
    drawing: ``("point", (a,))``; ``("bar", (a, b))``, the two farthest points where all are
    collinear; ``("plate", corners)``, the convex hull's corners counter-clockwise."""
    names = tuple(names)
    z = np.asarray([complex(p) for p in points], complex)
    if z.size == 1:
        return "point", names
    span = np.abs(z[:, None] - z[None, :])
    i, j = np.unravel_index(np.argmax(span), span.shape)
    corners = _hull(names, z)
    if len(corners) >= 3:
        zc = np.asarray([z[names.index(n)] for n in corners])
        area = 0.5 * np.sum(zc.real * np.roll(zc.imag, -1) - np.roll(zc.real, -1) * zc.imag)
        if abs(area) > 1e-12 * span[i, j] ** 2:
            return "plate", tuple(corners)
    return "bar", (names[i], names[j])


def shape_properties(kind: str, z, mass, xp=jnp):
    """``(centre of mass (complex, m), inertia about it (kg m^2))`` of a uniform link of
    `mass` (kg) whose `kind` (``mass_shape``) has its corners at `z` (complex, m, in the
    shape's order): ``m L^2 / 12`` for a bar, the polygon's centroid and polar second
    moment for a plate (a triangle: ``m (a^2 + b^2 + c^2) / 36``).  ``xp``: ``jax.numpy``
    (traced, inside a model) or ``numpy`` (concrete values: no small programs compiled)."""
    z = xp.stack([xp.asarray(v) for v in z]) if isinstance(z, (list, tuple)) else xp.asarray(z)
    if kind == "point":
        return z[0], xp.zeros((), xp.real(z).dtype) * mass
    if kind == "bar":
        return 0.5 * (z[0] + z[1]), mass * xp.abs(z[1] - z[0]) ** 2 / 12.0
    x, y = xp.real(z), xp.imag(z)
    x1, y1 = xp.roll(x, -1), xp.roll(y, -1)
    c = x * y1 - x1 * y
    area = 0.5 * xp.sum(c)
    gx = xp.sum((x + x1) * c) / (6.0 * area)
    gy = xp.sum((y + y1) * c) / (6.0 * area)
    # polar second moment of the polygon about the origin, then about its centroid
    j_o = xp.sum(c * (x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1)) / 12.0
    j_g = j_o - area * (gx * gx + gy * gy)
    return gx + 1j * gy, mass * j_g / area


def centre_function(kind: str, ring, base, th, values):
    """``fn(q, u, p)``: the centre of a link's shape (``shape_properties``' `kind`) whose
    corners are the position terms `ring` (``linkage.terms``), as ``G = E + c e^(i theta)``:
    ``E`` the link's entry (`base`, the terms of the point the tree enters it through),
    ``theta`` its angle terms `th`, and ``c`` the centre seen from ``E`` in the link's own
    frame, a function of the parameters alone.  So the shape's formula is evaluated once
    per sample and never differentiated along the stroke (a Watt six-bar's per-sample
    dynamics program: 6275 -> 3771 equations).  Where a corner is not one side away from
    the entry in the link's frame, the shape of the corners' positions themselves.
    `values(q, u, p)` gives the terms' lookup."""
    tails = [t[len(base):] for t in ring]
    if any(t[:len(base)] != base or len(tail) > 1 or (tail and tail[0].angle[:len(th)] != th) for t, tail in zip(ring, tails)):
        return lambda q, u, p: shape_properties(kind, [value(t, values(q, u, p)) for t in ring], 1.0)[0]
    if not any(tails):
        return lambda q, u, p: value(base, values(q, u, p))

    def local(look):
        corners = []
        for tail in tails:
            if not tail:
                corners.append(jnp.asarray(0j))
                continue
            v = look(tail[0].length) * cis(angle_value(tail[0].angle[len(th):], look))
            corners.append(v if tail[0].sign > 0 else -v)
        return shape_properties(kind, corners, 1.0)[0]

    def fn(q, u, p):
        look = values(q, u, p)
        return value(base, look) + local(look) * cis(angle_value(th, look))

    return fn


def link_mass_properties(points, mass: float) -> tuple[complex, float]:
    """``(centre of mass (complex, m), inertia about it (kg m^2))`` of a uniform link of
    `mass` (kg) through `points` (complex, m): ``shape_properties`` of its ``mass_shape``."""
    names = [str(k) for k in range(len(points))]
    kind, corners = mass_shape(names, points)
    g, j = shape_properties(kind, [complex(points[int(n)]) for n in corners], float(mass), np)
    return complex(g), float(j)


def derived_shapes(mass_spec: dict, joints: dict, links: dict, points: dict) -> tuple:
    """``Topology.mass_shapes``: for each link whose centre of mass or inertia is not given
    (``mass_spec``: ``{link: (mass, centre or None, inertia or None)}``), the uniform shape
    through its joints (through its points where it has fewer than two joints) that the
    drawing (``points``: ``{name: complex}``) gives it, ``(link, kind, corners, centre
    derived, inertia derived)``."""
    out = []
    for link, (_, c, J) in mass_spec.items():
        if c is not None and J is not None:
            continue
        names = joints[link] if len(joints[link]) >= 2 else tuple(links[link])
        kind, corners = mass_shape(names, [points[x] for x in names])
        out.append((link, kind, corners, c is None, J is None))
    return tuple(out)
