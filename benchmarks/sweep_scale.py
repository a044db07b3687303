"""Sweeps at scale: four-bar designs x 101 positions streamed to Parquet in bounded memory,
and what reading the dataset back costs.

Each case runs in a fresh Python process (so its peak RSS, ``ru_maxrss``, is its own):

1. **figures**: ``sweep_dataset(figures=True)``, D random crank-rocker designs, one row
   per design (max, its position, min, its position, travel of 7 columns; status).  Then,
   in the same process (peak RSS is taken before), the reads: the row count and three
   columns (``design``, ``theta3_max``, ``status``) with pyarrow, and with pandas, polars
   and duckdb where installed (each timed three times: first and best).  The dataset's
   pages are in the OS page cache by then (it was just written): warm-cache reads.
   ``--small-files`` also rewrites the same rows as files of 1024 rows (the layout of
   jaxmech before ``jaxmech-sweep-dataset/2``: a file per chunk, default Parquet options)
   and times the same reads on them.
2. **trace**: ``sweep_dataset()`` (one row per design and position, every table column).
3. **in-memory baseline**: ``sweep_scene`` (every column gathered in host memory), at a
   size that fits, for the throughput ratio measured side by side.

Each child first compiles and runs a 1024-design warm-up (reported as ``first_call_s``),
then times the sweep itself (``run_s``); throughput is designs x positions / ``run_s``.
The load average is recorded before and after every case: the machine may be shared.

``--synthetic D`` replaces the figures sweep by the dataset writer alone: D designs of
figures rows (the warm-up's real values, perturbed by 1e-9 relative so no two are equal)
go through ``jaxmech.sweep.dataset.DatasetWriter`` in chunks of 1024, as a sweep's would:
the files, the writer's time and memory, and the reads of a dataset of that size without
the hours of solving (the solving's time is the figures case's, per design).

Run: ``python -m benchmarks.sweep_scale [--quick] [--figures D] [--trace D] [--baseline D]
[--small-files] [--synthetic D] [--name NAME]`` (defaults 1e7, 1e6, 1e5); ``--trace 0`` or
``--baseline 0`` skips that case; ``--probe D --probe-s S`` replaces the figures run by a
D-design figures sweep killed S seconds after its first row group (peak RSS with the whole
design table loaded, throughput over the window).  Writes ``results/<name>.json``
(default ``sweep_scale``).  The datasets go to a temporary folder, deleted afterwards.
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
READ_COLUMNS = ["design", "theta3_max", "status"]


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _timed(fn, repeat: int = 3) -> dict:
    times, value = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return {"first_s": times[0], "best_s": min(times), "value": value}


def read_times(path: Path) -> dict:
    """The row count and three columns, with every reader installed (warm page cache)."""
    import pyarrow.dataset as pads
    import pyarrow.parquet as pq

    glob = f"{path}/*.parquet"
    out = {"files": len(list(path.glob("*.parquet")))}
    out["pyarrow_count_rows"] = _timed(lambda: pads.dataset(str(path), format="parquet").count_rows())
    out["pyarrow_read_3_columns"] = _timed(lambda: pq.read_table(path, columns=READ_COLUMNS).num_rows)
    try:
        import pandas as pd

        out["pandas_read_3_columns"] = _timed(lambda: len(pd.read_parquet(path, columns=READ_COLUMNS)))
    except ImportError:
        pass
    try:
        import polars as pl

        out["polars_count_rows"] = _timed(lambda: pl.scan_parquet(glob).select(pl.len()).collect().item())
        out["polars_read_3_columns"] = _timed(lambda: pl.read_parquet(glob, columns=READ_COLUMNS).height)
    except ImportError:
        pass
    try:
        import duckdb

        out["duckdb_count_rows"] = _timed(lambda: duckdb.sql(f"SELECT count(*) FROM '{glob}'").fetchall()[0][0])
        out["duckdb_read_3_columns"] = _timed(lambda: duckdb.sql(f"SELECT {', '.join(READ_COLUMNS)} FROM '{glob}'").to_arrow_table().num_rows)
    except ImportError:
        pass
    return out


def small_files(src: Path, dst: Path, rows: int = CHUNK) -> None:
    """The same rows as files of `rows` rows named by their first design, default Parquet
    options: the layout (not the names) of jaxmech before jaxmech-sweep-dataset/2."""
    import pyarrow.parquet as pq

    dst.mkdir()
    for f in sorted(src.glob("part-*.parquet")):
        t = pq.read_table(f)
        for i in range(0, t.num_rows, rows):
            c = t.slice(i, rows)
            pq.write_table(c, dst / f"part-{c['design'][0].as_py():012d}.parquet")


def _layout(path: Path) -> dict:
    import pyarrow.parquet as pq

    md = [pq.read_metadata(f) for f in sorted(path.glob("part-*.parquet"))]
    groups = [m.row_group(i).num_rows for m in md for i in range(m.num_row_groups)]
    return {"files": len(md), "rows_per_file": [m.num_rows for m in md], "row_groups": len(groups),
            "row_group_rows_min": min(groups, default=0), "row_group_rows_max": max(groups, default=0),
            "dataset_bytes": sum(f.stat().st_size for f in path.glob("*"))}


def _child(mode: str, d: int, folder: str, small: bool) -> dict:
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
        sweep_dataset(FOURBAR, Path(folder) / "warm.parquet", table=warm, figures=mode != "trace", points=POINTS,
                      chunk_size=CHUNK, progress=False)
    first = time.perf_counter() - t0
    table = random_designs(d, seed=1)
    rss_before = _rss_mb()
    out = Path(folder) / "run.parquet"
    t0 = time.perf_counter()
    if mode == "memory":
        res = sweep_scene(FOURBAR, table=table, points=POINTS, chunk_size=CHUNK, progress=False)
        rows, converged = d * POINTS, float(np.mean(res.ok))
    elif mode == "synthetic":
        rows, converged = _synthetic(Path(folder) / "warm.parquet", out, table), float("nan")
    else:
        s = sweep_dataset(FOURBAR, out, table=table, figures=mode == "figures", points=POINTS, chunk_size=CHUNK, progress=False)
        rows, converged = s.rows_written, s.counts.get("CONVERGED", 0) / d
    run_s = time.perf_counter() - t0
    row = {
        "mode": mode, "designs": d, "positions": POINTS, "chunk_size": CHUNK, "first_call_s": first, "run_s": run_s,
        "designs_x_positions_per_s": d * POINTS / run_s, "rows_written": rows, "converged_fraction": converged,
        "peak_rss_mb_before_run": rss_before, "peak_rss_mb": _rss_mb(),
    }
    if mode != "memory":
        row.update(_layout(out))
    if mode in ("figures", "synthetic"):
        row["reads"] = read_times(out)
        if small:
            t0 = time.perf_counter()
            small_files(out, Path(folder) / "small.parquet")
            row["small_files_write_s"] = time.perf_counter() - t0
            row["reads_files_of_1024_rows"] = read_times(Path(folder) / "small.parquet")
    return row


def _synthetic(warm: Path, out: Path, table: dict) -> int:
    """Figures rows of `table`'s designs through the dataset writer, no solving (see the
    module docstring); returns the rows written."""
    import numpy as np

    from jaxmech.scenes.classic import FOURBAR
    from jaxmech.sweep.dataset import Dataset, DatasetState, DatasetWriter, read_dataset
    from jaxmech.sweep.kernel import ChunkData

    t = read_dataset(warm)
    params = list(table)
    base = {f.metadata[b"jaxmech.column"].decode(): t.column(f.name).to_numpy() for f in t.schema
            if f.name not in ("design", "status", "status_code", "error", *params)}
    status = t.column("status_code").to_numpy()
    ds = Dataset(path=str(out), figures=True, points=POINTS, scene=FOURBAR.name,
                 parameter_units=tuple((k, FOURBAR.parameters[k][0]) for k in params))
    writer = DatasetWriter(ds, DatasetState())
    rng = np.random.default_rng(0)
    d = len(table[params[0]])
    for s in range(0, d, CHUNK):
        n = min(CHUNK, d - s)
        noise = 1 + 1e-9 * rng.random(n)
        cols = {k: v[:n] * noise if v.dtype.kind == "f" else v[:n] for k, v in base.items()}
        writer.add(ChunkData(start=s, params={k: table[k][s:s + n] for k in params}, columns=cols, status=status[:n], errors={}))
    writer.close()
    return d


def run_case(mode: str, d: int, small: bool = False) -> dict:
    folder = tempfile.mkdtemp(prefix=f"sweep_scale_{mode}_")
    try:
        load0 = os.getloadavg()
        cmd = [sys.executable, "-m", "benchmarks.sweep_scale", "--child", mode, str(d), folder, str(int(small))]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode:
            raise RuntimeError(f"{mode} D={d} failed:\n{proc.stderr[-3000:]}")
        row = json.loads(proc.stdout.strip().splitlines()[-1])
        row["load_average_before"], row["load_average_after"] = list(load0), list(os.getloadavg())
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    extra = ""
    if "files" in row:
        extra = f", {row['files']} files ({row['row_groups']} row groups)"
    if "reads" in row:
        r = row["reads"]
        extra += f"; count rows {r['pyarrow_count_rows']['best_s']:.3f} s, 3 columns {r['pyarrow_read_3_columns']['best_s']:.2f} s"
    print(f"{mode:>9} D={d:>9}: {row['run_s']:8.1f} s, {row['designs_x_positions_per_s']:.3g} design-positions/s, "
          f"peak RSS {row['peak_rss_mb']:.0f} MiB, {row['rows_written']} rows{extra}, load {row['load_average_after'][0]:.2f}", flush=True)
    return row


def _vm_hwm_mb(pid: int) -> float:
    """Peak resident memory of a running process (Linux ``VmHWM``), MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _designs_written(out: Path) -> int:
    """Designs in the part files and staged row groups (their footers), 0 while none."""
    import pyarrow.parquet as pq

    n = 0
    for f in [*out.glob("part-*.parquet"), *out.glob(".stage-*.rows")]:
        try:
            n += int(pq.read_metadata(f).metadata[b"jaxmech.designs"])
        except (OSError, KeyError):  # removed by a merge meanwhile
            pass
    return n


def run_probe(d: int, seconds: float) -> dict:
    """A figures sweep of ``d`` designs run for ``seconds`` after its first row group, then
    killed (SIGKILL): its peak RSS with the whole design table loaded, and its throughput
    over the window from the designs written (a full run is resumable from there)."""
    folder = tempfile.mkdtemp(prefix="sweep_scale_probe_")
    out = Path(folder) / "run.parquet"
    try:
        load0 = os.getloadavg()
        proc = subprocess.Popen([sys.executable, "-m", "benchmarks.sweep_scale", "--child", "figures", str(d), folder, "0"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        while proc.poll() is None and not (out.exists() and _designs_written(out)):
            time.sleep(0.05)
        t1, n1 = time.perf_counter(), _designs_written(out)
        time.sleep(seconds)
        t2, n2 = time.perf_counter(), _designs_written(out)
        hwm = _vm_hwm_mb(proc.pid)
        proc.kill()
        proc.wait()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    row = {"mode": "figures_probe", "designs": d, "positions": POINTS, "chunk_size": CHUNK, "window_s": t2 - t1,
           "designs_in_window": n2 - n1, "designs_x_positions_per_s": (n2 - n1) * POINTS / (t2 - t1),
           "peak_rss_mb": hwm, "designs_done_when_killed": n2,
           "load_average_before": list(load0), "load_average_after": list(os.getloadavg())}
    print(f"   probe D={d:>9}: {row['designs_x_positions_per_s']:.3g} design-positions/s over {row['window_s']:.0f} s, "
          f"peak RSS {hwm:.0f} MiB, load {row['load_average_after'][0]:.2f}", flush=True)
    return row


def main(argv=None):
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(_child(sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5] == "1")))
        return
    ap = base_parser("Sweeps of millions of designs streamed to Parquet: throughput, peak RSS, files and reads.")
    ap.add_argument("--figures", type=int, default=10**7, metavar="D", help="designs of the figures sweep (default 1e7)")
    ap.add_argument("--trace", type=int, default=10**6, metavar="D", help="designs of the trace sweep (default 1e6; 0 skips it)")
    ap.add_argument("--baseline", type=int, default=10**5, metavar="D",
                    help="designs of the in-memory sweep_scene baseline (default 1e5; 0 skips it)")
    ap.add_argument("--small-files", action="store_true", help="also time the reads of the same rows as files of 1024 rows")
    ap.add_argument("--synthetic", type=int, default=0, metavar="D",
                    help="instead of the figures sweep: D designs of figures rows through the dataset writer alone")
    ap.add_argument("--name", default="sweep_scale", help="results/NAME.json")
    ap.add_argument("--probe", type=int, default=0, metavar="D", help="instead of the full figures run: D designs for --probe-s seconds, then killed")
    ap.add_argument("--probe-s", type=float, default=60.0, metavar="S", help="seconds the probe runs (default 60)")
    args = ap.parse_args(argv)
    if args.quick:
        args.figures, args.trace, args.baseline = 10**4, 10**4, 10**4
    t0 = time.perf_counter()
    rows = [run_case("memory", args.baseline)] if args.baseline else []
    if args.probe:
        rows.append(run_probe(args.probe, args.probe_s))
    elif args.synthetic:
        rows.append(run_case("synthetic", args.synthetic, args.small_files))
    elif args.figures:
        rows.append(run_case("figures", args.figures, args.small_files))
    if args.trace:
        rows.append(run_case("trace", args.trace))
    base = rows[0]["designs_x_positions_per_s"] if args.baseline else None
    payload = {
        "points": POINTS, "rows": rows,
        "throughput_ratio_vs_in_memory": {r["mode"]: r["designs_x_positions_per_s"] / base for r in rows[1:]} if base else {},
        "total_s": time.perf_counter() - t0,
    }
    path = write_result(args.name, payload, out_dir=args.out)
    print(f"wrote {path} in {payload['total_s']:.0f} s")


if __name__ == "__main__":
    main()
