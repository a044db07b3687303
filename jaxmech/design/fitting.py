"""Multi-start fitting with optax: every start of a batch at once, with which start won and
why each of the others stopped."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ..solver.status import Status, status_message
from ..solver.xla import jit
from .figures import as_batch, figure_value

__all__ = ["FitResult", "fit"]


# =========================================================================== fitting
@dataclasses.dataclass(frozen=True)
class FitResult:
    """Result of a multi-start fit.

    - `params`: ``{name: (S,)}`` each start's final (last feasible) parameters.
    - `value`: ``(S,)`` objective there (``inf`` where even the start was infeasible).
    - `reason`: ``(S,)`` ``Status`` codes; `steps`: ``(S,)`` steps taken.
    - `history`: ``(steps + 1, S)`` objective after each step (once a start has stopped
      its last value is repeated; ``inf`` for a start infeasible from the beginning).
    - `best`: index of the winning start (lowest objective among those that neither
      diverged nor were infeasible from the start), ``-1`` if none.
    """

    params: dict
    value: np.ndarray
    reason: np.ndarray
    steps: np.ndarray
    history: np.ndarray
    best: int
    tol: float
    xtol: float

    @property
    def best_params(self) -> dict[str, float]:
        """The winning start's parameters as ``{name: float}`` (``ValueError`` if none won)."""
        if self.best < 0:
            raise ValueError("fit: no start produced a feasible design")
        return {k: float(v[self.best]) for k, v in self.params.items()}

    def message(self, i: int) -> str:
        """Why start ``i`` stopped, in words."""
        r = Status(int(self.reason[i]))
        if r == Status.INFEASIBLE:  # the fit's reading of the code
            if self.steps[i] == 0:
                return "infeasible at the start: objective not finite or the design did not solve"
            return "infeasible: objective not finite or the design did not solve; kept the last feasible design"
        if r == Status.CONVERGED:
            return f"converged: objective and parameter changes below tolerance (tol={self.tol:g}, xtol={self.xtol:g})"
        if r == Status.MAX_STEPS:
            return "ran out of steps while still improving"
        return status_message(r)

    def report(self) -> str:
        """Which start won, and why each of the others stopped."""
        n = len(self.value)
        lines = []
        if self.best >= 0:
            b = self.best
            lines.append(
                f"fit: {n} starts; start {b} won with objective {self.value[b]:.6g} after {int(self.steps[b])} steps "
                f"({self.message(b)})"
            )
            lines.append("  " + ", ".join(f"{k} = {v:.10g}" for k, v in self.best_params.items()))
        else:
            lines.append(f"fit: {n} starts; none produced a feasible design")
        lines.append(f"{'start':>5}  {'objective':>14}  {'steps':>5}  why it stopped")
        for i in range(n):
            tag = "  <- winner" if i == self.best else ""
            lost = ""
            if i != self.best and self.best >= 0 and np.isfinite(self.value[i]):
                lost = f"; lost by {self.value[i] - self.value[self.best]:.3g}"
            lines.append(f"{i:>5}  {self.value[i]:>14.6g}  {int(self.steps[i]):>5}  {self.message(i)}{lost}{tag}")
        return "\n".join(lines)


def fit(
    objective: Callable,
    p0: Mapping,
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    optimizer=None,
    steps: int = 200,
    tol: float = 1e-12,
    xtol: float = 1e-9,
    penalty: Callable | None = None,
    penalty_weight: float = 1e3,
    diverge: float = 1e8,
) -> FitResult:
    """Minimise an objective from a batch of starting designs at once (multi-start, optax).

    Every start runs the same optimiser, vmapped, in one compiled loop; each start stops
    on its own (converged, infeasible, diverged) while the others go on.

    **Arguments**

    - `objective`: ``f(p) -> value`` or ``-> (value, ok)`` for one design, ``p`` a mapping
      name -> scalar (e.g. a ``scene_figure``).  Not finite, or ``ok`` False: infeasible.
      It must mask the inputs of its own computations where it fails (see
      ``scene_figure``) so that no NaN reaches a gradient.
    - `p0`: ``{name: (S,)}`` the starting designs (scalars broadcast).
    - `bounds`: ``{name: (low, high)}``, enforced by projection: after every step the
      parameters are clipped into the box.  (A line search may still evaluate outside
      the box; it sees ``inf`` where that is infeasible.)
    - `optimizer`: an ``optax`` transformation; default ``optax.lbfgs()`` (with its zoom
      line search, which receives the objective as ``value_fn``).  The compiled loop is
      keyed on the objective and optimizer objects: reuse them to avoid recompiling.
    - `steps`: iteration budget per start.
    - `tol`, `xtol`: a start has converged when one step changes the objective by at most
      ``tol * max(|f|, tiny)`` and every parameter by at most ``xtol * max(|p|, tiny)``.
    - `penalty`: general constraints ``g(p) <= 0`` as ``penalty(p) -> array g``; added to
      the objective as ``penalty_weight * sum(max(g, 0)^2)`` (a quadratic exterior
      penalty: the optimum violates a constraint by ``O(1/penalty_weight)``).
    - `diverge`: a start whose objective exceeds ``diverge * max(|f0|, 1)`` diverged.

    **Returns** a ``FitResult``: the winner, each start's final design and stop reason,
    and ``report()`` in words.
    """
    batch, s = as_batch(p0, "fit")
    names = tuple(batch)
    bounds = dict(bounds or {})
    unknown = [k for k in bounds if k not in batch]
    if unknown:
        raise ValueError(f"fit: bounds for unknown parameter(s) {unknown}; parameters are {list(names)}")
    lo, hi = {}, {}
    for k in names:
        a, b = bounds.get(k, (-np.inf, np.inf))
        if not float(a) <= float(b):
            raise ValueError(f"fit: bounds of {k!r} must satisfy low <= high, got {bounds[k]}")
        lo[k], hi[k] = float(a), float(b)
    if steps < 1:
        raise ValueError(f"fit: steps must be at least 1, got {steps}")
    opt = _default_optimizer() if optimizer is None else optax.with_extra_args_support(optimizer)
    p_start = {k: jnp.clip(v, lo[k], hi[k]) for k, v in batch.items()}
    params, value, reason, nsteps, history = _fit_loop(
        objective, opt, penalty, float(penalty_weight), float(diverge), float(tol), float(xtol), int(steps),
        tuple(sorted(lo.items())), tuple(sorted(hi.items())), p_start,
    )
    value = np.asarray(value)
    reason = np.asarray(reason)
    usable = np.isfinite(value) & (reason != Status.DIVERGED)
    best = int(np.argmin(np.where(usable, value, np.inf))) if np.any(usable) else -1
    return FitResult(
        params={k: np.asarray(v) for k, v in params.items()},
        value=value,
        reason=reason,
        steps=np.asarray(nsteps),
        history=np.asarray(history),
        best=best,
        tol=tol,
        xtol=xtol,
    )


@functools.lru_cache(maxsize=1)
def _default_optimizer():
    # One object for every call: the compiled fit loop is keyed on the optimizer's identity.
    return optax.with_extra_args_support(optax.lbfgs())


class _FitCarry(NamedTuple):
    """The fit loop's state: step `k`, per start the parameters `p`, the optimiser's
    `state`, value `v`, gradient `g`, whether it is `active`, its stop `reason`, its steps
    `nsteps`, and the value `history` ``(steps + 1, starts)``."""

    k: Any
    p: Any
    state: Any
    v: Any
    g: Any
    active: Any
    reason: Any
    nsteps: Any
    history: Any


class FitLoop(NamedTuple):
    """What the compiled fit loop returns (``_fit_loop``), a row per start: the final
    designs `params`, objective `value`, ``Status`` `reason`, steps taken `nsteps`, and
    the objective's `history` ``(steps + 1, starts)`` (rows after a start ended repeat its
    final value)."""

    params: dict
    value: jax.Array
    reason: jax.Array
    nsteps: jax.Array
    history: jax.Array


@functools.partial(jit, static_argnums=tuple(range(10)))
def _fit_loop(objective, opt, penalty, weight, diverge, tol, xtol, steps, lo, hi, p0) -> FitLoop:
    lo, hi = dict(lo), dict(hi)
    tiny = jnp.finfo(jnp.result_type(float)).tiny

    def total(p):
        value, ok = figure_value(objective(p))
        if penalty is not None:
            g = jnp.ravel(jnp.asarray(penalty(p)))
            value = value + weight * jnp.sum(jnp.square(jnp.maximum(g, 0.0)))
        ok = ok & jnp.isfinite(value)
        # inf tells the line search "outside the domain"; the gradient of the masked
        # value is zero there (the objective masks its own inputs).
        return jnp.where(ok, value, jnp.inf), ok

    value_and_grad = jax.value_and_grad(total, has_aux=True)
    value_fn = lambda p: total(p)[0]  # noqa: E731

    def clip(p):
        return {k: jnp.clip(v, lo[k], hi[k]) for k, v in p.items()}

    def finite(tree):
        return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]))

    def start(p):
        (v, ok), g = value_and_grad(p)
        state = opt.init(p)
        reason = jnp.where(ok, Status.MAX_STEPS, Status.INFEASIBLE).astype(jnp.int32)
        return p, state, v, g, ok, reason, jnp.abs(v)

    def step(p, state, v, g, active, reason, v0):
        updates, new_state = opt.update(g, state, p, value=v, grad=g, value_fn=value_fn)
        p_new = clip(optax.apply_updates(p, updates))
        (v_new, ok_new), g_new = value_and_grad(p_new)
        diverged = ~finite(p_new) | (ok_new & (~finite(g_new) | (v_new > diverge * jnp.maximum(v0, 1.0))))
        infeasible = ~ok_new & ~diverged
        small_f = jnp.abs(v_new - v) <= tol * jnp.maximum(jnp.abs(v_new), tiny)
        small_x = jnp.all(jnp.stack([
            jnp.abs(p_new[k] - p[k]) <= xtol * jnp.maximum(jnp.abs(p_new[k]), tiny) for k in p
        ]))
        converged = ok_new & ~diverged & small_f & small_x
        accept = active & ok_new & ~diverged
        sel = lambda a, b: jax.tree_util.tree_map(lambda x, y: jnp.where(accept, x, y), a, b)  # noqa: E731
        p, state, v, g = sel(p_new, p), sel(new_state, state), sel(v_new, v), sel(g_new, g)
        reason = jnp.where(
            active,
            jnp.where(diverged, Status.DIVERGED, jnp.where(infeasible, Status.INFEASIBLE,
                      jnp.where(converged, Status.CONVERGED, Status.MAX_STEPS))),
            reason,
        ).astype(jnp.int32)
        return p, state, v, g, active & ~(diverged | infeasible | converged), reason

    p, state, v, g, active, reason, v0 = jax.vmap(start)(p0)
    s = v.shape[0]
    history = jnp.full((steps + 1, s), jnp.inf, v.dtype).at[0].set(v)
    nsteps = jnp.zeros((s,), jnp.int32)

    def cond(c: _FitCarry):
        return (c.k < steps) & jnp.any(c.active)

    def body(c: _FitCarry) -> _FitCarry:
        p, state, v, g, active_new, reason = jax.vmap(step)(c.p, c.state, c.v, c.g, c.active, c.reason, v0)
        nsteps = c.nsteps + c.active.astype(jnp.int32)
        history = c.history.at[c.k + 1].set(v)
        return _FitCarry(c.k + 1, p, state, v, g, active_new, reason, nsteps, history)

    k, p, state, v, g, active, reason, nsteps, history = jax.lax.while_loop(
        cond, body, _FitCarry(0, p, state, v, g, active, reason, nsteps, history)
    )
    # Rows after the loop ended repeat the final values.
    rows = jnp.arange(steps + 1)[:, None]
    history = jnp.where(rows <= k, history, v[None, :])
    return FitLoop(p, v, reason, nsteps, history)


def __getattr__(name):
    """The result codes' retired names (deprecated: ``jaxmech.Status``, ``status.RETIRED``)."""
    from ..solver.status import retired

    return retired(__name__, name)
