"""Constrained design with exact second derivatives, every start at once.

The problem is stated as in ``jaxmech.design.constrained``: least peak over the stroke
samples, equalities, inequalities, a box; either as a ``StrokeProblem`` (rows of the
motion at each sample: its Lagrangian's Hessian by the second-order adjoint of
``design.stroke_problem``, the cheap program) or as any ``state(x) -> Stated`` (the Hessian
by forward over reverse mode through the implicit rule of its position solves).  It is
solved in epigraph form ``min t  s.t.  peak_i(x) / peak_scale <= t``, in the box's scaled
variables, by the SQP of ``design.sqp`` with that exact Hessian, and the starts are one
vmapped program: a batch of 4 or of 256 starting designs is one call, and the compile is
paid once per problem and number of starts; a ``StrokeProblem``'s program is stored
(``jaxmech._compile.stored``), so a new process loads it instead of compiling.

Unassemblable trial points are the SQP's business: a trial design that does not assemble
has an infinite penalty and the step is shortened.  A start that cannot be assembled at
all is moved halfway towards the first start until it can (at most 20 times), inside the
same program.  Every start ends on the convergence test (IPOPT's scaled KKT residual
``E_0 <= tol``) or says why not (``Status``).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .constrained import starts_in_box, stated_rows
from ..solver.status import Status, status_message
from .nlp import Evaluation, weighted_derivatives
from ..solver.xla import jit
from .sqp import SQPOptions, queue
from .stroke_problem import StrokeProblem, stroke_evaluator, stroke_sizes

__all__ = ["SecondOrderResult", "state_evaluator", "minimize_second_order"]


def state_evaluator(state: Callable, names: tuple):
    """``evaluate(x, w) -> nlp.RowDerivatives`` for a generic ``state({name: scalar}) ->
    Stated``: the rows (peak, eq, le), their Jacobian (forward mode) and the Hessian of
    ``w . rows`` (forward over reverse mode), through whatever implicit rules `state` uses."""

    def rows(x):
        s = state(dict(zip(names, x)))
        return jnp.concatenate(stated_rows(s, x.dtype)), jnp.asarray(s.ok, bool)

    def evaluate(x, w):
        return weighted_derivatives(rows, x, w)

    return evaluate


def _state_sizes(state: Callable, names: tuple) -> tuple:
    dtype = jnp.result_type(float)
    shapes = jax.eval_shape(lambda x: state(dict(zip(names, x))), jax.ShapeDtypeStruct((len(names),), dtype))
    return tuple(0 if a is None else int(np.prod(a.shape)) for a in (shapes.peak, shapes.eq, shapes.le))


class Epigraph(NamedTuple):
    """The epigraph statement's sizes: `n` design variables, `peaks`, `eq`, `le` rows."""

    n: int
    peaks: int
    eq: int
    le: int

    @property
    def m(self) -> int:
        """Inequalities of the statement: the peaks, the limits, the box's two sides."""
        return self.peaks + self.le + 2 * self.n


def epigraph_evaluator(rows_evaluate: Callable, sizes: Epigraph, lo, hi, peak_scale: float):
    """``evaluate(xt, y, z) -> Evaluation`` of the epigraph statement for ``design.sqp``:
    ``xt`` = the scaled design ``(x - lo) / (hi - lo)`` and ``t``; ``f = t``; ``h`` the
    equalities; ``g`` the peaks over `peak_scale` less ``t``, the limits, and the box rows
    ``z - 1 <= 0``, ``-z <= 0``.  The Lagrangian's Hessian is the rows' (``t`` and the box
    enter linearly), weighted by the multipliers, in the scaled variables."""
    lo, width = jnp.asarray(lo), jnp.asarray(hi) - jnp.asarray(lo)
    n, n_pk, n_eq, n_le = sizes

    def evaluate(xt, y, z):
        zz, t = xt[:-1], xt[-1]
        w = jnp.concatenate([z[:n_pk] / peak_scale, y, z[n_pk:n_pk + n_le]])
        e = rows_evaluate(lo.astype(xt.dtype) + width.astype(xt.dtype) * zz, w)
        jac = e.jac * width[None, :]
        pk, eq, le = e.values[:n_pk] / peak_scale, e.values[n_pk:n_pk + n_eq], e.values[n_pk + n_eq:]
        j_pk, j_eq, j_le = jac[:n_pk] / peak_scale, jac[n_pk:n_pk + n_eq], jac[n_pk + n_eq:]
        eye = jnp.eye(n, dtype=xt.dtype)

        def col(a, tc):
            return jnp.concatenate([a, jnp.full((a.shape[0], 1), tc, xt.dtype)], axis=1)

        c = jnp.concatenate([eq, pk - t, le, zz - 1.0, -zz])
        jc = jnp.concatenate([col(j_eq, 0.0), col(j_pk, -1.0), col(j_le, 0.0), col(eye, 0.0), col(-eye, 0.0)])
        hess = jnp.zeros((n + 1, n + 1), xt.dtype).at[:n, :n].set(e.hess * width[:, None] * width[None, :])
        grad = jnp.zeros((n + 1,), xt.dtype).at[n].set(1.0)
        return Evaluation(t, c, grad, jc, hess, e.ok)

    return evaluate


@dataclasses.dataclass(frozen=True)
class SecondOrderResult:
    """Result of ``minimize_second_order`` over S starts.

    - `params`: ``{name: (S,)}`` final designs; `value`: ``(S,)`` the largest peak sample
      there (units of the peak; inf if it does not assemble); `violation`: ``(S,)`` largest
      equality or inequality violation (their units).
    - `status`: ``(S,)`` ``Status`` codes; `kkt`: ``(S,)`` scaled KKT residual ``E_0``;
      `iterations`: ``(S,)`` (each one evaluation of the problem and its derivatives);
      `pulled`: halvings towards the first start before it assembled.
    - `best`: the winning start (least value among converged feasible starts, else among
      feasible ones), -1 if none; `optima`: ``[(value, count, first start), ...]`` the
      distinct local optima the converged starts reached (``local_optima``).
    - `wall_s`: the call's wall time (its compile included when this process compiled the
      program: the first call for a problem and a number of starts, unless a stored
      executable was loaded).
    - `origin`: ``(S,)`` where each start came from (``refine``: its row of the sweep), or
      None.
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
    origin: np.ndarray | None = None

    @property
    def converged(self) -> int:
        return int(np.sum(self.status == Status.CONVERGED))

    @property
    def best_params(self) -> dict[str, float]:
        if self.best < 0:
            raise ValueError("minimize_second_order: no start reached a feasible design")
        return {k: float(v[self.best]) for k, v in self.params.items()}

    def message(self, i: int) -> str:
        """Why start ``i`` stopped, in words (``status_message``, with the SQP's reading)."""
        code = Status(int(self.status[i]))
        detail = {Status.CONVERGED: " (scaled KKT residual within tolerance)",
                  Status.INFEASIBLE: " (the start cannot be evaluated: the design does not assemble there)"}
        return status_message(code) + detail.get(code, "")

    def report(self, show: int = 12) -> str:
        """The winner, the local optima with how many starts reached each, and why each of
        the first `show` starts stopped."""
        n = len(self.value)
        head = (f"SQP, exact Hessians: {n} starts in {self.wall_s:.2f} s, "
                f"{self.converged} converged; " + (f"start {self.best} won with {self.value[self.best]:.10g}" if self.best >= 0 else "no feasible start"))
        lines = [head, "local optima (value: starts that reached it, first start): "
                 + "; ".join(f"{v:.10g}: {c} (start {i})" for v, c, i in self.optima)]
        lines.append(f"{'start':>5}  {'peak':>16}  {'violation':>9}  {'KKT':>8}  {'iter':>4}  why it stopped")
        for i in range(min(n, show)):
            tag = "  <- winner" if i == self.best else ""
            pulled = f" (pulled {int(self.pulled[i])}x towards start 0 to assemble)" if self.pulled[i] else ""
            lines.append(f"{i:>5}  {self.value[i]:>16.10g}  {self.violation[i]:>9.2g}  {self.kkt[i]:>8.1e}  "
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


#: Starts solved side by side in one vmapped loop; further starts wait for a lane to free
#: (``sqp.queue``): on a CPU, 32 lanes vectorise the evaluation as well as more do.
LANES = 32


@functools.partial(jit, static_argnums=(0, 1, 2, 3, 4, 5, 6))
def _solve_batch(problem, names: tuple, lo: tuple, hi: tuple, peak_scale: float, sizes: Epigraph, options: SQPOptions, z0, ref):
    """Every start's SQP, on ``LANES`` lanes of one vmapped loop (``sqp.queue``), from the
    scaled starts ``z0 (S, n)`` and the reference ``ref (n,)``: one program, compiled on its
    first call for these static arguments and shapes (a ``StrokeProblem``'s program is
    stored: a new process loads it)."""
    rows = stroke_evaluator(problem) if isinstance(problem, StrokeProblem) else state_evaluator(problem, names)
    evaluate = epigraph_evaluator(rows, sizes, np.array(lo), np.array(hi), peak_scale)
    n_pk, n_eq = sizes.peaks, sizes.eq

    def prepare(xt, ev):
        # t just above the start's largest peak: t enters the peak rows alone, as -t
        top = jnp.max(ev.c[n_eq:n_eq + n_pk] + xt[-1], initial=-jnp.inf)
        t = jnp.where(jnp.isfinite(top), top + 1e-6, xt[-1])
        return xt.at[-1].set(t), ev._replace(f=t, c=ev.c.at[n_eq:n_eq + n_pk].add(xt[-1] - t))

    # Stationarity in t asks the peak rows' multipliers to sum to one: start them uniform
    zm = jnp.zeros((sizes.m,), z0.dtype).at[:n_pk].set(1.0 / max(n_pk, 1))
    xt0 = jnp.concatenate([z0, jnp.zeros((z0.shape[0], 1), z0.dtype)], axis=1)
    return queue(evaluate, xt0, jnp.zeros((n_eq,), z0.dtype), zm, LANES, options, ref=jnp.append(ref, 0.0), prepare=prepare if n_pk else None)


def minimize_second_order(problem: StrokeProblem | Callable, x0: Mapping, bounds: Mapping[str, tuple[float, float]], *,
                          peak_scale: float = 1.0, options: SQPOptions = SQPOptions(), feas_tol: float = 1e-8,
                          reference: Mapping | None = None) -> SecondOrderResult:
    """Solve ``min max_i peak_i(x)  s.t.  eq(x) = 0, le(x) <= 0, bounds`` from every start
    at once, with exact second derivatives (module docstring).

    **Arguments**: `problem` a ``StrokeProblem`` (its `names` are the design variables) or
    ``state({name: scalar}) -> Stated`` as for ``constrained.minimize``; `x0`
    ``{name: (S,)}`` starts; `bounds` ``{name: (low, high)}``; `peak_scale` a typical size
    of the peak; `options` the ``SQPOptions`` (``tol``: the scaled KKT residual that ends
    a start); `feas_tol`: largest violation a winner may have; `reference` ``{name: value}``:
    the design a start that does not assemble is moved towards (default: the first start).

    **Returns** a ``SecondOrderResult``: every start's design, peak, violation, status and
    KKT residual, the winner, and the local optima with how many starts reached each.
    """
    names, starts, lo, hi = starts_in_box(x0, bounds, "minimize_second_order")
    if isinstance(problem, StrokeProblem):
        if set(names) != set(problem.names):
            raise ValueError(f"minimize_second_order: x0 names {names} must be the problem's design variables {problem.names}")
        order = [names.index(k) for k in problem.names]
        names, starts, lo, hi = problem.names, starts[:, order], lo[order], hi[order]
        sizes = Epigraph(len(names), *stroke_sizes(problem))
    else:
        sizes = Epigraph(len(names), *_state_sizes(problem, names))
    width = hi - lo
    dtype = jnp.result_type(float)
    z0 = jnp.asarray(np.clip((starts - lo) / width, 0.0, 1.0), dtype)
    ref = z0[0] if reference is None else jnp.asarray(np.clip([(float(reference[k]) - l) / w for k, l, w in zip(names, lo, width)], 0.0, 1.0), dtype)
    t0 = time.perf_counter()
    st, pulled = jax.block_until_ready(_solve_batch(problem, names, tuple(map(float, lo)), tuple(map(float, hi)), float(peak_scale),
                                                    sizes, options, z0, ref))
    return _result(st, pulled, sizes, lo, width, names, peak_scale, feas_tol, time.perf_counter() - t0)


def _result(st, pulled, sizes: Epigraph, lo, width, names, peak_scale, feas_tol, wall) -> SecondOrderResult:
    n, n_pk, p, n_le = sizes
    c = np.asarray(st.c)
    status = np.asarray(st.status)
    ok = np.isfinite(np.asarray(st.f)) & (status != Status.INFEASIBLE)
    t = np.asarray(st.x)[:, -1]
    peak = (c[:, p: p + n_pk] + t[:, None]) * peak_scale
    value = np.where(ok, np.max(peak, axis=1, initial=-np.inf), np.inf)
    viol = np.max(np.concatenate([np.abs(c[:, :p]), np.maximum(c[:, p + n_pk: p + n_pk + n_le], 0.0), np.zeros((c.shape[0], 1))], axis=1), axis=1)
    viol = np.where(ok, viol, np.inf)
    z = np.asarray(st.x)[:, :-1]
    feasible = ok & (viol <= feas_tol)
    conv = feasible & (status == Status.CONVERGED)
    pool = conv if np.any(conv) else feasible
    best = int(np.argmin(np.where(pool, value, np.inf))) if np.any(pool) else -1
    x = lo + width * z
    return SecondOrderResult(
        params={k: x[:, i] for i, k in enumerate(names)}, value=value, violation=viol, status=status,
        kkt=np.asarray(st.error), iterations=np.asarray(st.k), pulled=np.asarray(pulled), best=best,
        optima=local_optima(value, z, conv), feas_tol=feas_tol, wall_s=wall)

