"""Mass properties of a uniform link from its joints: a bar between two, a plate spanned by
three or more (the convex hull of the joints, as a lamina of uniform density)."""

from __future__ import annotations

import numpy as np

__all__ = ["link_mass_properties"]


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of points ``(n, 2)``: Andrew's monotone chain."""
    pts = sorted(set(map(tuple, points)))
    if len(pts) <= 2:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def link_mass_properties(points, mass: float) -> tuple[complex, float]:
    """``(centre of mass (complex, m), inertia about it (kg m^2))`` of a uniform link of
    `mass` (kg) through `points` (complex, m): a point mass for one point; a slender bar
    between the two farthest points when they are collinear (``m L^2 / 12``); otherwise the
    uniform plate of their convex hull (a triangle: ``m (a^2 + b^2 + c^2) / 36``)."""
    z = np.asarray(points, complex)
    if z.size == 1:
        return complex(z[0]), 0.0
    xy = np.stack([z.real, z.imag], axis=1)
    hull = _hull(xy)
    x, y = hull[:, 0], hull[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    c = x * y1 - x1 * y
    area = 0.5 * np.sum(c) if len(hull) >= 3 else 0.0
    span = np.max(np.abs(z[:, None] - z[None, :]))
    if len(hull) < 3 or abs(area) <= 1e-12 * span * span:
        i, j = np.unravel_index(np.argmax(np.abs(z[:, None] - z[None, :])), (z.size, z.size))
        return complex(0.5 * (z[i] + z[j])), float(mass * abs(z[i] - z[j]) ** 2 / 12.0)
    gx = np.sum((x + x1) * c) / (6.0 * area)
    gy = np.sum((y + y1) * c) / (6.0 * area)
    # polar second moment of the polygon about the origin, then about its centroid
    j_o = np.sum(c * (x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1)) / 12.0
    j_g = j_o - area * (gx * gx + gy * gy)
    return complex(gx, gy), float(mass * j_g / area)
