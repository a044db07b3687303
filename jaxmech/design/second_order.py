"""Constrained design with exact second derivatives, every start at once.

The problem is stated as in ``jaxmech.design.constrained`` (``state(x) -> Stated``: a peak to make
least over the stroke samples, equalities, inequalities, assemblability), in epigraph form
``min t  s.t.  peak_i(x) / peak_scale <= t``, in the box's scaled variables.  Its Lagrangian's
exact Hessian (every constraint at every stroke sample, through the implicit rule of the
position solves to second order) feeds a primal-dual interior-point method
(``design.interior``), and the starts are one vmapped program: a batch of 4 or of 256
starting designs is one call, and the compile is paid once.

Unassemblable trial points are the interior-point line search's business: a trial design
that does not assemble has an infinite merit and the step is halved.  A start that cannot
be assembled at all is moved halfway towards a reference start (the first) until it can
(at most 20 times), inside the same program.  Every start ends on the convergence test
(IPOPT's scaled KKT residual ``E_0 <= tol``) or says why not (``IPStatus``).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from .constrained import starts_in_box
from .interior import IP_MESSAGES, IPOptions, IPStatus, interior_point, second_order

__all__ = ["SecondOrderResult", "epigraph_problem", "minimize_second_order", "local_optima"]


def _flat(v, dtype):
    return jnp.zeros((0,), dtype) if v is None else jnp.ravel(jnp.asarray(v, dtype))


def epigraph_problem(state: Callable, names: tuple, lo, hi, peak_scale: float):
    """``problem(xt) -> (f, h, g, ok)`` for ``interior_point``: ``xt`` = the scaled design
    ``(x - lo) / (hi - lo)`` and the epigraph variable ``t``; ``f = t``; ``h`` the
    equalities; ``g`` the peaks over ``peak_scale`` less ``t``, the inequalities, and the
    box rows ``z - 1 <= 0``, ``-z <= 0``."""
    lo, hi = jnp.asarray(lo), jnp.asarray(hi)
    width = hi - lo

    def problem(xt):
        z, t = xt[:-1], xt[-1]
        s = state(dict(zip(names, lo + width * z)))
        dtype = xt.dtype
        peak = _flat(s.peak, dtype) / peak_scale
        g = jnp.concatenate([peak - t, _flat(s.le, dtype), z - 1.0, -z])
        return t, _flat(s.eq, dtype), g, jnp.asarray(s.ok, bool)

    return problem


@dataclasses.dataclass(frozen=True)
class SecondOrderResult:
    """Result of ``minimize_second_order`` over S starts.

    - `params`: ``{name: (S,)}`` final designs; `value`: ``(S,)`` the largest peak sample
      there (units of the peak; inf if it does not assemble); `violation`: ``(S,)`` largest
      equality or inequality violation (their units).
    - `status`: ``(S,)`` ``IPStatus`` codes; `kkt`: ``(S,)`` scaled KKT residual ``E_0``;
      `iterations`: ``(S,)``; `pulled`: halvings towards the first start before it assembled.
    - `best`: the winning start (least value among converged feasible starts, else among
      feasible ones), -1 if none; `optima`: ``[(value, count, first start), ...]`` the
      distinct local optima the converged starts reached (``local_optima``).
    - `wall_s`: the call's wall time (compile included when it compiled: `compile_s`).
    """

    params: dict
    value: np.ndarray
    violation: np.ndarray
    status: np.ndarray
    kkt: np.ndarray
    iterations: np.ndarray
    pulled: np.ndarray
    best: int
    optima: list
    feas_tol: float
    wall_s: float
    compile_s: float

    @property
    def converged(self) -> int:
        return int(np.sum(self.status == IPStatus.CONVERGED))

    @property
    def best_params(self) -> dict[str, float]:
        if self.best < 0:
            raise ValueError("minimize_second_order: no start reached a feasible design")
        return {k: float(v[self.best]) for k, v in self.params.items()}

    def message(self, i: int) -> str:
        return IP_MESSAGES[IPStatus(int(self.status[i]))]

    def report(self, show: int = 12) -> str:
        """The winner, the local optima with how many starts reached each, and why each of
        the first `show` starts stopped."""
        n = len(self.value)
        head = (f"interior point, exact Hessians: {n} starts in {self.wall_s:.2f} s ({self.compile_s:.2f} s compiling), "
                f"{self.converged} converged; " + (f"start {self.best} won with {self.value[self.best]:.8g}" if self.best >= 0 else "no feasible start"))
        lines = [head, "local optima (value: starts that reached it, first start): "
                 + "; ".join(f"{v:.8g}: {c} (start {i})" for v, c, i in self.optima)]
        lines.append(f"{'start':>5}  {'peak':>14}  {'violation':>9}  {'KKT':>8}  {'iter':>4}  why it stopped")
        for i in range(min(n, show)):
            tag = "  <- winner" if i == self.best else ""
            pulled = f" (pulled {int(self.pulled[i])}x towards start 0 to assemble)" if self.pulled[i] else ""
            lines.append(f"{i:>5}  {self.value[i]:>14.8g}  {self.violation[i]:>9.2g}  {self.kkt[i]:>8.1e}  "
                         f"{int(self.iterations[i]):>4}  {self.message(i)}{pulled}{tag}")
        return "\n".join(lines)


def local_optima(value, z, converged, rtol: float = 1e-7, xtol: float = 1e-5) -> list:
    """The distinct local optima among converged starts: ``[(value, count, first start)]``
    by value, two starts being one optimum when their values agree to `rtol` and their
    scaled designs to `xtol`."""
    groups: list = []
    for i in np.flatnonzero(converged):
        for g in groups:
            if abs(value[i] - g[0]) <= rtol * max(1.0, abs(g[0])) and np.max(np.abs(z[i] - z[g[2]])) <= xtol:
                g[1] += 1
                break
        else:
            groups.append([float(value[i]), 1, int(i)])
    return sorted((tuple(g) for g in groups), key=lambda g: g[0])


@functools.lru_cache(maxsize=16)
def _batch_solver(state: Callable, names: tuple, lo: tuple, hi: tuple, peak_scale: float, sizes: tuple, options: IPOptions):
    """One compiled-on-first-call program: every start's interior-point solve, vmapped
    (cached per problem, so a second call with the same shapes compiles nothing)."""
    n_pk, p, n_le = sizes
    problem = epigraph_problem(state, names, np.array(lo), np.array(hi), peak_scale)
    evaluate, _ = second_order(problem, p)
    m = n_pk + n_le + 2 * len(names)

    def prepare(xt, c):
        # the epigraph variable starts just above the start's largest peak (t enters the peak
        # rows as -t: their largest value is the amount t must rise)
        top = jnp.max(c[p: p + n_pk], initial=-jnp.inf)
        return xt.at[-1].add(jnp.where(jnp.isfinite(top), top + 1e-3, 0.0))

    def one(xt0, ref):
        return interior_point(evaluate, xt0, p, m, options, ref=ref, prepare=prepare if n_pk else None)

    return jax.jit(jax.vmap(one, in_axes=(0, None)))


def minimize_second_order(state: Callable, x0: Mapping, bounds: Mapping[str, tuple[float, float]], *, peak_scale: float = 1.0,
                          options: IPOptions = IPOptions(), feas_tol: float = 1e-8) -> SecondOrderResult:
    """Solve ``min max_i peak_i(x)  s.t.  eq(x) = 0, le(x) <= 0, bounds`` from every start
    at once, with exact second derivatives (module docstring).

    **Arguments**: as ``constrained.minimize``: `state` ``({name: scalar}) -> Stated``; `x0`
    ``{name: (S,)}`` starts; `bounds` ``{name: (low, high)}``; `peak_scale` a typical size
    of the peak; `options` the interior point's ``IPOptions`` (``tol``: the scaled KKT
    residual that ends a start); `feas_tol`: largest violation a winner may have.

    **Returns** a ``SecondOrderResult``: every start's design, peak, violation, status and
    KKT residual, the winner, and the local optima with how many starts reached each.
    """
    names, starts, lo, hi = starts_in_box(x0, bounds, "minimize_second_order")
    width = hi - lo
    z0 = np.clip((starts - lo) / width, 0.0, 1.0)
    xt0 = np.concatenate([z0, np.zeros((z0.shape[0], 1))], axis=1)
    dtype = jnp.result_type(float)
    shapes = jax.eval_shape(lambda x: state(dict(zip(names, x))), jax.ShapeDtypeStruct((len(names),), dtype))
    sizes = tuple(0 if a is None else int(np.prod(a.shape)) for a in (shapes.peak, shapes.eq, shapes.le))
    solve = _batch_solver(state, names, tuple(lo), tuple(hi), float(peak_scale), sizes, options)
    t0 = time.perf_counter()
    compiled = solve.lower(jnp.asarray(xt0, dtype), jnp.asarray(xt0[0], dtype)).compile()
    compile_s = time.perf_counter() - t0
    st, pulled = jax.block_until_ready(compiled(jnp.asarray(xt0, dtype), jnp.asarray(xt0[0], dtype)))
    wall = time.perf_counter() - t0
    n_pk, p, n_le = sizes
    c = np.asarray(st.c)
    ok = np.isfinite(np.asarray(st.f)) & (np.asarray(st.status) != IPStatus.START_NOT_EVALUATED)
    t = np.asarray(st.x)[:, -1]
    peak = (c[:, p: p + n_pk] + t[:, None]) * peak_scale
    value = np.where(ok, np.max(peak, axis=1, initial=-np.inf), np.inf)
    viol = np.max(np.concatenate([np.abs(c[:, :p]), np.maximum(c[:, p + n_pk: p + n_pk + n_le], 0.0), np.zeros((c.shape[0], 1))], axis=1), axis=1)
    viol = np.where(ok, viol, np.inf)
    status = np.asarray(st.status)
    z = np.asarray(st.x)[:, :-1]
    feasible = ok & (viol <= feas_tol)
    conv = feasible & (status == IPStatus.CONVERGED)
    pool = conv if np.any(conv) else feasible
    best = int(np.argmin(np.where(pool, value, np.inf))) if np.any(pool) else -1
    x = lo + width * z
    return SecondOrderResult(
        params={k: x[:, i] for i, k in enumerate(names)}, value=value, violation=viol, status=status,
        kkt=np.asarray(st.error), iterations=np.asarray(st.k), pulled=np.asarray(pulled), best=best,
        optima=local_optima(value, z, conv), feas_tol=feas_tol, wall_s=wall, compile_s=compile_s)
