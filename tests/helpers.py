"""Independent derivative truths and the four-bar / slider-crank / inverted slider-crank
closed forms used by the tests."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxmech import Mechanism, cis


def central_diff(f, x, h=1e-3):
    """Sixth-order central difference of a scalar-argument function (float64).

    Error ~ h^6 f^(7) / 140 plus roundoff ~ eps |f| / h: about 1e-13 relative for smooth f.
    """
    c = [(1, 45.0), (2, -9.0), (3, 1.0)]
    return sum(w * (np.asarray(f(x + k * h)) - np.asarray(f(x - k * h))) for k, w in c) / (60.0 * h)


# ----------------------------------------------------------------------- four-bar
def fourbar_closed(theta2, a, b, c, d, sign=1.0):
    """Closed-form four-bar (loop a e^{i t2} + b e^{i t3} - c e^{i t4} - d = 0).

    ``sign=+1`` is the open assembly (sin(theta4 - theta3) > 0).  Returns (theta3, theta4);
    NaN where the triangle inequality fails.
    """
    bx = d - a * jnp.cos(theta2)
    by = -a * jnp.sin(theta2)
    f = jnp.hypot(bx, by)
    g = jnp.arctan2(by, bx)
    cos_beta = (b * b + f * f - c * c) / (2 * b * f)
    beta = jnp.arccos(cos_beta)  # angle at the coupler joint between b and the diagonal
    theta3 = g + sign * beta
    # c e^{i t4} = a e^{i t2} + b e^{i t3} - d
    v = a * cis(theta2) + b * cis(theta3) - d
    theta4 = jnp.angle(v)
    return theta3, theta4


def fourbar_feasible(theta2, a, b, c, d):
    f = np.hypot(d - a * np.cos(theta2), a * np.sin(theta2))
    return (f <= b + c) & (f >= abs(b - c)), f


# ----------------------------------------------------------------------- slider-crank
def slider_closed(theta2, a, b, e, sign=1.0):
    """Offset slider-crank: a e^{i t2} + b e^{i t3} - x - i e = 0; sign=+1: cos(theta3) > 0."""
    s3 = (e - a * jnp.sin(theta2)) / b
    theta3 = jnp.where(sign > 0, jnp.arcsin(s3), jnp.pi - jnp.arcsin(s3))
    x = a * jnp.cos(theta2) + b * jnp.cos(theta3)
    return theta3, x


# ----------------------------------------------------------------------- inverted slider-crank
inverted_slider_mechanism = Mechanism(
    name="inverted_slider_crank",
    coords=("theta12", "theta13"),
    inputs=("s34",),
    params=("a1", "a2", "alpha0"),
    lengths=("a1", "a2", "s34"),
    # The arc-track thesis's loop: a2 e^{i(alpha0+theta12)} = a1 e^{i alpha0} + s34 e^{i(alpha0+theta13)}
    constraints=lambda q, u, p: [
        p.a2 * cis(p.alpha0 + q.theta12) - p.a1 * cis(p.alpha0) - u.s34 * cis(p.alpha0 + q.theta13)
    ],
    branch=lambda q, u, p: jnp.sin(q.theta13),
)


def inverted_closed(s, a1, a2, alpha0, sign=1.0):
    """Closed form of the inverted slider-crank; sign=+1: sin(theta13) > 0."""
    cos13 = (a2 * a2 - a1 * a1 - s * s) / (2 * a1 * s)
    theta13 = sign * jnp.arccos(cos13)
    theta12 = jnp.angle(a1 + s * cis(theta13))
    return theta12, theta13


def inverted_feasible(s, a1, a2):
    return (s >= abs(a2 - a1)) & (s <= a1 + a2)


# ----------------------------------------------------------------------- six-bar (two loops)
#: Watt-II six-bar: four-bar O2-A-B-O4 plus a second dyad from the rocker's extension E
#: (at angle theta4 + gamma, length e) through link f to a rocker g pivoted at O6 = (h, k).
sixbar_mechanism = Mechanism(
    name="watt_sixbar",
    coords=("theta3", "theta4", "theta5", "theta6"),
    inputs=("theta2",),
    params=("a", "b", "c", "d", "e", "f", "g", "h", "k", "gamma"),
    lengths=("a", "b", "c", "d", "e", "f", "g", "h", "k"),
    signed=("h", "k"),
    constraints=lambda q, u, p: [
        p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d,
        p.d + p.e * cis(q.theta4 + p.gamma) + p.f * cis(q.theta5) - p.g * cis(q.theta6) - (p.h + 1j * p.k),
    ],
)

SIXBAR_P = dict(a=1.0, b=3.0, c=2.5, d=3.5, e=1.5, f=3.0, g=2.0, h=5.0, k=2.0, gamma=0.6)
