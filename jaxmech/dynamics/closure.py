"""Closing the loop at a given input from a nearby pose, by a fixed number of Newton steps:
what statics and forward dynamics do at every new input of an iteration or a stage."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..linalg import cond1, solve_small
from ..mechanism import Mechanism
from ..implicit import implicit_root
from ..branches import branch_value, has_branch, on_branch
from ..options import SolverOptions, tolerances

__all__ = ["close_loop"]


def close_loop(mech: Mechanism, u, p, qg, iters: int, options: SolverOptions = SolverOptions()):
    """Close the loop near ``qg`` by ``iters`` plain Newton steps (a step's guess is within
    a step of the root; a fixed count keeps every batch member in step), then
    attach the root to ``(u, p)`` (implicit derivatives).  ``ok`` is False for a residual
    above tolerance, a singular Jacobian (toggle) or a change of assembly branch.

    **Arguments**: `u` ``(dof,)``; `p` parameters (a mapping; the mechanism's are read);
    `qg` ``(m,)`` coordinates near the root (the last step's); `iters` (static);
    `options`: the caller's ``SolverOptions`` (its ``ftol`` and ``cond_max`` judge the root).

    **Returns** ``(q, ok)``: ``q (m,)`` differentiable in `u` and `p` (NaN where not ok)."""
    stop = jax.lax.stop_gradient
    us, ps = stop(u), jax.tree_util.tree_map(stop, p)
    _, ftol, cond_max = tolerances(options, qg.dtype)
    def newton_step(_, q):
        return q - solve_small(jax.jacfwd(mech.residual)(q, us, ps), mech.residual(q, us, ps))

    q = jax.lax.fori_loop(0, iters, newton_step, stop(qg))
    r = mech.residual(q, us, ps)
    scale = mech.length_scale(ps)
    ok = jnp.all(jnp.isfinite(q)) & (jnp.linalg.norm(r) <= ftol * scale)
    s_ = jnp.where(jnp.asarray(mech.coord_is_length()), scale, 1.0)
    ok = ok & (cond1(jax.jacfwd(mech.residual)(q, us, ps) * s_[None, :] / scale) <= cond_max)
    if has_branch(mech):
        ok = ok & on_branch(jnp.sign(branch_value(mech, stop(qg), us, ps)), branch_value(mech, q, us, ps))
    q_star = jnp.where(ok, q, jnp.nan)
    return implicit_root(mech, q_star, ok, u, p), ok

