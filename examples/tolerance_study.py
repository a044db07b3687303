"""Tolerance study: how far manufacturing tolerances move a four-bar's coupler path and a
flap's travel and peak torque, first order (``jaxmech.design.tolerance.analyse``) against batched
Monte Carlo (``jaxmech.design.tolerance.monte_carlo``).

- ``GENERAL_FOURBAR``: a four-bar anywhere in the plane through the engine's position solve
  (``jaxmech.solve``, implicit-function derivatives); ``pose`` solves one crank angle.
- ``fourbar_figures``: for ``GENERAL_FOURBAR`` at the crank angle
  ``FOURBAR_ALPHA``: the coupler point's position (``x``, ``y``, m: its path deviation
  components), the rocker angle ``theta4`` (rad) and the transmission angle (rad).
- ``flap_figures``: for the MSD double flap (``design_problems.flap_state``): second-flap
  travel (rad) and peak motor torque over the stroke (N m).
- ``tolerance_study``: both methods side by side for a batch of designs, tolerances
  ``+-scale`` relative to every length and pivot coordinate (``t_k = scale |p_k|``, or
  ``scale`` x the largest length for a coordinate at zero).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxmech.design.tolerance import analyse, monte_carlo
from jaxmech.mechanism import Mechanism, cis
from jaxmech import Status, solve

__all__ = ["FOURBAR_DESIGNS", "FOURBAR_ALPHA", "GENERAL_FOURBAR", "PARAMS", "fourbar_figures", "flap_figures", "pose",
           "relative_tolerances", "tolerance_study"]

PARAMS = ("x0", "y0", "phi", "a", "b", "c", "d", "px", "py")


def _coupler(q, u, p):
    return p.x0 + 1j * p.y0 + cis(p.phi) * (p.a * cis(u.theta2) + (p.px + 1j * p.py) * cis(q.theta3))


#: A four-bar anywhere in the plane: crank a at (x0, y0), ground d at angle phi, coupler
#: b, rocker c; coupler point (px, py) in the coupler's frame (x along A->B).  Angles
#: theta2..4 from the ground line; the open assembly (sin(theta4 - theta3) > 0).
GENERAL_FOURBAR = Mechanism(
    name="general_fourbar",
    coords=("theta3", "theta4"),
    inputs=("theta2",),
    params=PARAMS,
    lengths=("a", "b", "c", "d", "px", "py", "x0", "y0"),
    signed=("px", "py", "x0", "y0"),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d],
    points={"P": _coupler},
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)


def _guess(p, theta2):
    # Open assembly by circle intersection: B on circles about A (radius b) and O4 (c).
    A = p["a"] * jnp.exp(1j * theta2)
    AO = p["d"] - A
    dist = jnp.abs(AO)
    cos_ = (p["b"] ** 2 + dist**2 - p["c"] ** 2) / (2 * p["b"] * dist)
    theta3 = jnp.angle(AO) + jnp.arccos(cos_)  # NaN where the loop cannot close
    B = A + p["b"] * jnp.exp(1j * theta3)
    return jnp.stack([theta3, jnp.angle(B - p["d"])])


def pose(p, theta2):
    """``(q, P, ok)`` at ground-frame crank angle ``theta2`` (rad): ``q = (theta3,
    theta4)`` by the engine's solve (differentiable by the implicit rule), the coupler
    point ``P`` (complex, m), and whether the design assembles there (else placeholders)."""
    g = _guess(jax.lax.stop_gradient(p), theta2)
    assembled = jnp.all(jnp.isfinite(g))
    sol = solve(GENERAL_FOURBAR, theta2, p, jnp.where(assembled, g, 0.0))
    ok = assembled & (sol.status == Status.CONVERGED)
    q = jnp.where(ok, sol.q, 0.0)
    P = GENERAL_FOURBAR.point("P", q, jnp.reshape(theta2, (1,)), p)
    return q, P, ok

FOURBAR_ALPHA = np.deg2rad(60.0)  #: absolute crank angle of the four-bar figures (rad)

#: Two crank-rocker designs (m, rad).
FOURBAR_DESIGNS = {
    "x0": np.array([0.0, 0.2]), "y0": np.array([0.0, -0.1]), "phi": np.array([0.1, 0.0]),
    "a": np.array([1.0, 0.8]), "b": np.array([3.0, 2.6]), "c": np.array([2.5, 2.2]), "d": np.array([3.5, 3.0]),
    "px": np.array([1.5, 1.0]), "py": np.array([0.8, 1.2]),
}


def fourbar_figures(p):
    """``{x, y, theta4, transmission}`` of one general four-bar design at ``FOURBAR_ALPHA``."""
    q, P, ok = pose(p, FOURBAR_ALPHA - p["phi"])
    out = {"x": P.real, "y": P.imag, "theta4": q[1], "transmission": jnp.arccos(jnp.abs(jnp.cos(q[1] - q[0])))}
    return {k: jnp.where(ok, v, jnp.nan) for k, v in out.items()}


@functools.cache
def _flap_figures(points: int):
    from .design_problems import FLAP_TRAVEL, flap_state

    state = flap_state(points, 0.0)

    def figures(p):
        s = state(p)
        return {"travel": jnp.where(s.ok, s.eq[1] + FLAP_TRAVEL, jnp.nan), "peak_torque": jnp.where(s.ok, jnp.max(s.peak), jnp.nan)}

    return figures


def flap_figures(points: int = 31):
    """``figure(p) -> {travel (rad), peak_torque (N m)}`` of the MSD flap over loops 2-3's
    lengths and pivot B's offsets (``design_problems.FLAP_VARS``), ``points`` samples."""
    return _flap_figures(points)


def relative_tolerances(designs, names, scale: float) -> dict[str, float]:
    """``+-scale |p_k|`` of the first design for every name (a coordinate at zero gets
    ``scale`` x the largest length)."""
    big = max(abs(float(np.atleast_1d(designs[k])[0])) for k in names)
    return {k: scale * (abs(float(np.atleast_1d(designs[k])[0])) or big) for k in names}


def tolerance_study(figure, designs, scale: float, *, samples: int = 10_000, names=None, seed: int = 0):
    """First-order spread against Monte Carlo for relative tolerances ``+-scale``.

    **Returns** ``{figure: {"std_linear", "std_mc", "ratio", "rss", "worst", "mean_shift"}}``
    with ``(D,)`` arrays: ``ratio = std_linear / std_mc`` (1 while linear theory holds),
    ``mean_shift`` = MC mean minus nominal (the curvature's bias), in figure units.
    """
    names = tuple(names or designs)
    tol = relative_tolerances(designs, names, scale)
    lin = analyse(figure, designs, tol)
    mc = monte_carlo(figure, designs, tol, samples, seed=seed)
    return {k: {"std_linear": lin.std[k], "std_mc": mc[k]["std"], "ratio": lin.std[k] / mc[k]["std"], "rss": lin.rss[k],
                "worst": lin.worst[k], "mean_shift": mc[k]["mean"] - lin.value[k], "failed": mc[k]["failed"]} for k in lin.value}


FOURBAR_NAMES = PARAMS[:2] + PARAMS[3:]  # every length and pivot coordinate (phi exact)
