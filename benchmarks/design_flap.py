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
  (``stroke_evaluator``) on the epigraph form, same box and starts, one after another.
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
        res = minimize_second_order(prob, {k: p0[k][idx] for k in FLAP_VARS}, flap_state_bounds(), peak_scale=3000.0, options=opts,
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
    res = minimize(flap_state(101, np.deg2rad(limit_deg)), {k: x0[k] for k in FLAP_VARS}, flap_state_bounds(), peak_scale=3000.0, maxiter=300)
    return {"objective": float(res.value[res.best]) if res.best >= 0 else None, "wall_s": time.perf_counter() - t0,
            "iterations": res.iterations.tolist(), "violation": res.violation.tolist(), "report": res.report()}


def trust_constr(limit_deg: float, starts: int = STARTS, maxiter: int = 500) -> dict:
    """scipy ``trust-constr`` with the exact Hessian (``stroke_evaluator``: the same rows,
    Jacobians and Lagrangian Hessians as the SQP) on the epigraph form of the same problem:
    minimise ``t`` over ``(x, t)`` with every sample's torque ``<= t``, the travel equality and
    the transmission limits, the same box and starts, one start after another.  A trial
    design that does not assemble gives NaN rows (trust-constr has no other way to hear it)."""
    import jax
    import jax.numpy as jnp
    from scipy.optimize import Bounds, NonlinearConstraint, minimize

    from examples.design_problems import FLAP_ELIMINATED, FLAP_VARS, flap_starts, flap_state_bounds, flap_stroke_problem
    from jaxmech.design.stroke_problem import stroke_evaluator, stroke_sizes
    from jaxmech.scenes.flap_msd import DEFAULTS

    scale = 3000.0  # N m: rows and t in units of the document's peak
    prob = flap_stroke_problem(101, np.deg2rad(limit_deg))
    n_peak, n_eq, n_le = stroke_sizes(prob)
    k = n_peak + n_eq + n_le
    row_scale = np.concatenate([np.full(n_peak, 1.0 / scale), np.ones(n_eq + n_le)])
    evaluate = jax.jit(stroke_evaluator(prob))
    n = len(FLAP_VARS)
    evaluate(jnp.asarray([DEFAULTS[v] for v in FLAP_VARS]), jnp.zeros(k)).values.block_until_ready()  # compiled before the clock
    cache: dict = {}

    def rows(z):
        key = z[:n].tobytes()
        if key not in cache:
            cache.clear()
            r = evaluate(jnp.asarray(z[:n]), jnp.zeros(k))
            cache[key] = (np.asarray(r.values) * row_scale, np.asarray(r.jac) * row_scale[:, None])
        return cache[key]

    def c(z):
        v, _ = rows(z)
        return np.concatenate([v[:n_peak] - z[n], v[n_peak:]])

    def c_jac(z):
        _, j = rows(z)
        return np.hstack([j, np.concatenate([-np.ones(n_peak), np.zeros(n_eq + n_le)])[:, None]])

    def c_hess(z, v):
        h = np.asarray(evaluate(jnp.asarray(z[:n]), jnp.asarray(v * row_scale)).hess)
        out = np.zeros((n + 1, n + 1))
        out[:n, :n] = h
        return out

    lb = np.concatenate([np.full(n_peak, -np.inf), np.zeros(n_eq), np.full(n_le, -np.inf)])
    con = NonlinearConstraint(c, lb, np.zeros(k), jac=c_jac, hess=c_hess)
    box = flap_state_bounds()
    bounds = Bounds([box[v][0] for v in FLAP_VARS] + [-np.inf], [box[v][1] for v in FLAP_VARS] + [np.inf])
    x0 = {**flap_starts(starts), **{v: np.full(starts, DEFAULTS[v]) for v in FLAP_ELIMINATED}}
    runs = []
    t0 = time.perf_counter()
    for i in range(starts):
        x = np.array([float(x0[v][i]) for v in FLAP_VARS])
        z0 = np.append(x, np.nanmax(rows(np.append(x, 0.0))[0][:n_peak]))
        r = minimize(lambda z: z[n], z0, jac=lambda z: np.eye(n + 1)[n], hess=lambda z: np.zeros((n + 1, n + 1)),
                     method="trust-constr", constraints=[con], bounds=bounds, options={"maxiter": maxiter, "gtol": 1e-8, "xtol": 1e-12})
        viol = float(np.max(np.maximum(np.concatenate([np.maximum(c(r.x)[:n_peak], 0), np.abs(c(r.x)[n_peak:n_peak + n_eq]),
                                                       np.maximum(c(r.x)[n_peak + n_eq:], 0)]), 0.0)))
        runs.append({"objective": float(r.x[n] * scale), "peak": float(np.max(rows(r.x)[0][:n_peak]) * scale), "status": int(r.status),
                     "message": str(r.message), "iterations": int(r.nit), "optimality": float(r.optimality),
                     "violation": viol, "wall_s": time.perf_counter() - t0})
    feasible = [r["peak"] for r in runs if np.isfinite(r["peak"]) and r["violation"] <= 1e-8]
    return {"objective": min(feasible) if feasible else None, "wall_s": time.perf_counter() - t0, "runs": runs,
            "method": "scipy trust-constr (exact Hessian of the Lagrangian from stroke_evaluator), epigraph form, starts one after another"}


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


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(child(json.loads(sys.argv[2]))))
    else:
        print(json.dumps(bench_flap_problem(), indent=1, default=float)[:4000])
