"""The double flap's singular positions (toggles) over a whole crank turn, located by
continuation and refined on the fold (see the package docstring)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ...continuation.solve import solve_stroke
from ...solver.status import Status
from ...solver.xla import jit
from .model import ALPHA_START, COORDS, DEG, SCENE, closed_form_positions, loop_determinants, mechanism

__all__ = ["Toggle", "singular_positions"]


# --------------------------------------------------------------------------- singular positions
@dataclasses.dataclass(frozen=True)
class Toggle:
    """A singular (toggle) position of the scene's branch.

    - `alpha`: crank angle (rad), unwrapped: continuous with the stroke (may exceed 2 pi).
    - `q`: ``{coordinate: angle (rad)}`` there.
    - `loop`: which loop closure is singular (1, 2 or 3): its two unknown links are aligned.
    - `side`: ``"below"`` or ``"above"`` the stroke; the branch cannot be assembled past it.
    - `residual`: ``|Phi|`` there (m); `det`: ``det Phi_q / L^6`` (-), both ~0.
    """

    alpha: float
    q: dict
    loop: int
    side: str
    residual: float
    det: float


def _fold_residual(z, p, L):
    # Bordered system for a limit point: Phi(q, alpha) = 0 and det Phi_q(q, alpha) = 0.
    # At a simple fold its Jacobian is regular, so Newton converges quadratically there,
    # where a Newton on alpha alone (det of the solved q(alpha)) sees a square-root cusp.
    q, u = z[:6], z[6:]
    phi = mechanism.residual(q, u, p) / L
    jac = jax.jacfwd(mechanism.residual)(q, u, p) / L
    return jnp.concatenate([phi, jnp.linalg.det(jac)[None]])


@jit
def _fold_newton(z, p):
    L = mechanism.length_scale(p)

    def body(_, z):
        f = _fold_residual(z, p, L)
        j = jax.jacfwd(_fold_residual)(z, p, L)
        return z - jnp.linalg.solve(j, f)

    z = jax.lax.fori_loop(0, 30, body, z)
    return z, _fold_residual(z, p, L)


_CHUNK = 46  # points per continuation call: the shape run_scene(SCENE, 46) compiles


def singular_positions(p: Mapping | None = None, *, step_deg: float = 1.0, span_deg: float = 360.0) -> tuple[Toggle, Toggle]:
    """The singular positions nearest to the stroke, below and above it, on the scene's branch.

    Found with the engine in two steps: (1) ``solve_stroke`` continues the branch from the
    stroke start downwards and upwards in steps of ``step_deg`` (over at most ``span_deg``);
    the first position that is not ``CONVERGED``, or leaves the branch, brackets the toggle;
    (2) a Newton on the bordered system ``Phi(q, alpha) = 0, det Phi_q = 0`` in ``(q, alpha)``,
    started from the last converged position, pins it to machine precision.  For this
    mechanism they are also the **assembly limits** of the branch: past them loop 2 cannot
    close (``|G - B| < d - p``).

    **Arguments**: `p`: parameter overrides (default: the report's design).

    **Returns** ``(below, above)`` ``Toggle`` records; ``alpha`` is continuous with the
    stroke (the upper toggle of the default design is at 440.94 deg, i.e. 80.94 deg).

    **Raises** ``RuntimeError`` if no toggle lies within ``span_deg`` on one side, or the
    bordered Newton does not converge inside its bracket.
    """
    p = SCENE.params(**(p or {}))
    pj = {k: jnp.asarray(v, float) for k, v in p.items()}
    q_start = closed_form_positions(p, ALPHA_START)
    step = step_deg * DEG
    out = []
    for side, sgn in (("below", -1.0), ("above", 1.0)):
        a0, qa, k_fail = ALPHA_START, q_start, None
        # Chunks of _CHUNK points, each continuing from the previous chunk's last position.
        for _ in range(int(np.ceil(span_deg / step_deg / (_CHUNK - 1)))):
            us = a0 + sgn * step * np.arange(_CHUNK)
            sol = solve_stroke(mechanism, jnp.asarray(us), p, qa)
            good = (np.asarray(sol.status) == Status.CONVERGED) & np.all(np.asarray(sol.branch) > 0, axis=-1)
            if not good[0]:
                raise RuntimeError(f"flap_msd: the branch is lost at alpha = {np.rad2deg(a0):.6g} deg")
            if not np.all(good):
                k_fail = int(np.flatnonzero(~good)[0])
                break
            a0, qa = us[-1], sol.q[-1]
        if k_fail is None:
            raise RuntimeError(f"flap_msd: no singular position within {span_deg} deg {side} the stroke start")
        lo, hi = sorted((us[k_fail - 1], us[k_fail]))
        z, f = _fold_newton(jnp.concatenate([sol.q[k_fail - 1], jnp.asarray(us[k_fail - 1 : k_fail])]), pj)
        z, f = np.asarray(z), np.asarray(f)
        if not (np.all(np.abs(f) < 1e-10) and lo - 1e-9 <= z[6] <= hi + 1e-9):
            raise RuntimeError(f"flap_msd: the toggle {side} the stroke did not converge in its bracket "
                               f"[{np.rad2deg(lo):.6g}, {np.rad2deg(hi):.6g}] deg")
        dets = np.asarray(loop_determinants(z[:6], p))
        scale = np.array([p["b"] * p["c"], p["d"] * p["p"], p["h"] * p["z"]])
        out.append(Toggle(
            alpha=float(z[6]), q=dict(zip(COORDS, map(float, z[:6]))),
            loop=int(np.argmin(np.abs(dets) / scale)) + 1, side=side,
            residual=float(np.linalg.norm(f[:6]) * float(mechanism.length_scale(p))), det=float(f[6]),
        ))
    return out[0], out[1]
