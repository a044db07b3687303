"""Render the benchmark JSON results as Markdown tables (for the project README).

``python -m benchmarks.summary [--results DIR] [--output FILE]``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.common import RESULTS


def _load(results: Path, name: str):
    p = results / f"{name}.json"
    return json.loads(p.read_text()) if p.exists() else None


def _f(x, fmt="{:.3g}"):
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    return fmt.format(x)


def _machine(doc) -> str:
    m = doc.get("machine") or {}
    v = m.get("versions") or m  # older scripts (dynamics.py) record the versions at the top level
    load = m.get("load_average_1_5_15min")
    load_s = f", load avg {load[0]:.1f}" if load else ", load avg not recorded"
    cpu = m.get("cpu_model") or m.get("processor") or m.get("platform") or "?"
    git = f" ({m['git']})" if m.get("git") else ""
    return (f"_{cpu}, {m.get('cpu_count')} cores{load_s}; jax {v.get('jax')}, "
            f"jaxmech {v.get('jaxmech')}{git}, {m.get('date')}{' (--quick)' if doc.get('quick') else ''}_")


def kinematics_table(doc) -> str:
    lines = ["### Four-bar positions + velocities + accelerations (`benchmarks/kinematics.py`)", "", _machine(doc), "",
             "| case | method | positions | ns / position | compile (s) | pos err (rad) | vel err (rad/s) | acc err (rad/s²) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in doc["rows"]:
        sub = " (subsample)" if r.get("subsample") else ""
        lines.append(f"| {r['case']} | {r['method']}{sub} | {r['n_positions']:,} | {_f(r['ns_per_position'], '{:,.0f}')} | "
                     f"{_f(r['compile_s'], '{:.2f}')} | {_f(r['pos_err_rad'], '{:.1e}')} | {_f(r['vel_err'], '{:.1e}')} | {_f(r['acc_err'], '{:.1e}')} |")
    lines += ["", "| case | positions | jaxmech / closed form (JAX) | fsolve / jaxmech | pylinkage / jaxmech |", "|---|---:|---:|---:|---:|"]
    for r in doc.get("ratios", []):
        lines.append(f"| {r['case']} | {r['n_positions']:,} | {_f(r['jaxmech_over_closed_jax'], '{:.1f}x')} | "
                     f"{_f(r['fsolve_over_jaxmech'], '{:.0f}x')} | {_f(r.get('pylinkage_over_jaxmech'), '{:.1f}x')} |")
    if doc.get("notes"):
        lines += ["", "Notes: " + "; ".join(f"{k}: {v}" for k, v in doc["notes"].items())]
    return "\n".join(lines)


def speed_error_table(doc) -> str:
    lines = ["### Speed against error, four-bar (`benchmarks/speed_error.py`)", "", _machine(doc),
             f"Reference: {doc.get('reference')}, {doc.get('n_reference')} of {doc.get('n_positions'):,} positions.", "",
             "| method | ns / position | pos err (rad) | vel err | acc err | success | NaN fraction |", "|---|---:|---:|---:|---:|---:|---:|"]
    for r in doc["rows"]:
        lines.append(f"| {r['method']} | {_f(r['ns_per_position'], '{:,.0f}')} | {_f(r['pos_err_rad'], '{:.1e}')} | "
                     f"{_f(r.get('vel_err'), '{:.1e}')} | {_f(r.get('acc_err'), '{:.1e}')} | {_f(r.get('success_rate'), '{:.3f}')} | "
                     f"{_f(r.get('nan_fraction'), '{:.3f}')} |")
    extra = {k: v for k, v in (doc.get("extra_cases") or {}).items()}
    if extra:
        lines += ["", "Other scenes: " + "; ".join(f"{k}: {v.get('skipped', 'see JSON')}" for k, v in extra.items())]
    return "\n".join(lines)


def scaling_table(doc) -> str:
    bf, lf = doc["batch_fit"], doc.get("loop_fit")
    if lf is None:  # a partial run: fit what was measured
        import numpy as np

        ks = [r["loops"] for r in doc["loops"]]
        ts = [r["ns_per_sample"] for r in doc["loops"]]
        lf = {"time_per_sample_exponent": float(np.polyfit(np.log(ks), np.log(ts), 1)[0]) if len(ks) > 1 else float("nan")}
    lines = ["### Scaling (`benchmarks/scaling.py`)", "", _machine(doc), "",
             "| batch | ns / sample | compile (s) | XLA memory (bytes) | success |", "|---:|---:|---:|---:|---:|"]
    for r in doc["batch"]:
        lines.append(f"| {r['batch']:,} | {_f(r['ns_per_sample'], '{:,.0f}')} | {_f(r['compile_s'], '{:.2f}')} | "
                     f"{_f(r['memory'].get('total_bytes'), '{:,}')} | {_f(r['success_rate'], '{:.3f}')} |")
    lines += ["", f"Fixed overhead (B = 1): {bf['fixed_overhead_s'] * 1e6:.0f} µs; growth {bf['per_sample_s_fit_B_ge_1e3'] * 1e9:.0f} ns per "
              f"sample (fit, B ≥ 1e3); {bf['bytes_per_sample_largest']:.0f} bytes per sample.", "",
              "| loops k | m | ns / sample | compile (s) | max error (rad) |", "|---:|---:|---:|---:|---:|"]
    for r in doc["loops"]:
        lines.append(f"| {r['loops']} | {r['m']} | {_f(r['ns_per_sample'], '{:,.0f}')} | {_f(r['compile_s'], '{:.2f}')} | {_f(r['max_error_rad'], '{:.1e}')} |")
    partial = " (partial run: the loops above are those measured before the run stopped)" if doc.get("partial") else ""
    lines += ["", f"Time per sample grows as k^{lf['time_per_sample_exponent']:.2f}{partial}."]
    return "\n".join(lines)


def _ms(x, fmt="{:,.2f}"):
    return _f(None if x is None else x * 1e3, fmt)


def dynamics_table(doc) -> str:
    lines = ["### Dynamics (`benchmarks/dynamics.py`)", "", _machine(doc)]
    inv = doc.get("inverse_dynamics") or []
    if inv:
        lines += ["", f"Inverse dynamics (position solve + driving torque + reactions), random crank states, {doc.get('dtype', 'float64')}:", "",
                  "| mechanism | loops | batch | positions / s | run (ms) | compile (s) | success | finite torque |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in inv:
            lines.append(f"| {r.get('mechanism')} | {_f(r.get('loops'), '{}')} | {_f(r.get('batch'), '{:,}')} | "
                         f"{_f(r.get('positions_per_s'), '{:,.0f}')} | {_ms(r.get('run_median_s'))} | {_f(r.get('compile_s'), '{:.2f}')} | "
                         f"{_f(r.get('success_rate'), '{:.3f}')} | {_f(r.get('finite_torque_rate'), '{:.3f}')} |")
    fwd = doc.get("forward_dynamics") or {}
    if fwd.get("runs"):
        ref = fwd.get("reference") or {}
        ref_s = (f"reference {ref.get('method')} (rtol {ref.get('rtol')}, atol {ref.get('atol')}, "
                 f"{_f(ref.get('nfev'), '{:,}')} evaluations, {_f(ref.get('wall_s'), '{:.1f}')} s)") if ref else "reference not recorded"
        lines += ["", f"Forward dynamics: {fwd.get('scene', '?')}, {_f(fwd.get('t_end'), '{:g}')} s; error at the end against the {ref_s}. "
                  "One compile per method (the step is traced); run time = median time per step x steps.", "",
                  "| method | h (s) | steps | θ2 err (rad) | ω err (rad/s) | current err (A) | Newton its (mean) | µs / step | run (ms) | compile (s) |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in fwd["runs"]:
            bad = r.get("finite") is False
            err = (lambda k: "diverged" if bad else _f(r.get(k), "{:.1e}"))
            lines.append(f"| {r.get('method')} | {_f(r.get('h'), '{:g}')} | {_f(r.get('steps'), '{:,}')} | {err('error_theta2_rad')} | "
                         f"{err('error_omega_rad_s')} | {err('error_current_A')} | {_f(r.get('newton_mean'), '{:.2f}')} | "
                         f"{_f(None if r.get('run_s_per_step') is None else r['run_s_per_step'] * 1e6, '{:,.0f}')} | "
                         f"{_ms(r.get('run_s_for_horizon'))} | {_f(r.get('compile_s'), '{:.2f}')} |")
    if not inv and not fwd.get("runs"):
        lines += ["", "_no inverse- or forward-dynamics rows in the JSON_"]
    return "\n".join(lines)


def design_table(doc) -> str:
    lines = ["### Design sweeps, gradients and fits (`benchmarks/design.py`)", "", _machine(doc), ""]
    sw = doc.get("sweep") or {}
    if sw.get("rows"):
        lines += [f"Sweep (`sweep_scene`, four-bar scene, {doc.get('points', '?')} stroke positions per design, every table column); "
                  f"first call {_f(sw.get('first_call_s'), '{:.1f}')} s (compile ≈ {_f(sw.get('compile_s_estimate'), '{:.1f}')} s):", "",
                  "| designs | designs x positions / s | designs / s | run (s) | chunk x chunks | kernel bytes / design | host peak alloc (MB) | results (MB) | peak RSS (MB) | converged |",
                  "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in sw["rows"]:
            lines.append(f"| {_f(r.get('designs'), '{:,}')} | {_f(r.get('designs_x_positions_per_s'), '{:,.0f}')} | "
                         f"{_f(r.get('designs_per_s'), '{:,.0f}')} | {_f(r.get('run_s'), '{:.2f}')} | "
                         f"{_f(r.get('chunk_size'), '{:,}')} x {_f(r.get('n_chunks'), '{:,}')} | {_f(r.get('kernel_bytes_per_design'), '{:,.0f}')} | "
                         f"{_f(r.get('host_peak_alloc_mb'), '{:,.1f}')} | {_f(r.get('results_mb'), '{:,.1f}')} | "
                         f"{_f(r.get('peak_rss_mb'), '{:,.0f}')} | {_f(r.get('converged_fraction'), '{:.3f}')} |")
        lines.append("")
    gr = doc.get("gradients") or {}
    if gr.get("rows"):
        params = ", ".join(gr.get("parameters") or []) or "?"
        lines += [f"Gradient of the {gr.get('figure', 'figure')} w.r.t. ({params}), {_f(gr.get('designs'), '{:,}')} designs; "
                  f"truth: {gr.get('truth', '?')}:", "",
                  "| method | evaluations / design | gradients / s | run (s) | first call (s) | max rel error |", "|---|---:|---:|---:|---:|---:|"]
        for name, r in gr["rows"].items():
            lines.append(f"| {name} | {_f(r.get('evaluations_per_design'), '{}')} | {_f(r.get('gradients_per_s'), '{:,.0f}')} | "
                         f"{_f(r.get('run_s'), '{:.3f}')} | {_f(r.get('first_call_s'), '{:.1f}')} | {_f(r.get('max_rel_error'), '{:.1e}')} |")
        lines += ["", f"Implicit gradient speed-up: {_f(gr.get('speedup_vs_fd_order2'), '{:.1f}x')} over 2nd-order FD, "
                  f"{_f(gr.get('speedup_vs_fd_order6'), '{:.1f}x')} over 6th-order FD.", ""]
    probs = [r for r in doc.get("design_problems") or [] if r.get("problem")]
    skipped = [r["skipped"] for r in doc.get("design_problems") or [] if r.get("skipped") and not r.get("problem")]
    if probs:
        lines += ["Design problems (multi-start `design.fit`, L-BFGS with implicit gradients, against scipy Nelder-Mead from the same starts):", "",
                  "| problem | starts | fit run (s) | fit first call (s) | fit best | fit steps | Nelder-Mead run (s) | NM best | NM evaluations | speed-up (run) |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in probs:
            if r.get("pending") or r.get("skipped"):
                lines.append(f"| {r.get('problem')} | _{r.get('pending') or r.get('skipped')}_ | | | | | | | | |")
                continue
            fit, nm = r.get("fit_lbfgs") or {}, r.get("nelder_mead") or {}
            steps = "/".join(str(x) for x in fit.get("steps") or []) or "-"
            evals = "/".join(str(x.get("evaluations")) for x in nm.get("rows") or []) or "-"
            lines.append(f"| {r.get('problem')} | {_f(r.get('starts'), '{}')} | {_f(fit.get('run_s'), '{:.3f}')} | "
                         f"{_f(fit.get('first_call_s_with_compile'), '{:.1f}')} | {_f(fit.get('best_value'), '{:.10g}')} | {steps} | "
                         f"{_f(nm.get('run_s'), '{:.3f}')} | {_f(nm.get('best_value'), '{:.10g}')} | {evals} | {_f(r.get('speedup_run'), '{:.1f}x')} |")
    else:
        lines.append(f"Design problems: not run ({'; '.join(skipped) or 'python -m benchmarks.design --problems'}).")
    fp = doc.get("flap_problem") or {}
    if fp.get("gradient") and fp.get("nelder_mead"):
        lines += ["", f"flap_msd constrained design (`--flap`, {_f(fp.get('limit_deg'), '{:g}')} deg transmission limit, 4 starts; "
                  "wall time includes each method's compile unless said):", "",
                  "| method | best peak (N m) | starts converged | wall (s) | compile (s) |", "|---|---:|---:|---:|---:|"]
        g = fp["gradient"]
        lines.append(f"| jaxmech SQP, exact Hessians | {_f(g.get('objective'), '{:.6f}')} | {g.get('converged_starts')}/{g.get('starts')} | "
                     f"{_f(g.get('wall_s'), '{:.2f}')} cold, {_f(g.get('time_to_nm_final_s_warm'), '{:.2f}')} warm | {_f(g.get('compile_s'), '{:.1f}')} |")
        nm = fp["nelder_mead"]
        lines.append(f"| Nelder-Mead (compiled before the clock) | {_f(nm.get('objective'), '{:.6f}')} | - | {_f(nm.get('wall_s'), '{:.2f}')} | - |")
        for key, label in (("slsqp", "scipy SLSQP"), ("trust_constr", "scipy trust-constr, exact Hessians"),
                           ("ipopt", "IPOPT (cyipopt), exact Hessians, after the evaluator's compile"), ("slsqp_jax", "slsqp-jax")):
            r = fp.get(key) or {}
            if not r or r.get("skipped"):
                lines.append(f"| {label} | _{r.get('skipped', 'not run')}_ | | | |")
                continue
            runs = r.get("runs") or []
            done = {"trust_constr": lambda x: x.get("status") in (1, 2), "ipopt": lambda x: x.get("status") == 0,
                    "slsqp_jax": lambda x: bool(x.get("successful"))}.get(key)  # each method's own convergence statuses
            conv = (sum(1 for x in runs if done(x)) if runs else sum(1 for it in r.get("iterations") or [] if it < 300))
            lines.append(f"| {label} | {_f(r.get('objective'), '{:.6f}')} | {conv}/{len(runs) or len(r.get('iterations') or [])} | "
                         f"{_f(r.get('wall_s'), '{:.2f}')} | {_f(r.get('compile_s'), '{:.1f}')} |")
        lines.append("")
    ps = {k: v for k, v in (doc.get("path_synthesis") or {}).items() if isinstance(v, dict) and v.get("gradient")}
    for kind, r in ps.items():
        best = min(r.get("pylinkage_pso") or [{}], key=lambda x: x.get("error", float("inf")))
        lines.append(f"Path synthesis `{kind}` (`--synthesis`): gradient rms {_f(r['gradient'].get('error'), '{:.2e}')} m in "
                     f"{_f(r['gradient'].get('wall_s'), '{:.1f}')} s; pylinkage PSO best {_f(best.get('error'), '{:.2e}')} m in "
                     f"{_f(best.get('wall_s'), '{:.1f}')} s.")
    return "\n".join(lines).rstrip()


def sweep_scale_table(doc) -> str:
    lines = ["### Sweeps streamed to Parquet (`benchmarks/sweep_scale.py`)", "", _machine(doc), "",
             f"Four-bar random crank-rockers x {doc.get('points', '?')} positions, each case in a fresh process "
             "(`memory`: `sweep_scene`, every column in host memory; `figures`/`trace`: `sweep_dataset`):", "",
             "| mode | designs | run (s) | designs x positions / s | vs memory | peak RSS (MB) | rows written | dataset (MB) | load after |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    ratio = doc.get("throughput_ratio_vs_in_memory") or {}
    for r in doc["rows"]:
        lines.append(f"| {r['mode']} | {_f(r.get('designs'), '{:,}')} | {_f(r.get('run_s'), '{:.1f}')} | "
                     f"{_f(r.get('designs_x_positions_per_s'), '{:,.0f}')} | {_f(ratio.get(r['mode'], 1.0), '{:.2f}')} | "
                     f"{_f(r.get('peak_rss_mb'), '{:,.0f}')} | {_f(r.get('rows_written'), '{:,}')} | "
                     f"{_f((r.get('dataset_bytes') or 0) / 2**20, '{:,.0f}')} | {_f((r.get('load_average_after') or [None])[0], '{:.1f}')} |")
    return "\n".join(lines)


def flap_torque_table(doc) -> str:
    drive = doc.get("drive") or {}
    drive_s = (f"crank {drive.get('alpha_start_deg')} → {drive.get('alpha_end_deg')} deg at {drive.get('alpha_dot_rad_s')} rad/s, "
               if drive else "")
    lines = ["### flap_msd driving torque: jaxmech against Exudyn (`benchmarks/flap_torque.py`)", "", _machine(doc), "",
             f"{drive_s}{_f(doc.get('n_positions'), '{:,} stroke positions; ') if doc.get('n_positions') else ''}reference: {doc.get('reference', '?')}. "
             "Rel err is taken over the converged samples; converged = fraction of positions whose solve converged.", ""]
    rows = doc.get("rows") or []
    if rows:
        lines += ["| jaxmech configuration | k (max steps) | run (ms) | compile (s) | rel err | converged |", "|---|---:|---:|---:|---:|---:|"]
        for r in rows:
            lines.append(f"| {r.get('method')} | {_f(r.get('budget'), '{}')} | {_ms(r.get('run_s'))} | {_f(r.get('compile_s'), '{:.2f}')} | "
                         f"{_f(r.get('rel_err'), '{:.1e}')} | {_f(r.get('success_rate'), '{:.3f}')} |")
        lines.append("")
    erows = doc.get("exudyn_rows") or []
    if erows:
        lines += [f"Exudyn {doc.get('exudyn_version', '')} (generalized-alpha, index 3; run = `SolveDynamic` only):", "",
                  "| Exudyn run | steps | step (ms) | run (ms) | build + assemble (ms) | rel err |", "|---|---:|---:|---:|---:|---:|"]
        for r in erows:
            if "failed" in r:
                lines.append(f"| {r.get('method')} | {_f(r.get('steps'), '{:,}')} | failed: {r['failed']} | | | |")
                continue
            lines.append(f"| {r.get('method')} | {_f(r.get('steps'), '{:,}')} | {_ms(r.get('step_size_s'), '{:.3f}')} | {_ms(r.get('run_s'))} | "
                         f"{_ms(r.get('build_and_assemble_s'), '{:.1f}')} | {_f(r.get('rel_err'), '{:.1e}')} |")
        lines.append("")
    elif not rows and doc.get("summary_table"):  # only the plain-text table survived
        lines += ["```", *doc["summary_table"], "```", ""]
    acc = doc.get("acceptance") or {}
    if acc:
        passed = {True: "**PASS**", False: "**FAIL**"}.get(acc.get("passed"), "not decided")
        lines.append(f"Acceptance ({acc.get('criterion', '?')}): {passed}.")
        if acc.get("verdict"):
            lines.append(f"{acc['verdict']}.")
        inc = acc.get("jaxmech_fastest_at_target_incl_compile")
        if inc:
            lines.append(f"Fastest jaxmech configuration counting its compile: {inc.get('method')} ({_ms(inc.get('run_s'))} ms run + "
                         f"{_f(inc.get('compile_s'), '{:.1f}')} s compile).")
    notes = doc.get("notes") or {}
    if notes:
        lines += ["", "Notes: " + "; ".join(f"{k}: {v}" for k, v in notes.items())]
    return "\n".join(lines).rstrip()


def gpu_table(doc) -> str:
    m = doc.get("machine") or {}
    acc = (m.get("accelerator") or (doc.get("notes") or {}).get("accelerator") or [None, None])
    lines = ["### Large sweeps on an accelerator (`benchmarks/gpu.py`)", "",
             f"_{acc[1] or 'no accelerator'} beside a {m.get('cpu_count')}-core {m.get('cpu_model', '?')} host; jax "
             f"{(m.get('versions') or {}).get('jax')}, {m.get('git')}, {m.get('date')}_", "",
             f"`stroke_kinematics`, designs x {doc.get('positions', '?')} crank positions; errors on the first "
             f"{doc.get('error_designs', '?')} designs:", "",
             "| mechanism | platform | dtype | designs | compile (s) | run (s) | poses / s | position error | against | converged |",
             "|---|---|---|---:|---:|---:|---:|---:|---|---:|"]
    for r in doc.get("rows") or []:
        if "poses_per_s" not in r:
            continue
        key = next((k for k in ("err_vs_f64", "err_vs_closed_form", "f64_loop_residual") if k in r), None)
        e = r.get(key) or {}
        err = e["pos_m"] if "pos_m" in e else (e.get("pos") or {}).get("abs")  # loop residual (m) or angle error (rad)
        lines.append(f"| {r['mech']} | {r['platform']} | {r['dtype']} | {_f(r.get('designs'), '{:,}')} | {_f(r.get('compile_s'), '{:.2f}')} | "
                     f"{_f(r.get('run_s'), '{:.3f}')} | {_f(r.get('poses_per_s'), '{:.3g}')} | {_f(err, '{:.1e}')} | {key or '-'} | "
                     f"{_f(r.get('converged_fraction'), '{:.3f}')} |")
    for q in doc.get("ratios") or []:
        lines.append(f"\n{q['mech']} {q['dtype']}: accelerator / CPU poses per second {_f(q.get('accelerator_over_cpu'), '{:.0f}x')}.")
    return "\n".join(lines).rstrip()


TABLES = {"kinematics": kinematics_table, "speed_error": speed_error_table, "scaling": scaling_table,
          "dynamics": dynamics_table, "design": design_table, "sweep_scale": sweep_scale_table, "flap_torque": flap_torque_table,
          "gpu": gpu_table}


def render(results: Path = RESULTS) -> str:
    parts = ["## Benchmarks", ""]
    for name, fn in TABLES.items():
        doc = _load(results, name)
        if not doc:
            parts.append(f"### {name}\n\n_not run yet: `python -m benchmarks.{name}`_")
        else:
            try:
                parts.append(fn(doc))
            except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:  # a partial or older JSON
                parts.append(f"### {name}\n\n_results/{name}.json could not be rendered ({type(e).__name__}: {e}); "
                             f"re-run `python -m benchmarks.{name}`_")
        parts.append("")
    return "\n".join(parts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--output", type=Path, default=None, help="write the Markdown here (default: print)")
    args = ap.parse_args(argv)
    md = render(args.results)
    if args.output:
        args.output.write_text(md)
    else:
        print(md)


if __name__ == "__main__":
    main()
