"""Sweeps at scale: four-bar designs x 101 positions streamed to Parquet in bounded memory.

Each case runs in a fresh Python process (so its peak RSS, ``ru_maxrss``, is its own):

1. **figures**: ``sweep_dataset(figures=True)``, D random crank-rocker designs, one row
   per design (max, its position, min, its position, travel of 7 columns; status).
2. **trace**: ``sweep_dataset()`` (one row per design and position, every table column).
3. **in-memory baseline**: ``sweep_scene`` (today's path: every column gathered in host
   memory), at a size that fits, for the throughput ratio measured side by side.

Each child first compiles and runs a 1024-design warm-up (reported as ``first_call_s``),
then times the sweep itself (``run_s``); throughput is designs x positions / ``run_s``.
The load average is recorded before and after every case: the machine may be shared.

Run: ``python -m benchmarks.sweep_scale [--quick] [--figures D] [--trace D] [--baseline D]``
(defaults 1e7, 1e6, 1e5: about 40 minutes on 2 idle cores); ``--probe D --probe-s S``
replaces the full figures run by a D-design figures sweep killed S seconds after its first
chunk (peak RSS with the whole design table loaded, throughput over the window); ``--trace
0`` skips the trace case.  Writes ``results/<name>.json`` (``--name``, default
``sweep_scale``).  The datasets go to a temporary folder, deleted afterwards.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import base_parser, write_result

POINTS = 101
CHUNK = 1024  # the CPU default: the in-memory baseline plans the same chunk


def _child(mode: str, d: int, folder: str) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from benchmarks.fourbar_reference import random_designs
    from jaxmech.scenes.classic import FOURBAR
    from jaxmech.sweep import sweep_dataset, sweep_scene

    t0 = time.perf_counter()
    warm = random_designs(CHUNK, seed=99)
    if mode == "memory":
        sweep_scene(FOURBAR, table=warm, points=POINTS, chunk_size=CHUNK, progress=False)
    else:
        sweep_dataset(FOURBAR, Path(folder) / "warm.parquet", table=warm, figures=mode == "figures", points=POINTS,
                      chunk_size=CHUNK, progress=False)
    first = time.perf_counter() - t0
    table = random_designs(d, seed=1)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    if mode == "memory":
        res = sweep_scene(FOURBAR, table=table, points=POINTS, chunk_size=CHUNK, progress=False)
        rows, converged = d * POINTS, float(np.mean(res.ok))
    else:
        s = sweep_dataset(FOURBAR, Path(folder) / "run.parquet", table=table, figures=mode == "figures", points=POINTS,
                          chunk_size=CHUNK, progress=False)
        rows, converged = s.rows_written, s.counts.get("CONVERGED", 0) / d
    run_s = time.perf_counter() - t0
    disk = sum(f.stat().st_size for f in (Path(folder) / "run.parquet").glob("*")) if mode != "memory" else 0
    return {
        "mode": mode, "designs": d, "positions": POINTS, "chunk_size": CHUNK, "first_call_s": first, "run_s": run_s,
        "designs_x_positions_per_s": d * POINTS / run_s, "rows_written": rows, "converged_fraction": converged,
        "dataset_bytes": disk, "peak_rss_mb_before_run": rss_before,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def run_case(mode: str, d: int) -> dict:
    folder = tempfile.mkdtemp(prefix=f"sweep_scale_{mode}_")
    try:
        load0 = os.getloadavg()
        cmd = [sys.executable, "-m", "benchmarks.sweep_scale", "--child", mode, str(d), folder]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        row = json.loads(out.strip().splitlines()[-1])
        row["load_average_before"], row["load_average_after"] = list(load0), list(os.getloadavg())
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    print(f"{mode:>8} D={d:>9}: {row['run_s']:8.1f} s, {row['designs_x_positions_per_s']:.3g} design-positions/s, "
          f"peak RSS {row['peak_rss_mb']:.0f} MiB, {row['rows_written']} rows, load {row['load_average_after'][0]:.2f}", flush=True)
    return row


def _vm_hwm_mb(pid: int) -> float:
    """Peak resident memory of a running process (Linux ``VmHWM``), MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def run_probe(d: int, seconds: float) -> dict:
    """A figures sweep of ``d`` designs run for ``seconds`` after its first chunk file, then
    killed (SIGKILL): its peak RSS with the whole design table loaded, and its throughput
    over the window from the chunk files written (a full run is resumable from there)."""
    folder = tempfile.mkdtemp(prefix="sweep_scale_probe_")
    out = Path(folder) / "run.parquet"
    try:
        load0 = os.getloadavg()
        proc = subprocess.Popen([sys.executable, "-m", "benchmarks.sweep_scale", "--child", "figures", str(d), folder],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        while proc.poll() is None and not (out.exists() and any(out.glob("part-*.parquet"))):
            time.sleep(0.05)
        t1, n1 = time.perf_counter(), len(list(out.glob("part-*.parquet")))
        time.sleep(seconds)
        t2, n2 = time.perf_counter(), len(list(out.glob("part-*.parquet")))
        hwm = _vm_hwm_mb(proc.pid)
        proc.kill()
        proc.wait()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    row = {"mode": "figures_probe", "designs": d, "positions": POINTS, "chunk_size": CHUNK, "window_s": t2 - t1,
           "chunks_in_window": n2 - n1, "designs_x_positions_per_s": (n2 - n1) * CHUNK * POINTS / (t2 - t1),
           "peak_rss_mb": hwm, "designs_done_when_killed": n2 * CHUNK,
           "load_average_before": list(load0), "load_average_after": list(os.getloadavg())}
    print(f"   probe D={d:>9}: {row['designs_x_positions_per_s']:.3g} design-positions/s over {row['window_s']:.0f} s, "
          f"peak RSS {hwm:.0f} MiB, load {row['load_average_after'][0]:.2f}", flush=True)
    return row


def main(argv=None):
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(_child(sys.argv[2], int(sys.argv[3]), sys.argv[4])))
        return
    ap = base_parser("Sweeps of millions of designs streamed to Parquet: throughput and peak RSS.")
    ap.add_argument("--figures", type=int, default=10**7, metavar="D", help="designs of the figures sweep (default 1e7)")
    ap.add_argument("--trace", type=int, default=10**6, metavar="D", help="designs of the trace sweep (default 1e6)")
    ap.add_argument("--baseline", type=int, default=10**5, metavar="D", help="designs of the in-memory sweep_scene baseline (default 1e5)")
    ap.add_argument("--name", default="sweep_scale", help="results/NAME.json")
    ap.add_argument("--probe", type=int, default=0, metavar="D", help="instead of the full figures run: D designs for --probe-s seconds, then killed")
    ap.add_argument("--probe-s", type=float, default=60.0, metavar="S", help="seconds the probe runs (default 60)")
    args = ap.parse_args(argv)
    if args.quick:
        args.figures, args.trace, args.baseline = 10**4, 10**4, 10**4
    t0 = time.perf_counter()
    rows = [run_case("memory", args.baseline)]
    rows.append(run_probe(args.probe, args.probe_s) if args.probe else run_case("figures", args.figures))
    if args.trace:
        rows.append(run_case("trace", args.trace))
    base = rows[0]["designs_x_positions_per_s"]
    payload = {
        "points": POINTS, "rows": rows,
        "throughput_ratio_vs_in_memory": {r["mode"]: r["designs_x_positions_per_s"] / base for r in rows[1:]},
        "total_s": time.perf_counter() - t0,
    }
    path = write_result(args.name, payload, out_dir=args.out)
    print(f"wrote {path} in {payload['total_s']:.0f} s")


if __name__ == "__main__":
    main()
