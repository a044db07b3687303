"""Constrained design as engineers state it, solved by a well-kept SQP with exact Jacobians.

A design question reads: *least peak torque over the stroke, the flap turning through
exactly 60 deg, no transmission angle below 30 deg, lengths within their box.*  Here it is
written as that, one design at a time, by a function ``state(x) -> Stated``:

- ``peak``: ``(N,)`` values at the stroke samples whose maximum is to be least.  It is
  minimised in epigraph form: a variable ``t`` is added and the problem becomes
  ``min t  s.t.  peak_i(x) <= t`` at every sample, so the optimiser sees smooth
  constraints instead of a kinked maximum (no smoothing temperature, no bias);
- ``eq``: ``(E,)`` equality targets, ``eq(x) = 0``;
- ``le``: ``(I,)`` inequality limits, ``le(x) <= 0`` (transmission angle, assemblability
  margin, clearance);
- ``ok``: False where the design cannot be assembled (a sample did not converge).

``program(state, names)`` compiles, once, ONE program ``x -> (values, Jacobian, ok)``:
every constraint at every stroke sample and its exact Jacobian in forward mode
(``jax.jacfwd``; the positions' tangents come from the implicit function theorem through the
position solve).  ``minimize`` feeds it to ``scipy.optimize.minimize`` (SLSQP by default,
or ``trust-constr``) from each start in turn, reusing the compiled program.

**Unassemblable trial points.**  When a line search tries a design that cannot be
assembled, every constraint is reported violated by ``FAIL_VIOLATION`` (in the scaled
units the optimiser sees); the merit function then rises and the line search shortens the
step.  The start goes on; ``Result.failed_trials`` counts such points.

scipy is a runtime dependency for this module: its SLSQP and trust-constr are the
well-kept constrained optimisers we feed; we do not write an SQP by hand.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.xla import jit

__all__ = ["Stated", "stated_rows", "Program", "ConstrainedResult", "starts_in_box", "program", "minimize",
           "FAIL_VIOLATION"]

#: Scaled violation reported for every constraint at a design that cannot be assembled.
FAIL_VIOLATION = 1e3


class Stated(NamedTuple):
    """One design's requirements (see the module docstring); any field may be empty."""

    peak: jax.Array | None = None
    eq: jax.Array | None = None
    le: jax.Array | None = None
    ok: jax.Array | bool = True


def stated_rows(s: Stated, dtype) -> tuple:
    """``(peak, eq, le)`` of a ``Stated``, each a flat array of `dtype` (empty where absent)."""
    return tuple(jnp.zeros((0,), dtype) if v is None else jnp.ravel(jnp.asarray(v, dtype)) for v in (s.peak, s.eq, s.le))


@dataclasses.dataclass(frozen=True)
class Program:
    """The compiled program of a stated problem: ``evaluate(x) -> (values, jac, ok)``.

    `values` stacks ``(peak, eq, le)`` (lengths ``sizes``); `jac` is ``d values / d x``
    ``(n_values, n_x)``.  `compile_s` is the time spent tracing and compiling it.
    """

    names: tuple
    sizes: tuple
    evaluate: Callable
    compile_s: float


def program(state: Callable, names, x_example) -> Program:
    """Compile ``x -> (values, Jacobian, ok)`` for ``state(x: {name: scalar}) -> Stated``.

    One forward-mode pass (``jax.jacfwd``, as many tangents as ``names``) gives every
    constraint at every sample with its exact Jacobian; compiled ahead of time for the
    shape of `x_example` (``(len(names),)``) so the compile is measured and paid once.
    """
    names = tuple(names)
    x_example = jnp.asarray(x_example, jnp.result_type(float))
    if x_example.shape != (len(names),):
        raise ValueError(f"program: x_example must have shape ({len(names)},) for names {names}, got {x_example.shape}")
    dtype = x_example.dtype

    def parts(x):
        s = state(dict(zip(names, x)))
        return stated_rows(s, dtype), jnp.asarray(s.ok, bool)

    sizes = tuple(int(a.shape[0]) for a in jax.eval_shape(parts, x_example)[0])

    def both(x):
        def values(x_):
            (pk, e, l_), ok = parts(x_)
            v = jnp.concatenate([pk, e, l_])
            return v, (v, ok)

        jac, (v, ok) = jax.jacfwd(values, has_aux=True)(x)
        ok = ok & jnp.all(jnp.isfinite(v)) & jnp.all(jnp.isfinite(jac))
        return v, jac, ok

    t0 = time.perf_counter()
    compiled = jit(both).lower(x_example).compile()
    return Program(names, sizes, compiled, time.perf_counter() - t0)


@dataclasses.dataclass(frozen=True)
class ConstrainedResult:
    """Result of ``minimize`` over several starts.

    - `params`: ``{name: (S,)}`` each start's final design; `value`: ``(S,)`` its peak
      (the largest ``peak`` sample, in the units of ``peak``), or ``inf`` if infeasible.
    - `violation`: ``(S,)`` largest violation of an equality (``|eq|``) or inequality
      (``max(le, 0)``) at the final design, in their own units (``inf``: not assembled).
    - `success`, `message`, `iterations`, `evaluations`, `failed_trials`: per start, from
      the optimiser (failed trials: designs tried by a line search that could not be
      assembled; each shortened a step).
    - `best`: the winning start (lowest value among those with ``violation <= feas_tol``),
      -1 if none.  `wall_s`: seconds for all starts, including `compile_s` (the program's
      compile when ``minimize`` compiled it; 0 when a compiled ``prog`` was passed in).
    """

    params: dict
    value: np.ndarray
    violation: np.ndarray
    success: np.ndarray
    message: tuple
    iterations: np.ndarray
    evaluations: np.ndarray
    failed_trials: np.ndarray
    best: int
    feas_tol: float
    method: str
    wall_s: float
    compile_s: float

    @property
    def best_params(self) -> dict[str, float]:
        if self.best < 0:
            raise ValueError("minimize: no start reached a feasible design")
        return {k: float(v[self.best]) for k, v in self.params.items()}

    def report(self) -> str:
        """Which start won, and why each start stopped, in words."""
        n = len(self.value)
        head = (f"{self.method}: {n} starts, {self.wall_s:.2f} s ({self.compile_s:.2f} s compiling one program); "
                + (f"start {self.best} won with {self.value[self.best]:.8g}" if self.best >= 0 else "no feasible start"))
        lines = [head, f"{'start':>5}  {'peak':>14}  {'violation':>9}  {'iter':>4}  {'evals':>5}  {'failed':>6}  why it stopped"]
        for i in range(n):
            tag = "  <- winner" if i == self.best else ""
            why = self.message[i]
            if self.violation[i] > self.feas_tol:
                why += f"; infeasible (violation {self.violation[i]:.2g} > {self.feas_tol:g})"
            elif self.best >= 0 and i != self.best:
                why += f"; lost by {self.value[i] - self.value[self.best]:.3g}"
            lines.append(f"{i:>5}  {self.value[i]:>14.8g}  {self.violation[i]:>9.2g}  {int(self.iterations[i]):>4}  "
                         f"{int(self.evaluations[i]):>5}  {int(self.failed_trials[i]):>6}  {why}{tag}")
        return "\n".join(lines)


def _restore(evaluate, z, n_pk, n_eq, feas_tol, steps=8):
    """Pull an optimiser's last iterate onto ``eq = 0, le <= 0`` (scaled variables ``z``).

    Least-norm Gauss-Newton steps ``dz = -J_A^+ c_A`` on the equalities and the inequalities
    within ``feas_tol`` of active or violated, clipped into the box; the epigraph variable
    is not used (the peak is re-read at the final design).  SQP iterates stop with a
    violation of the order of the step; a step or two of this meets the constraints to
    round-off while moving the design by about as much.
    """
    x = z[:-1].copy()
    for _ in range(steps):
        v, jac, ok = evaluate(np.append(x, z[-1]))
        if not ok:
            return z
        c = v[n_pk:]
        rows = np.arange(c.size) < n_eq
        rows |= c > -feas_tol
        viol = np.max(np.abs(np.where(np.arange(c.size) < n_eq, c, np.maximum(c, 0.0))), initial=0.0)
        if viol <= 1e-3 * feas_tol:
            break
        dx = -np.linalg.lstsq(jac[n_pk:][rows], c[rows], rcond=None)[0]
        x = np.clip(x + dx, 0.0, 1.0)
    return np.append(x, z[-1])


class ScaledProblem:
    """The stated problem as the optimiser sees it, in the box's scaled variables
    ``z = ((x - low) / (high - low), t)`` with ``t`` the epigraph variable (peak units over
    `peak_scale`).  Holds the one compiled program, the latest evaluation (SLSQP asks for
    values and Jacobians at the same point in turn), evaluation counts and the last
    iterate whose gradients the optimiser asked for (an accepted, assemblable one)."""

    def __init__(self, prog: Program, lo, hi, peak_scale: float):
        self.prog, self.lo, self.width, self.peak_scale = prog, lo, hi - lo, float(peak_scale)
        self.n_pk, self.n_eq, self.n_le = prog.sizes
        self.evals, self.failed = 0, 0
        self.accepted = None
        self.latest: tuple = (None, None)

    def evaluate(self, z):
        """``(values, Jacobian in z, ok)`` at ``z`` (the Jacobian's columns scaled by the box)."""
        key = z.tobytes()
        if self.latest[0] != key:
            x = self.lo + self.width * z[:-1]
            v, jac, ok = (np.asarray(a) for a in self.prog.evaluate(jnp.asarray(x)))
            self.evals += 1
            self.failed += int(not ok)
            self.latest = (key, (v, jac * self.width[None, :], bool(ok)))
        return self.latest[1]

    def eq_fun(self, z):
        v, _, ok = self.evaluate(z)
        return v[self.n_pk:self.n_pk + self.n_eq] if ok else np.full(self.n_eq, FAIL_VIOLATION)

    def eq_jac(self, z):
        _, jac, ok = self.evaluate(z)
        if not ok:
            return np.zeros((self.n_eq, z.size))
        return np.hstack([jac[self.n_pk:self.n_pk + self.n_eq], np.zeros((self.n_eq, 1))])

    def ge_fun(self, z):
        """scipy's convention, ``fun(z) >= 0``: ``t - peak / peak_scale`` and ``-le``."""
        v, _, ok = self.evaluate(z)
        if not ok:
            return np.full(self.n_pk + self.n_le, -FAIL_VIOLATION)
        return np.concatenate([z[-1] - v[:self.n_pk] / self.peak_scale, -v[self.n_pk + self.n_eq:]])

    def ge_jac(self, z):
        _, jac, ok = self.evaluate(z)
        if not ok:
            return np.zeros((self.n_pk + self.n_le, z.size))
        self.accepted = z.copy()  # gradients are asked for at the iterates the line search accepted
        top = np.hstack([-jac[:self.n_pk] / self.peak_scale, np.ones((self.n_pk, 1))])
        return np.vstack([top, np.hstack([-jac[self.n_pk + self.n_eq:], np.zeros((self.n_le, 1))])])

    def constraints(self) -> list:
        """The constraints in ``scipy.optimize.minimize``'s form."""
        out = []
        if self.n_eq:
            out.append({"type": "eq", "fun": self.eq_fun, "jac": self.eq_jac})
        if self.n_pk + self.n_le:
            out.append({"type": "ineq", "fun": self.ge_fun, "jac": self.ge_jac})
        return out

    def to_z(self, x):
        """Scaled design variables of ``x`` (without the epigraph variable), clipped into the box."""
        return np.clip((x - self.lo) / self.width, 0.0, 1.0)


class StartPoint(NamedTuple):
    """Where one start begins: ``z0`` (with the epigraph variable at its peak), whether it
    could be assembled, and how many times it was pulled halfway to start 0 first."""

    z0: np.ndarray
    ok: bool
    pulled: int


class StartOutcome(NamedTuple):
    """One start's end: final design ``x``, peak, violation (``inf`` if not assembled),
    the optimiser's success and message, iterations, evaluations and failed trials."""

    x: np.ndarray
    peak: float
    violation: float
    success: bool
    message: str
    iterations: int
    evaluations: int
    failed_trials: int


def _start_point(problem: ScaledProblem, starts, s: int) -> StartPoint:
    """Start ``s`` in scaled variables; one that cannot be assembled is moved halfway to
    start 0 until it can (at most 20 times)."""
    z0 = problem.to_z(starts[s])
    v0, _, ok0 = problem.evaluate(np.append(z0, 0.0))
    pulled = 0
    while not ok0 and s > 0 and pulled < 20:
        z0 = 0.5 * (z0 + problem.to_z(starts[0]))
        v0, _, ok0 = problem.evaluate(np.append(z0, 0.0))
        pulled += 1
    t0 = float(np.max(v0[:problem.n_pk]) / problem.peak_scale) if ok0 and problem.n_pk else 0.0
    return StartPoint(np.append(z0, t0), bool(ok0), pulled)


def _optimise(problem: ScaledProblem, z0, method: str, maxiter: int, tol: float):
    """``scipy.optimize.minimize`` of the epigraph variable from ``z0``, restarted from the
    last assemblable iterate (at most 3 times, within `maxiter` in all) when it stops on a
    design that cannot be assembled.  Returns ``(scipy result, iterations, restarts)``."""
    from scipy.optimize import minimize as scipy_minimize

    e_t = np.zeros(z0.size)
    e_t[-1] = 1.0
    opts = {"maxiter": maxiter, **({"ftol": tol} if method == "SLSQP" else {"gtol": tol, "xtol": tol})}
    bounds = [(0.0, 1.0)] * (z0.size - 1) + [(None, None)]
    problem.accepted = z0.copy()
    restarts, nit = 0, 0
    while True:
        res = scipy_minimize(lambda z: z[-1], z0, jac=lambda z: e_t, method=method,
                             constraints=problem.constraints(), bounds=bounds, options=opts)
        nit += int(getattr(res, "nit", 0) or 0)
        if problem.evaluate(np.asarray(res.x, float))[2] or restarts == 3 or nit >= maxiter:
            return res, nit, restarts
        # The optimiser stopped on a design that cannot be assembled (a line search
        # accepted it): go on from the last assemblable iterate, with a fresh model.
        z0, restarts = problem.accepted.copy(), restarts + 1
        opts["maxiter"] = max(maxiter - nit, 1)


def _finish(problem: ScaledProblem, start: StartPoint, res, nit: int, restarts: int, feas_tol: float,
            counts: tuple[int, int]) -> StartOutcome:
    """The start's final design (the last assemblable iterate, pulled onto the constraints
    by ``_restore``), its peak and violation in their own units, and why it stopped."""
    z = np.asarray(res.x, float)
    if not problem.evaluate(z)[2]:
        z = problem.accepted
    z = _restore(problem.evaluate, z, problem.n_pk, problem.n_eq, feas_tol)
    v, _, ok = problem.evaluate(z)
    n_pk, n_eq = problem.n_pk, problem.n_eq
    if ok:
        pk = float(np.max(v[:n_pk])) if n_pk else float(res.fun)
        viol = max([0.0, *np.abs(v[n_pk:n_pk + n_eq]), *np.maximum(v[n_pk + n_eq:], 0.0)])
    else:
        pk, viol = np.inf, np.inf
    msg = str(res.message)
    if not start.ok:
        msg = "the start cannot be assembled: " + msg
    elif start.pulled:
        msg = f"start pulled {start.pulled}x halfway to start 0 to assemble; " + msg
    if restarts:
        msg += f" (restarted {restarts}x from the last assemblable iterate)"
    return StartOutcome(problem.lo + problem.width * z[:-1], pk, viol, bool(res.success), msg, nit,
                        problem.evals - counts[0], problem.failed - counts[1])


class StartsInBox(NamedTuple):
    """A multi-start call's designs: parameter `names`, `starts` ``(S, n)`` and the box
    ``lo``, ``hi`` ``(n,)`` (parameter units)."""

    names: tuple
    starts: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def starts_in_box(x0: Mapping, bounds: Mapping, what: str) -> StartsInBox:
    """Eager checks of a multi-start call's starts ``{name: (S,)}`` and finite bounds
    ``{name: (low, high)}`` for every name (``ValueError`` beginning with `what`)."""
    if not isinstance(x0, Mapping) or not x0:
        raise ValueError(f"{what}: x0 must be a non-empty mapping {{name: (S,) starts}}")
    names = tuple(x0)
    missing = [k for k in names if k not in bounds]
    if missing:
        raise ValueError(f"{what}: bounds missing for {missing}; give (low, high) for every parameter")
    lo = np.array([float(bounds[k][0]) for k in names])
    hi = np.array([float(bounds[k][1]) for k in names])
    if not np.all(np.isfinite(lo) & np.isfinite(hi) & (lo < hi)):
        raise ValueError(f"{what}: every parameter needs finite bounds low < high, got {dict(bounds)}")
    starts = np.stack([np.atleast_1d(np.asarray(x0[k], float)) for k in names], axis=1)
    return StartsInBox(names, starts, lo, hi)


def minimize(
    state: Callable,
    x0: Mapping,
    bounds: Mapping[str, tuple[float, float]],
    *,
    peak_scale: float = 1.0,
    method: str = "SLSQP",
    maxiter: int = 200,
    tol: float = 1e-12,
    feas_tol: float = 1e-8,
    prog: Program | None = None,
) -> ConstrainedResult:
    """Solve ``min max_i peak_i(x)  s.t.  eq(x) = 0, le(x) <= 0, bounds``, from each start.

    **Arguments**

    - `state`: ``state({name: scalar}) -> Stated`` for one design, in ``jax.numpy``.
    - `x0`: ``{name: (S,)}`` starting designs (every name needs `bounds`).
    - `bounds`: ``{name: (low, high)}`` finite; the optimiser works in the scaled
      variables ``(x - low) / (high - low)`` and stays in the box.
    - `peak_scale`: a typical size of ``peak`` (its units); the epigraph variable and the
      peak constraints are divided by it.  Give the starting design's peak, say.
    - `method`: ``"SLSQP"`` or ``"trust-constr"`` (``scipy.optimize.minimize``).
    - `maxiter`, `tol`: the optimiser's budget and tolerance (``ftol`` of SLSQP, ``gtol``
      and ``xtol`` of trust-constr).  `feas_tol`: largest violation a winner may have.
    - `prog`: a ``Program`` from an earlier call, to reuse (else compiled here).

    A start that cannot be assembled is moved halfway towards the first start until it
    can (at most 20 times); the report says so.  If the optimiser stops on a design that
    cannot be assembled (SLSQP's line search may accept one), it is restarted from the
    last assemblable iterate (at most 3 times, within `maxiter` in all).  After the optimiser stops, a few
    least-norm Gauss-Newton steps pull its last iterate onto the constraints (SQP iterates
    carry a violation of the order of their last step).

    **Returns** a ``ConstrainedResult`` (``report()`` says who won and why others stopped).
    """
    if method not in ("SLSQP", "trust-constr"):
        raise ValueError(f"minimize: method must be 'SLSQP' or 'trust-constr', got {method!r}")
    names, starts, lo, hi = starts_in_box(x0, bounds, "minimize")
    t_start = time.perf_counter()
    compiled_here = prog is None
    prog = program(state, names, starts[0]) if compiled_here else prog
    if prog.names != names:
        raise ValueError(f"minimize: prog was compiled for {prog.names}, not {names}")
    problem = ScaledProblem(prog, lo, hi, peak_scale)
    rows = []
    for s in range(starts.shape[0]):
        counts = (problem.evals, problem.failed)
        start = _start_point(problem, starts, s)
        res, nit, restarts = _optimise(problem, start.z0, method, maxiter, tol)
        rows.append(_finish(problem, start, res, nit, restarts, feas_tol, counts))
    value = np.array([r.peak for r in rows])
    viol = np.array([r.violation for r in rows])
    feasible = np.isfinite(value) & (viol <= feas_tol)
    best = int(np.argmin(np.where(feasible, value, np.inf))) if np.any(feasible) else -1
    xs = np.stack([r.x for r in rows])
    return ConstrainedResult(
        params={k: xs[:, i] for i, k in enumerate(names)}, value=value, violation=viol,
        success=np.array([r.success for r in rows]), message=tuple(r.message for r in rows),
        iterations=np.array([r.iterations for r in rows]), evaluations=np.array([r.evaluations for r in rows]),
        failed_trials=np.array([r.failed_trials for r in rows]), best=best, feas_tol=feas_tol, method=method,
        wall_s=time.perf_counter() - t_start, compile_s=prog.compile_s if compiled_here else 0.0,
    )
