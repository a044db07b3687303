"""Four-bar closed forms (numpy and JAX) and the common test design, shared by the benchmarks.

Loop ``a e^{i t2} + b e^{i t3} - c e^{i t4} - d = 0`` (jaxmech's ``fourbar_mechanism``), open
assembly ``sin(t4 - t3) > 0``.  Positions by circle intersection, velocities and accelerations
by the differentiated loop solved with Cramer's rule:

    i a w2 e2 + i b w3 e3 - i c w4 e4 = 0
    (i a al2 - a w2^2) e2 + (i b al3 - b w3^2) e3 - (i c al4 - c w4^2) e4 = 0
"""

from __future__ import annotations

import numpy as np

#: The crank-rocker of jaxmech's FOURBAR scene (m), its drive (rad/s, rad/s^2) and a guess.
DESIGN = {"a": 1.0, "b": 3.0, "c": 2.5, "d": 3.5}
OMEGA = 2.0
ALPHA = 0.5
GUESS = (0.2, 1.2)


def closed_form(xp, th2, a, b, c, d, w2=OMEGA, al2=ALPHA):
    """(t3, t4, w3, w4, al3, al4) for crank angles `th2`; `xp` is numpy or jax.numpy.

    NaN where the design cannot be assembled.
    """
    c2, s2 = xp.cos(th2), xp.sin(th2)
    ax, ay = a * c2, a * s2
    ex, ey = d - ax, -ay  # from the crank pin A to the rocker pivot O4
    f2 = ex * ex + ey * ey
    f = xp.sqrt(f2)
    x = (b * b - c * c + f2) / (2.0 * f)
    h = xp.sqrt(b * b - x * x)  # NaN when the triangle inequality fails
    ux, uy = ex / f, ey / f
    bx, by = x * ux - h * uy, x * uy + h * ux  # B - A: the coupler vector, open branch
    rx, ry = ax + bx - d, ay + by  # B - O4: the rocker vector
    t3 = xp.arctan2(by, bx)
    t4 = xp.arctan2(ry, rx)
    # velocities: b w3 (i e3) - c w4 (i e4) = -a w2 (i e2); with v = (x, y) of a vector,
    # i v = (-y, x).  det of [[-by, ry], [bx, -rx]] (columns: w3 coefficient, -w4 coefficient)
    det = by * rx - bx * ry  # = b c sin(t4 - t3)
    vx, vy = -(-ay) * w2, -(ax) * w2  # right-hand side -a w2 i e2
    w3 = (vx * (-rx) - ry * vy) / det
    w4 = ((-by) * vy - bx * vx) / det
    # accelerations: b al3 (i e3) - c al4 (i e4) = -(a al2 i e2 - a w2^2 e2 - b w3^2 e3 + c w4^2 e4)
    gx = -(-ay * al2 - ax * w2 * w2 - bx * w3 * w3 + rx * w4 * w4)
    gy = -(ax * al2 - ay * w2 * w2 - by * w3 * w3 + ry * w4 * w4)
    al3 = (gx * (-rx) - ry * gy) / det
    al4 = ((-by) * gy - bx * gx) / det
    return t3, t4, w3, w4, al3, al4


def closed_form_numpy(th2, a, b, c, d, w2=OMEGA, al2=ALPHA):
    return closed_form(np, np.asarray(th2, float), a, b, c, d, w2, al2)


def random_designs(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """`n` crank-rocker designs around ``DESIGN`` (+-0.2 m): all assemble over a full turn
    (Grashof: a + d <= 4.9 < 5.1 <= b + c, crank shortest)."""
    rng = np.random.default_rng(seed)
    return {k: v + rng.uniform(-0.2, 0.2, n) for k, v in DESIGN.items()}


def angle_error(x, ref):
    """Largest |x - ref| with angles compared modulo 2 pi (rad)."""
    d = np.angle(np.exp(1j * (np.asarray(x, float) - np.asarray(ref, float))))
    return float(np.nanmax(np.abs(d))) if np.size(d) else float("nan")


def max_error(x, ref):
    x, ref = np.asarray(x, float), np.asarray(ref, float)
    return float(np.max(np.abs(x - ref))) if x.size else float("nan")
