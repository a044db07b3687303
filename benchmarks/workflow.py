"""The design workflow, cold, stage by stage: a drawing, a million-design sweep, a refinement
of the best 256, a tolerance study (``examples/design_workflow.py``, timed).

Stages (one fresh Python process, an empty compile store: every compile is paid here):

- ``drawing``: the README's Watt six-bar ``Linkage`` and its scene (crank at 2 pi rad/s);
- ``sweep``: ``--designs`` random designs of its ten geometric parameters +-10% to a Parquet
  dataset (``sweep_dataset``, figures mode: peak crank torque, least ``|sin mu|``), 37 points;
- ``refine``: the best ``--starts`` feasible designs (``|sin mu| >= 0.5``: ``mu`` within 30
  to 150 deg) refined in one ``jaxmech.design.refine`` call (least peak crank torque, the
  transmission limit at every sample, the +-10% box);
- ``tolerance``: the winner's first-order spread of peak torque (+-0.5 mm on every length)
  and the Monte Carlo check (2,000 samples).

Recorded per stage: wall time, the time JAX spent tracing, lowering and compiling in it
(``jax.monitoring`` duration events), and its counts (failed designs, starts converged to the
KKT tolerance); the load average before and after.  The script uses public names only.

Run: ``python -m benchmarks.workflow [--designs D] [--starts K] [--quick]``; writes
``results/workflow.json``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

from benchmarks.common import base_parser, write_result

COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
                  "/jax/core/compile/backend_compile_duration")


def child(designs: int, starts: int, out: str) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import math

    import numpy as np

    from examples import design_workflow as wf
    from jaxmech.sweep import read_dataset

    spent = {"compile": 0.0}

    def listen(event, duration, **_):
        if event in COMPILE_EVENTS:
            spent["compile"] += duration

    jax.monitoring.register_event_duration_secs_listener(listen)
    stages = {}

    def stage(name, fn):
        spent["compile"] = 0.0
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        value = fn()
        stages[name] = {"wall_s": time.perf_counter() - t0, "compile_s": spent["compile"], "load_before": load}
        print(f"{name}: {stages[name]['wall_s']:.1f} s (compiles {spent['compile']:.1f} s)", file=sys.stderr, flush=True)
        return value

    linkage, scene, bounds = stage("drawing", lambda: (lambda lk: (lk, lk.scene(speed=2 * math.pi), wf.box(lk)))(wf.watt()))
    stage("sweep", lambda: wf.sweep(scene, bounds, designs, out))
    table = read_dataset(out, columns=["status", wf.TORQUE, wf.QUALITY]).to_pandas()
    failed = int((table["status"] != "CONVERGED").sum())
    feasible = int(((table["status"] == "CONVERGED") & (table[wf.QUALITY] >= 0.5)).sum())
    stages["sweep"].update(designs=designs, failed_designs=failed, feasible_designs=feasible,
                           designs_per_s=designs / stages["sweep"]["wall_s"],
                           best_peak_torque=float(table[table[wf.QUALITY] >= 0.5][wf.TORQUE].min()))
    res = stage("refine", lambda: wf.refined(scene, bounds, out, starts))
    stages["refine"].update(starts=len(res.value), converged=res.converged, best_peak_torque=float(res.value[res.best]),
                            optima=[list(o) for o in res.optima[:5]], iterations_median=float(np.median(res.iterations)),
                            kkt_max_converged=float(np.max(res.kkt[res.status == 0])) if res.converged else None)
    first, mc = stage("tolerance", lambda: wf.tolerances(scene, res.best_params))
    stages["tolerance"].update(peak_torque=float(first.value[wf.TORQUE][0]), rss=float(first.rss[wf.TORQUE][0]),
                               monte_carlo_3sigma=3 * float(mc[wf.TORQUE]["std"][0]), monte_carlo_failed=int(mc[wf.TORQUE]["failed"][0]))
    return stages


def main(argv=None):
    ap = base_parser(__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=1_000_000)
    ap.add_argument("--starts", type=int, default=256)
    ap.add_argument("--child", action="store_true", help=argparse_hidden())
    ap.add_argument("--dataset", default=None, help=argparse_hidden())
    args = ap.parse_args(argv)
    if args.quick:
        args.designs, args.starts = 20_000, 32
    if args.child:
        print(json.dumps(child(args.designs, args.starts, args.dataset)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, JAXMECH_COMPILE_CACHE=os.path.join(tmp, "store"),
                   PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", "benchmarks.workflow", "--child", "--designs", str(args.designs), "--starts", str(args.starts),
               "--dataset", os.path.join(tmp, "dataset")]
        done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True, check=True)
        total = time.perf_counter() - t0
        load1 = os.getloadavg()
    stages = json.loads(done.stdout.strip().splitlines()[-1])
    payload = {"designs": args.designs, "starts": args.starts, "total_wall_s": total, "stages": stages,
               "load_before": load0, "load_after": load1,
               "command": f"python -m benchmarks.workflow --designs {args.designs} --starts {args.starts}"}
    for name, s in stages.items():
        print(f"{name:>10}: {s['wall_s']:8.1f} s  (compiles {s['compile_s']:.1f} s)")
    print(f"{'total':>10}: {total:8.1f} s (a new process, its start and imports included); load {load0[0]:.2f} -> {load1[0]:.2f}")
    path = write_result("workflow" if not args.quick else "workflow_quick", payload, out_dir=args.out)
    print(f"wrote {path}")


def argparse_hidden():
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    main()
