"""The document's fixed-point iteration for the SMA flap's equilibrium, its rate and
Newton's history beside it (see the package docstring)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping

import jax.numpy as jnp
import numpy as np

from ...solver.xla import jit
from .model import circle_angle, drive_params, hinge_geometry, point_z, residual, rest_length, stiffness, wire_tensions

__all__ = ["FixedPoint", "fixed_point", "fixed_point_rate", "newton_history"]


# --------------------------------------------------------------------------- the document's fixed point
@dataclasses.dataclass(frozen=True)
class FixedPoint:
    """Result of ``fixed_point``: `theta` (rad), `iterations`, `status` (``"converged"``,
    ``"diverged"``, ``"unreachable"``, ``"2-cycle"`` or ``"maxit"``), `history` (iterates,
    ``(k+1, n)`` rad) and `amplitude` (half the 2-cycle swing, rad; NaN otherwise)."""

    theta: np.ndarray
    iterations: int
    status: str
    history: np.ndarray
    amplitude: np.ndarray


@functools.partial(jit, static_argnums=(3, 4))
def _fp_step(theta, eps, p, n, law):
    # Algorithm 1 (corrected physics), Jacobi sweep over the hinges: the spring tension that
    # balances hinge j at theta^k (eq. 1.15) -> spring length -> theta_j^{k+1} from the spring's
    # inverse kinematics (eq. 1.7 as a circle intersection).
    R = residual(theta, eps, p, n_hinges=n, law=law)
    _, ts = wire_tensions(theta, eps, p, n, law)
    dls = hinge_geometry(theta, p, n)[1][1]
    new = []
    for j in range(1, n + 1):
        d = dls[j - 1, j - 1]
        t_need = -(R[j - 1] - ts[j - 1] * d) / d
        L_need = rest_length(p, "s", j) + (t_need - p[f"F_pre{j}"]) / p[f"k{j}"]
        J = point_z(p, f"J{j}")
        new.append(circle_angle(L_need, point_z(p, f"s{j}A") - J, point_z(p, f"s{j}F") - J, theta[j - 1]))
    return jnp.stack(new)


def fixed_point(p: Mapping, u, *, n_hinges: int = 2, drive: str = "strain", theta0=None, tol: float = 1e-10,
                maxit: int = 200, blowup: float = np.pi, law=None) -> FixedPoint:
    """The document's Algorithm 1 (with its physics corrected), with its iterate history.

    Each iteration takes, for every hinge, the spring tension that balances the moment at the
    current angles (eq. 1.15).  That gives a spring length, and eq. 1.7 (a circle
    intersection) gives the new angle.  The iteration stops when the step is below `tol` (rad),
    an angle exceeds `blowup`, or the spring length asked for is out of the linkage's reach.
    """
    th = np.zeros(n_hinges) if theta0 is None else np.asarray(theta0, float)
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    pj = {k: jnp.asarray(v, float) for k, v in pp.items()}
    hist = [th.copy()]
    nan = np.full(n_hinges, np.nan)
    for it in range(1, maxit + 1):
        new = np.asarray(_fp_step(jnp.asarray(th), eps, pj, n_hinges, law))
        hist.append(new.copy())
        if np.any(np.isnan(new)):
            return FixedPoint(new, it, "unreachable", np.array(hist), nan)
        if np.any(np.abs(new) > blowup):
            return FixedPoint(new, it, "diverged", np.array(hist), nan)
        if np.max(np.abs(new - th)) < tol:
            return FixedPoint(new, it, "converged", np.array(hist), nan)
        th = new
    H = np.array(hist)
    if np.max(np.abs(H[-1] - H[-3])) < 1e-8 and np.max(np.abs(H[-1] - H[-2])) > 1e-6:
        return FixedPoint(th, maxit, "2-cycle", H, np.abs(H[-1] - H[-2]) / 2)
    return FixedPoint(th, maxit, "maxit", H, nan)


@functools.partial(jit, static_argnums=(3, 4))
def _rate_parts(th, eps, p, n, law):
    return stiffness(th, eps, p, n_hinges=n, law=law), hinge_geometry(th, p, n)[1][1]


def fixed_point_rate(p: Mapping, u, theta_star, *, n_hinges=2, drive="strain", law=None):
    """Linear rate of Algorithm 1 about the root: eigenvalues of ``I - D^-1 H`` with
    ``D = diag(k_j (dL_spring,j/dtheta_j)^2)`` and H the stiffness.  Returns
    ``(eigenvalues, spectral radius)``; the scheme converges only if the radius is below 1.
    For one hinge the eigenvalue is ``1 - V''/(k L_s'^2)``."""
    th = jnp.atleast_1d(jnp.asarray(theta_star, float))
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    H, dls = (np.asarray(x) for x in _rate_parts(th, eps, {k: jnp.asarray(v, float) for k, v in pp.items()}, n_hinges, law))
    D = np.diag([float(p[f"k{j}"]) * dls[j - 1, j - 1] ** 2 for j in range(1, n_hinges + 1)])
    ev = np.linalg.eigvals(np.eye(n_hinges) - np.linalg.solve(D, 0.5 * (H + H.T)))
    return ev, float(np.max(np.abs(ev)))


def newton_history(p: Mapping, u, *, n_hinges=2, drive="strain", theta0=None, tol=1e-13, maxit=20, law=None):
    """Plain Newton on the same residual (the engine's ``solve`` adds damping and statuses).
    Returns ``(theta, max |R| per iterate (N m))``: quadratic convergence, for comparison with
    ``fixed_point``."""
    th = jnp.zeros(n_hinges) if theta0 is None else jnp.asarray(theta0, float)
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    f = jit(lambda t, e, q: (residual(t, e, q, n_hinges=n_hinges, law=law), stiffness(t, e, q, n_hinges=n_hinges, law=law)))
    hist = []
    for _ in range(maxit + 1):
        R, H = f(th, eps, pp)
        hist.append(float(jnp.max(jnp.abs(R))))
        if hist[-1] < tol:
            break
        th = th - jnp.linalg.solve(H, R)
    return np.asarray(th), hist
