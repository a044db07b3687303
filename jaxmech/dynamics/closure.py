"""Closing the loop at a given input from a nearby pose, by a fixed number of Newton steps:
what statics and forward dynamics do at every new input of an iteration or a stage."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..solver.linalg import cond1, small_norm, solve_small
from ..mechanism.mechanism import Mechanism
from ..solver.implicit import implicit_positions
from ..solver.newton import evaluator
from ..mechanism.branches import branch_value, has_branch, on_branch
from ..solver.options import SolverOptions, tolerances

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
    # judged in the solver's scaled variables (newton.evaluator): residual over its scale
    # (the length scale, or the mechanism's residual_scale), lengths over the length scale
    r, js = evaluator(mech, us, ps, qg.dtype)[0](q)
    ok = jnp.all(jnp.isfinite(q)) & (small_norm(r) <= ftol)
    ok = ok & (cond1(js) <= cond_max)
    if has_branch(mech):
        ok = ok & on_branch(jnp.sign(branch_value(mech, stop(qg), us, ps)), branch_value(mech, q, us, ps))
    q_star = jnp.where(ok, q, jnp.nan)
    return implicit_positions(mech, q_star, ok, u, p), ok

