"""flap_msd's constrained design: the SQP with exact Hessians against Nelder-Mead and SLSQP.

The problem (``examples/design_problems.flap_stroke_problem``): choose the lengths of loops 2
and 3 of the MSD double flap (d, p, s, t, g, h, z) for the least peak motor torque over the
stroke (101 samples, 275 -> 320 deg at 1 rad/s), the second flap turning through exactly
60 deg from the document's start angle, no transmission angle of loops 2 and 3 below a limit
at any sample, lengths in a box (0.7-1.3 times the document's; h, z 0.5-1.5).

- ``gradient``: ``jaxmech.design.minimize_second_order`` (SQP, exact Hessians of every
  constraint at every sample by the second-order adjoint), 4 starts (``flap_starts``) in one
  program; cold: a new process with an empty executable store (its compile included), warm:
  a second process that loads the stored program.  ``time_to_nm_final_s``: the first moment
  the best feasible design is at or below Nelder-Mead's final value (the call's wall time:
  the starts end together).
- ``nelder_mead``: ``scipy.optimize.minimize(method="Nelder-Mead")`` from the same 4 starts
  on the same problem with h and z eliminated by the two equalities (closed form + Newton)
  and every inequality as an extreme barrier (inf where violated); the sampled peak
  (no smoothing); its objective compiled before the clock starts.
- ``slsqp``: today's ``design.constrained.minimize`` (scipy SLSQP, exact Jacobians) on the same
  statement, 300 iterations, same starts.
- ``trust_constr``: scipy ``trust-constr`` with the same exact Hessians
  (``stroke_evaluator``) on the epigraph form (``_Epigraph``), same box and starts, one after
  another.
- ``ipopt``: IPOPT through ``cyipopt`` (``pip install cyipopt-wheels``) with the same exact
  Hessians on the same epigraph form, tol 1e-8; a trial that does not assemble is an
  evaluation error, which IPOPT's line search cuts back from.
- ``slsqp_jax``: slsqp-jax (pure JAX, L-BFGS model, exact Jacobians) on the same form, every
  start in one vmapped ``optimistix.minimise``, 40 steps (300 took 991 s here, no start
  converged: ``python -m benchmarks.design_flap --slsqp-jax '{"limit_deg": 20, "max_steps": 300}'``); in a child process killed after
  ``SLSQP_JAX_LIMIT_S``.
- ``batch``: 256 starts (the document's design, then random ones within +-10 %) in one call,
  against 4 starts run one after another through the one-start program (both warm).
- ``limits``: the same design with a 1 deg transmission limit (the document's problem with
  almost nothing but assemblability: its optimum is close to loop 2's toggle at the stroke
  start), and 0 deg, where the infimum lies on the toggle: the motion's derivatives there
  are unbounded, so no KKT point exists and the starts say so.

Run: ``python -m benchmarks.design --flap`` (merged into ``results/design.json``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

LIMIT_DEG = 20.0
STARTS = 4
PEAK_SCALE = 3000.0  # N m, the document's peak: every method's torque rows in these units
SLSQP_JAX_LIMIT_S = 600.0  # s: slsqp-jax's compile (about 76 s here) and run, then killed


def child(spec: dict) -> dict:
    """Run one SQP call in this process (a fresh interpreter) and report it."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from examples.design_problems import FLAP_ELIMINATED, FLAP_VARS, flap_starts, flap_state_bounds, flap_stroke_problem
    from jaxmech.design import SQPOptions, minimize_second_order
    from jaxmech.scenes.flap_msd import DEFAULTS

    n = spec["starts"]
    p0 = flap_starts(n, seed=spec.get("seed", 0))
    p0 = {**p0, **{k: np.full(n, DEFAULTS[k]) for k in FLAP_ELIMINATED}}
    prob = flap_stroke_problem(101, np.deg2rad(spec["limit_deg"]))
    opts = SQPOptions(**({"max_iter": spec["max_iter"]} if "max_iter" in spec else {}))
    out = {}
    doc = {k: DEFAULTS[k] for k in FLAP_VARS}  # the design a start that does not assemble moves towards
    for label, idx in spec.get("runs", {"all": list(range(n))}).items():
        t0 = time.perf_counter()
        res = minimize_second_order(prob, {k: p0[k][idx] for k in FLAP_VARS}, flap_state_bounds(), peak_scale=PEAK_SCALE, options=opts,
                                    reference=doc)
        out[label] = {"wall_s": time.perf_counter() - t0, "value": res.value.tolist(), "status": res.status.tolist(),
                      "kkt": res.kkt.tolist(), "violation": res.violation.tolist(), "iterations": res.iterations.tolist(),
                      "best": res.best, "optima": res.optima, "design": res.best_params if res.best >= 0 else None,
                      "report": res.report(show=8)}
    return out


def run_child(spec: dict, store: str) -> dict:
    env = {**os.environ, "JAXMECH_COMPILE_CACHE": store}
    cmd = [sys.executable, "-m", "benchmarks.design_flap", "--child", json.dumps(spec)]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def nelder_mead(limit_deg: float, starts: int = STARTS) -> dict:
    """Nelder-Mead on the eliminated problem (module docstring), in this process."""
    import jax
    import jax.numpy as jnp
    from scipy.optimize import minimize

    from examples.design_problems import FLAP_FREE, _flap_project, flap_bounds, flap_starts, flap_stroke_problem
    from jaxmech.design.stroke_problem import stroke_state

    state = stroke_state(flap_stroke_problem(101, np.deg2rad(limit_deg)))

    @jax.jit
    def value(free):
        h, z, ok = _flap_project(free)
        s = state({**free, "h": h, "z": z})
        return jnp.where(ok & s.ok & jnp.all(s.le <= 0), jnp.max(s.peak), jnp.inf)

    free0 = flap_starts(starts)
    value({k: float(v[0]) for k, v in free0.items()})  # compiled before the clock starts
    trace, rows = [], []
    t0 = time.perf_counter()

    def f(x):
        v = float(value(dict(zip(FLAP_FREE, x))))
        trace.append((time.perf_counter() - t0, min(v, trace[-1][1]) if trace else v))
        return v

    bounds = flap_bounds()
    for i in range(starts):
        r = minimize(f, [float(free0[k][i]) for k in FLAP_FREE], method="Nelder-Mead", bounds=[bounds[k] for k in FLAP_FREE],
                     options={"xatol": 1e-10, "fatol": 1e-10, "maxfev": 4000})
        rows.append({"value": float(r.fun), "evaluations": int(r.nfev), "x": r.x.tolist()})
    final = min(v for _, v in trace)
    return {"objective": final, "wall_s": next(t for t, v in trace if v <= final), "wall_s_all_starts": time.perf_counter() - t0,
            "rows": rows, "objective_kind": "sampled peak, h and z eliminated, inequalities as an extreme barrier"}


def slsqp(limit_deg: float, starts: int = STARTS) -> dict:
    from examples.design_problems import FLAP_ELIMINATED, FLAP_VARS, flap_starts, flap_state, flap_state_bounds
    from jaxmech.design.constrained import minimize
    from jaxmech.scenes.flap_msd import DEFAULTS

    x0 = {**flap_starts(starts), **{k: np.full(starts, DEFAULTS[k]) for k in FLAP_ELIMINATED}}
    t0 = time.perf_counter()
    res = minimize(flap_state(101, np.deg2rad(limit_deg)), {k: x0[k] for k in FLAP_VARS}, flap_state_bounds(), peak_scale=PEAK_SCALE, maxiter=300)
    return {"objective": float(res.value[res.best]) if res.best >= 0 else None, "wall_s": time.perf_counter() - t0,
            "iterations": res.iterations.tolist(), "violation": res.violation.tolist(), "report": res.report()}


class _Epigraph:
    """The flap problem in epigraph form for a general NLP solver: minimise ``t`` over
    ``z = (x, t)`` with every sample's torque ``<= t`` (rows in units of ``PEAK_SCALE``), the
    travel equalities and the transmission limits, the same box and starts.  Rows, Jacobians
    and Lagrangian Hessians are ``stroke_evaluator``'s (the same as the SQP's), compiled
    before any clock starts.  ``assembles(z)`` says whether the design assembles at every
    sample (a trial that does not has no rows: each solver hears it its own way)."""

    SCALE = PEAK_SCALE

    def __init__(self, limit_deg: float, starts: int = STARTS):
        import jax
        import jax.numpy as jnp

        from examples.design_problems import FLAP_ELIMINATED, FLAP_VARS, flap_starts, flap_state_bounds, flap_stroke_problem
        from jaxmech.design.stroke_problem import stroke_evaluator, stroke_sizes
        from jaxmech.scenes.flap_msd import DEFAULTS

        self._jnp = jnp
        self.problem = flap_stroke_problem(101, np.deg2rad(limit_deg))
        self.n_peak, self.n_eq, self.n_le = stroke_sizes(self.problem)
        self.k = self.n_peak + self.n_eq + self.n_le
        self.n = n = len(FLAP_VARS)
        self.row_scale = np.concatenate([np.full(self.n_peak, 1.0 / self.SCALE), np.ones(self.n_eq + self.n_le)])
        self.evaluate = jax.jit(stroke_evaluator(self.problem))
        self.evaluate(jnp.asarray([DEFAULTS[v] for v in FLAP_VARS]), jnp.zeros(self.k)).values.block_until_ready()
        self._cache: dict = {}
        self.t_col = np.concatenate([-np.ones(self.n_peak), np.zeros(self.n_eq + self.n_le)])
        box = flap_state_bounds()
        self.lower = np.array([box[v][0] for v in FLAP_VARS] + [-np.inf])
        self.upper = np.array([box[v][1] for v in FLAP_VARS] + [np.inf])
        x0 = {**flap_starts(starts), **{v: np.full(starts, DEFAULTS[v]) for v in FLAP_ELIMINATED}}
        self.x0 = [np.array([float(x0[v][i]) for v in FLAP_VARS]) for i in range(starts)]
        # the constraint c(z): peak rows - t <= 0, eq rows = 0, le rows <= 0
        self.c_lower = np.concatenate([np.full(self.n_peak, -np.inf), np.zeros(self.n_eq), np.full(self.n_le, -np.inf)])
        self.c_upper = np.zeros(self.k)

    def _rows(self, z):
        key = z[:self.n].tobytes()
        if key not in self._cache:
            self._cache.clear()
            r = self.evaluate(self._jnp.asarray(z[:self.n]), self._jnp.zeros(self.k))
            self._cache[key] = (np.asarray(r.values) * self.row_scale, np.asarray(r.jac) * self.row_scale[:, None], bool(r.ok))
        return self._cache[key]

    def assembles(self, z) -> bool:
        return self._rows(z)[2]

    def start(self, i: int):
        x = self.x0[i]
        return np.append(x, np.nanmax(self._rows(np.append(x, 0.0))[0][:self.n_peak]))

    def c(self, z):
        v = self._rows(z)[0]
        return np.concatenate([v[:self.n_peak] - z[self.n], v[self.n_peak:]])

    def c_jac(self, z):
        return np.hstack([self._rows(z)[1], self.t_col[:, None]])

    def c_hess(self, z, v):
        """Hessian of ``v . c(z)`` over ``z`` ((n+1, n+1); ``t`` enters linearly)."""
        h = np.asarray(self.evaluate(self._jnp.asarray(z[:self.n]), self._jnp.asarray(v * self.row_scale)).hess)
        out = np.zeros((self.n + 1, self.n + 1))
        out[:self.n, :self.n] = h
        return out

    def violation(self, z) -> float:
        c = self.c(z)
        return float(np.max(np.concatenate([np.maximum(c[:self.n_peak], 0), np.abs(c[self.n_peak:self.n_peak + self.n_eq]),
                                            np.maximum(c[self.n_peak + self.n_eq:], 0)])))

    def peak(self, z) -> float:
        return float(np.max(self._rows(z)[0][:self.n_peak]) * self.SCALE)

    def outcome(self, runs: list, t0: float, method: str) -> dict:
        feasible = [r["peak"] for r in runs if np.isfinite(r["peak"]) and r["violation"] <= 1e-8]
        return {"objective": min(feasible) if feasible else None, "wall_s": time.perf_counter() - t0, "runs": runs,
                "method": method}


def trust_constr(limit_deg: float, starts: int = STARTS, maxiter: int = 500) -> dict:
    """scipy ``trust-constr`` with the exact Hessian on the epigraph form (``_Epigraph``),
    one start after another.  A trial design that does not assemble gives NaN rows
    (trust-constr has no other way to hear it)."""
    from scipy.optimize import Bounds, NonlinearConstraint, minimize

    e = _Epigraph(limit_deg, starts)
    n = e.n
    con = NonlinearConstraint(e.c, e.c_lower, e.c_upper, jac=e.c_jac, hess=e.c_hess)
    runs = []
    t0 = time.perf_counter()
    for i in range(starts):
        r = minimize(lambda z: z[n], e.start(i), jac=lambda z: np.eye(n + 1)[n], hess=lambda z: np.zeros((n + 1, n + 1)),
                     method="trust-constr", constraints=[con], bounds=Bounds(e.lower, e.upper),
                     options={"maxiter": maxiter, "gtol": 1e-8, "xtol": 1e-12})
        runs.append({"objective": float(r.x[n] * e.SCALE), "peak": e.peak(r.x), "status": int(r.status),
                     "message": str(r.message), "iterations": int(r.nit), "optimality": float(r.optimality),
                     "violation": e.violation(r.x), "wall_s": time.perf_counter() - t0})
    return e.outcome(runs, t0, "scipy trust-constr (exact Hessian of the Lagrangian from stroke_evaluator), epigraph form, "
                               "starts one after another")


def ipopt(limit_deg: float, starts: int = STARTS, maxiter: int = 500) -> dict:
    """IPOPT (``cyipopt``, the ``cyipopt-wheels`` build) with the exact Hessian of the
    Lagrangian on the epigraph form (``_Epigraph``), one start after another, tol 1e-8.  A
    trial design that does not assemble raises ``CyIpoptEvaluationError``: IPOPT's own line
    search cuts the step back.  Absent when cyipopt does not import."""
    try:
        import cyipopt
    except ImportError as err:
        return {"skipped": f"cyipopt not importable ({err}); pip install cyipopt-wheels"}
    e = _Epigraph(limit_deg, starts)
    n, k = e.n, e.k
    rows, cols = np.tril_indices(n + 1)

    def _assembled(z):
        """`z`, or IPOPT's evaluation error where the design does not assemble."""
        if not e.assembles(z):
            raise cyipopt.CyIpoptEvaluationError()
        return z

    class _NLP:
        def objective(self, z):
            return z[n]

        def gradient(self, z):
            return np.eye(n + 1)[n]

        def constraints(self, z):
            return e.c(_assembled(z))

        def jacobian(self, z):
            return e.c_jac(_assembled(z)).ravel()

        def hessian(self, z, lagrange, obj_factor):
            return e.c_hess(_assembled(z), np.asarray(lagrange))[rows, cols]  # the objective t is linear

        def hessianstructure(self):
            return rows, cols

        def intermediate(self, alg_mod, iter_count, *args):
            self.iterations = iter_count

    runs = []
    t0 = time.perf_counter()
    for i in range(starts):
        nlp = _NLP()
        problem = cyipopt.Problem(n=n + 1, m=k, problem_obj=nlp, lb=e.lower, ub=e.upper, cl=e.c_lower, cu=e.c_upper)
        for key, value in (("tol", 1e-8), ("constr_viol_tol", 1e-8), ("max_iter", maxiter), ("print_level", 0),
                           ("sb", "yes"), ("hessian_approximation", "exact")):
            problem.add_option(key, value)
        z, info = problem.solve(e.start(i))
        runs.append({"objective": float(z[n] * e.SCALE), "peak": e.peak(z) if e.assembles(z) else float("inf"),
                     "status": int(info["status"]), "message": info["status_msg"].decode() if isinstance(info["status_msg"], bytes)
                     else str(info["status_msg"]), "iterations": int(getattr(nlp, "iterations", -1)),
                     "violation": e.violation(z) if e.assembles(z) else float("inf"), "wall_s": time.perf_counter() - t0})
    return e.outcome(runs, t0, f"IPOPT {cyipopt.IPOPT_VERSION if hasattr(cyipopt, 'IPOPT_VERSION') else ''} through cyipopt "
                               "(exact Hessian of the Lagrangian from stroke_evaluator), epigraph form, starts one after another")


def slsqp_jax(limit_deg: float, starts: int = STARTS, max_steps: int = 300) -> dict:
    """slsqp-jax (a pure-JAX SLSQP on optimistix, L-BFGS Hessian model) on the epigraph form,
    every start in one ``vmap``ped ``optimistix.minimise`` call, given the rows and their exact
    Jacobians (forward mode through the implicit rule, ``stroke_state``; no Hessians: it keeps
    its own model); rtol = atol = 1e-8.  ``_Epigraph``'s compiled evaluator only makes the
    starts and scores the results, outside the clock.  A trial design that does
    not assemble has NaN rows.  ``wall_s`` is the compile (``compile_s``) and the run
    (``run_s``).  Absent when slsqp_jax does not import."""
    try:
        import optimistix as optx
        import slsqp_jax
    except ImportError as err:
        return {"skipped": f"slsqp-jax not importable ({err}); pip install slsqp-jax"}
    import jax
    import jax.numpy as jnp

    e = _Epigraph(limit_deg, starts)
    n, n_peak, n_eq, k = e.n, e.n_peak, e.n_eq, e.k
    scale = jnp.asarray(e.row_scale)

    from examples.design_problems import FLAP_VARS
    from jaxmech.design.stroke_problem import stroke_state

    state = stroke_state(e.problem)

    def values(x):
        s = state(dict(zip(FLAP_VARS, x)))
        v = jnp.concatenate([jnp.ravel(s.peak), jnp.ravel(s.eq), jnp.ravel(s.le)]) * scale
        return v, (v, s.ok)

    def rows(z):  # first order only: slsqp-jax builds its own Hessian model
        jac, (v, ok) = jax.jacfwd(values, has_aux=True)(z[:n])
        bad = jnp.where(ok, 0.0, jnp.nan)
        return v + bad, jac + bad

    def eq(z, args):
        return rows(z)[0][n_peak:n_peak + n_eq]

    def eq_jac(z, args):
        return jnp.pad(rows(z)[1][n_peak:n_peak + n_eq], ((0, 0), (0, 1)))

    def ineq(z, args):  # c >= 0: t - peak rows, - le rows
        v = rows(z)[0]
        return jnp.concatenate([z[n] - v[:n_peak], -v[n_peak + n_eq:]])

    def ineq_jac(z, args):
        j = rows(z)[1]
        return jnp.concatenate([jnp.hstack([-j[:n_peak], jnp.ones((n_peak, 1))]), jnp.pad(-j[n_peak + n_eq:], ((0, 0), (0, 1)))])

    solver = slsqp_jax.SLSQP(
        eq_constraint_fn=eq, n_eq_constraints=n_eq, ineq_constraint_fn=ineq, n_ineq_constraints=k - n_eq,
        bounds=jnp.stack([jnp.asarray(np.where(np.isfinite(e.lower), e.lower, -1e6)), jnp.asarray(np.where(np.isfinite(e.upper), e.upper, 1e6))], 1),
        obj_grad_fn=lambda z, args: jnp.eye(n + 1)[n], eq_jac_fn=eq_jac, ineq_jac_fn=ineq_jac,
        config=slsqp_jax.SLSQPConfig(tolerance=slsqp_jax.ToleranceConfig(rtol=1e-8, atol=1e-8, max_steps=max_steps)))

    @jax.jit
    def solve(z0):
        def one(z):
            sol = optx.minimise(lambda z_, args: (z_[n], None), solver, z, has_aux=True, max_steps=max_steps, throw=False)
            return sol.value, sol.stats["num_steps"], slsqp_jax.RESULTS.promote(sol.result) == slsqp_jax.RESULTS.successful
        return jax.vmap(one)(z0)

    z0 = jnp.asarray(np.stack([e.start(i) for i in range(starts)]))
    t0 = time.perf_counter()
    compiled = solve.lower(z0).compile()
    compile_s = time.perf_counter() - t0
    print(f"slsqp-jax: compiled in {compile_s:.1f} s", file=sys.stderr, flush=True)
    t1 = time.perf_counter()
    z, steps, ok = jax.block_until_ready(compiled(z0))
    run_s = time.perf_counter() - t1
    z, steps, ok = np.asarray(z), np.asarray(steps), np.asarray(ok)
    runs = [{"objective": float(z[i, n] * e.SCALE), "peak": e.peak(z[i]) if e.assembles(z[i]) else float("inf"),
             "successful": bool(ok[i]), "iterations": int(steps[i]),
             "violation": e.violation(z[i]) if e.assembles(z[i]) else float("inf")} for i in range(starts)]
    out = e.outcome(runs, t0, f"slsqp-jax {getattr(slsqp_jax, '__version__', '')} (L-BFGS model, exact Jacobians from "
                              "stroke_evaluator), epigraph form, all starts in one vmapped optimistix.minimise")
    out.update(wall_s=compile_s + run_s, compile_s=compile_s, run_s=run_s)
    return out


def _summary(cold: dict, warm: dict, nm_final: float) -> dict:
    c, w = cold["all"], warm["all"]
    best = c["value"][c["best"]] if c["best"] >= 0 else None
    reached = best is not None and best <= nm_final
    return {"objective": best, "wall_s": c["wall_s"], "compile_s": c["wall_s"] - w["wall_s"],
            "time_to_nm_final_s": c["wall_s"] if reached else None, "time_to_nm_final_s_warm": w["wall_s"] if reached else None,
            "converged_starts": int(sum(s == 0 for s in c["status"])), "starts": len(c["status"]), "max_kkt": max(c["kkt"]),
            "max_violation": max(c["violation"]), "iterations": c["iterations"], "design": c["design"], "report": c["report"],
            "method": "jaxmech.design.minimize_second_order: SQP, exact Hessian of the Lagrangian by the second-order adjoint "
                      "(every constraint at every sample), QPs by Mehrotra + active-set polish, l1 penalty line search with "
                      "second-order corrections; all starts in one vmapped program"}


def bench_flap_problem() -> dict:
    out = {"limit_deg": LIMIT_DEG}
    with tempfile.TemporaryDirectory() as store:
        spec = {"starts": STARTS, "limit_deg": LIMIT_DEG}
        cold, warm = run_child(spec, store), run_child(spec, store)
    out["nelder_mead"] = nm = nelder_mead(LIMIT_DEG)
    out["gradient"] = _summary(cold, warm, nm["objective"])
    g = out["gradient"]
    if g["time_to_nm_final_s"]:
        out["ratio_to_nm_cold"] = g["time_to_nm_final_s"] / nm["wall_s"]
        out["ratio_to_nm_warm"] = g["time_to_nm_final_s_warm"] / nm["wall_s"]
    print(f"flap ({LIMIT_DEG:g} deg): SQP {g['objective']} ({g['converged_starts']}/{g['starts']} converged) cold {g['wall_s']:.2f} s, "
          f"warm {warm['all']['wall_s']:.2f} s; Nelder-Mead {nm['objective']:.6f} after {nm['wall_s']:.2f} s", flush=True)
    out["slsqp"] = slsqp(LIMIT_DEG)
    out["trust_constr"] = tc = trust_constr(LIMIT_DEG)
    print(f"flap: trust-constr {tc['objective']} after {tc['wall_s']:.2f} s "
          f"({[r['status'] for r in tc['runs']]}, iterations {[r['iterations'] for r in tc['runs']]})", flush=True)
    out["ipopt"] = ip = ipopt(LIMIT_DEG)
    print(f"flap: IPOPT {ip.get('objective')} after {ip.get('wall_s', 0):.2f} s "
          f"({[(r['status'], r['iterations']) for r in ip.get('runs', [])]}) {ip.get('skipped', '')}", flush=True)
    out["slsqp_jax"] = sj = slsqp_jax_bounded(LIMIT_DEG)
    print(f"flap: slsqp-jax {sj.get('objective')} after {sj.get('wall_s', 0):.2f} s "
          f"({[(r['successful'], r['iterations']) for r in sj.get('runs', [])]}) {sj.get('skipped', '')}"
          f"{' killed after %.0f s' % sj['timed_out_s'] if 'timed_out_s' in sj else ''}", flush=True)
    out["batch"] = bench_batch()
    out["batch"]["speedup_per_start_vs_slsqp"] = out["slsqp"]["wall_s"] / STARTS / out["batch"]["per_start_s"]
    out["limits"] = bench_limits()
    return out


def bench_batch(n: int = 256) -> dict:
    with tempfile.TemporaryDirectory() as store:
        spec = {"starts": n, "limit_deg": LIMIT_DEG, "runs": {"warmup": list(range(n))}}
        run_child(spec, store)  # compiles and stores the n-start program
        batch = run_child({**spec, "runs": {"batch": list(range(n))}}, store)["batch"]
        one = {"starts": STARTS, "limit_deg": LIMIT_DEG, "runs": {"warmup": [0]}}
        run_child(one, store)  # the one-start program
        seq = run_child({**one, "runs": {f"start{i}": [i] for i in range(STARTS)}}, store)
    seq_s = sum(r["wall_s"] for r in seq.values())
    per_batch, per_seq = batch["wall_s"] / n, seq_s / STARTS
    converged = int(sum(s == 0 for s in batch["status"]))
    print(f"batch: {n} starts in {batch['wall_s']:.2f} s ({per_batch * 1e3:.1f} ms a start, {converged} converged); "
          f"{STARTS} sequential starts {seq_s:.2f} s ({per_seq * 1e3:.1f} ms a start)", flush=True)
    return {"starts": n, "wall_s": batch["wall_s"], "per_start_s": per_batch, "converged_starts": converged,
            "optima": batch["optima"], "sequential_starts": STARTS, "sequential_wall_s": seq_s, "sequential_per_start_s": per_seq,
            "speedup_per_start": per_seq / per_batch, "note": "both warm (programs loaded from the store); the one-start program "
            "is called once per start, as a user's loop would"}


def bench_limits() -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as store:
        for deg, it in ((1.0, 1500), (0.0, 400)):
            r = run_child({"starts": STARTS, "limit_deg": deg, "max_iter": it}, store)["all"]
            out[f"{deg:g}deg"] = {k: r[k] for k in ("wall_s", "value", "status", "kkt", "violation", "iterations", "report")}
            print(f"limit {deg:g} deg: values {np.round(r['value'], 4).tolist()}, statuses {r['status']}", flush=True)
    return out


def slsqp_jax_bounded(limit_deg: float, seconds: float = SLSQP_JAX_LIMIT_S, max_steps: int = 40) -> dict:
    """``slsqp_jax`` in a fresh process, killed past `seconds` (its vmapped loop runs until
    the slowest start ends, and one that never converges takes every step)."""
    import jax

    cmd = [sys.executable, "-m", "benchmarks.design_flap", "--slsqp-jax", json.dumps({"limit_deg": limit_deg, "max_steps": max_steps})]
    env = {**os.environ, "JAX_ENABLE_X64": "1" if jax.config.jax_enable_x64 else "0"}
    t0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=seconds, check=True)
    except subprocess.TimeoutExpired as err:
        said = (err.stderr or b"").decode() if isinstance(err.stderr, bytes) else (err.stderr or "")
        return {"objective": None, "timed_out_s": seconds, "wall_s": time.perf_counter() - t0, "stderr": said.strip()[-500:],
                "max_steps": max_steps}
    return json.loads(done.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(child(json.loads(sys.argv[2]))))
    elif sys.argv[1:2] == ["--slsqp-jax"]:
        import jax

        jax.config.update("jax_enable_x64", True)
        spec = json.loads(sys.argv[2])
        print(json.dumps(slsqp_jax(spec["limit_deg"], max_steps=spec["max_steps"]), default=float))
    else:
        print(json.dumps(bench_flap_problem(), indent=1, default=float)[:4000])
