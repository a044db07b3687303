"""Sweeps streamed to Parquet: figures against closed forms and the traces they reduce,
failed designs kept as rows, files of whole row groups read by pyarrow, pandas, polars and
duckdb by plain names with their units in the metadata, a sweep killed by a real signal (or
a Ctrl-C, or a failed chunk) and resumed holds every design exactly once and equals an
uninterrupted one, the first layout read and converted, other arguments refused.

Every figures sweep here is the four-bar at 41 points in chunks of 16 designs: one
compiled kernel (and the subprocesses load it from the persistent cache).  Most use row
groups of 64 rows and files of 256 (``GROUP``, ``FILE``) so that 1200 designs make five
files."""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402
import os  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
import pytest  # noqa: E402

from jaxmech import Status, __version__  # noqa: E402
from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.scenes.classic import FOURBAR  # noqa: E402
from jaxmech.sweep import Figures, grid, random_designs, sweep_dataset, sweep_scene  # noqa: E402
from jaxmech.sweep import run as sweep_run  # noqa: E402
from jaxmech.sweep.dataset import Dataset, convert_dataset, read_dataset, split_unit  # noqa: E402
from jaxmech.sweep.kernel import ChunkData  # noqa: E402

from helpers import fourbar_closed  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POINTS = 41
CHUNK = 16
GROUP, FILE = 64, 256  # rows: 4 chunks a row group, 4 row groups a file
CLOSED_TOL = 1e-10  # rad, solver vs closed form
# c = 1.0 cannot be assembled over part of the stroke (see test_sweep.GRID); a = -1 is rejected.
# 15 + 1 designs: one chunk of 16, the kernel of every other figures sweep here.
GRID = {"a": [0.9, 1.0, 1.1], "c": [1.0, 2.3, 2.5, 2.7, 3.0]}
# The random sweep of the kill test: about a third of the designs (c < ~2) fail somewhere.
RANGES = {"a": (0.9, 1.1), "c": (1.0, 3.0)}
N_RANDOM, SEED = 1200, 7
STATUS_NAMES = [s.name for s in Status]


def final_rocker(cols, p):
    """A user figure: the rocker angle at the end of the stroke (rad).  Module-level, so
    the command line imports it (``--figure``) and every sweep here shares one kernel."""
    return cols["theta4[rad]"][-1]


FIGURES = Figures(functions={"final_theta4[rad]": final_rocker})


def _table_with_rejected():
    t = grid(GRID)
    return {k: np.append(v, -1.0 if k == "a" else 2.5) for k, v in t.items()}


def _random_table():
    return random_designs(RANGES, N_RANDOM, seed=SEED)


def _sweep_random(out, n=N_RANDOM, **kw):
    """The random figures sweep (its first `n` designs): the kill test's subprocess runs this."""
    table = {k: v[:n] for k, v in _random_table().items()}
    return sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=POINTS, chunk_size=CHUNK, progress=False,
                         **{"rows_per_group": GROUP, "rows_per_file": FILE, **kw})


def _read(path):
    """The dataset as numpy columns sorted by design (and point): pyarrow, no jaxmech."""
    t = pq.read_table(path)
    keys = [("design", "ascending")] + ([("point", "ascending")] if "point" in t.column_names else [])
    t = t.sort_by(keys)
    return {k: t.column(k).to_numpy(zero_copy_only=False) for k in t.column_names}


def _columns(t):
    return {k: t.column(k).to_numpy(zero_copy_only=False) for k in t.column_names}


def _assert_same_dataset(x, y):
    assert list(x) == list(y)
    for k in x:
        np.testing.assert_array_equal(x[k], y[k], err_msg=k)  # NaN equals NaN here


def _chunks_in_files(out):
    """{first design: designs} listed by the footers of the part files and staged row groups."""
    got = {}
    for f in [*sorted(out.glob("part-*.parquet")), *sorted(out.glob(".stage-*.rows"))]:
        chunks = json.loads(pq.read_metadata(f).metadata[b"jaxmech.chunks"])
        if f.suffix == ".rows" and all(s in got for s, _ in chunks):
            continue  # copied into a part file just before a kill: the rerun removes it
        for s, n in chunks:
            assert s not in got, f"chunk {s} in two files"
            got[s] = n
    return got


@pytest.fixture(scope="module")
def figures_and_traces(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    table = _table_with_rejected()
    s_fig = sweep_dataset(FOURBAR, root / "f.parquet", table=table, figures=FIGURES, points=POINTS, chunk_size=CHUNK, progress=False)
    s_tr = sweep_dataset(FOURBAR, root / "t.parquet", table=table, points=POINTS, chunk_size=CHUNK, progress=False)
    return table, s_fig, _read(root / "f.parquet"), s_tr, _read(root / "t.parquet"), root


def test_figures_against_closed_form_and_failed_rows_kept(figures_and_traces):
    table, summary, f, _, tr, _ = figures_and_traces
    d = len(table["a"])
    np.testing.assert_array_equal(f["design"], np.arange(d))  # one row per design, none dropped
    th2 = np.linspace(0.0, 2 * np.pi, POINTS)
    status = tr["status_code"].reshape(d, POINTS)
    np.testing.assert_array_equal(f["status"], [Status(c).name for c in f["status_code"]])  # the name, readable
    for i in range(d):
        p = {**FOURBAR.defaults, **{k: table[k][i] for k in table}}
        if p["a"] < 0:  # rejected before solving: a row with its reason
            assert f["status"][i] == "NONFINITE" and "length 'a'" in f["error"][i]
            assert np.isnan(f["theta4_max"][i])
            continue
        assert f["error"][i] is None
        bad = status[i] != Status.CONVERGED
        assert f["failed_points"][i] == bad.sum()
        if bad.any():  # the first failing sample's status, figures NaN
            assert p["c"] == 1.0 and f["status_code"][i] == status[i][np.argmax(bad)] == Status.INFEASIBLE
            assert f["status"][i] == "INFEASIBLE"
            assert np.isnan(f["theta4_travel"][i]) and np.isnan(f["final_theta4"][i])
            continue
        # Independent truth: the closed-form open assembly at the same samples.
        t3, t4 = (np.asarray(x) for x in fourbar_closed(th2, p["a"], p["b"], p["c"], p["d"]))
        mu = np.arccos(np.abs(np.cos(t4 - t3)))
        assert abs(f["theta4_max"][i] - t4.max()) < CLOSED_TOL
        assert abs(f["theta4_min"][i] - t4.min()) < CLOSED_TOL
        assert abs(f["theta4_travel"][i] - (t4.max() - t4.min())) < CLOSED_TOL
        assert abs(f["transmission_angle_min"][i] - mu.min()) < CLOSED_TOL
        assert abs(f["final_theta4"][i] - t4[-1]) < CLOSED_TOL
        # the positions: samples where the closed form reaches its extreme (ties at 0 and 2 pi)
        for at, truth, best in ((f["theta4_max_at"][i], t4, t4.max()), (f["theta4_min_at"][i], t4, t4.min()),
                                (f["transmission_angle_min_at"][i], mu, mu.min())):
            assert abs(truth[np.flatnonzero(th2 == at)[0]] - best) < CLOSED_TOL
    assert summary.counts == {"CONVERGED": 12, "INFEASIBLE": 3, "NONFINITE": 1} and summary.rows_written == d


def test_figures_are_the_reductions_of_the_traces(figures_and_traces):
    """Reduced inside the kernel == numpy reductions of the trace dataset (same samples)."""
    table, _, f, _, tr, _ = figures_and_traces
    d = len(table["a"])
    ok = f["status_code"] == Status.CONVERGED
    for col in ("theta3", "theta4_dot", "theta4_ddot", "transmission_angle"):
        v = tr[col].reshape(d, POINTS)[ok]
        np.testing.assert_allclose(f[f"{col}_max"][ok], v.max(axis=1), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(f[f"{col}_min"][ok], v.min(axis=1), rtol=1e-12, atol=1e-12)


def test_trace_dataset_equals_the_sweep_in_memory(figures_and_traces):
    table, _, _, summary, tr, root = figures_and_traces
    mem = sweep_scene(FOURBAR, table=table, points=POINTS, chunk_size=CHUNK)
    d = len(table["a"])
    assert summary.rows_written == d * POINTS and summary.info["mode"] == "trace"
    np.testing.assert_array_equal(tr["point"], np.tile(np.arange(POINTS), d))
    schema = pq.read_schema(root / "t.parquet" / "part-000000.parquet")
    for k, v in mem.columns.items():  # NAME[UNIT] in memory: NAME in the file, UNIT in its field
        name, unit = split_unit(k)
        np.testing.assert_array_equal(tr[name], v.reshape(-1), err_msg=k)
        assert schema.field(name).metadata[b"unit"].decode() == unit
    np.testing.assert_array_equal(tr["status_code"], mem.status.reshape(-1))
    np.testing.assert_array_equal(tr["a"], np.repeat(table["a"], POINTS))
    assert all(e is None for e in tr["error"][: (d - 1) * POINTS]) and "length 'a'" in tr["error"][-1]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "ref.parquet"
    s = _sweep_random(out)
    return _read(out), out, s


def test_files_of_whole_row_groups_each_design_once(uninterrupted):
    """1200 designs in chunks of 16, row groups of 4 chunks, files of 4 row groups: five
    files (4 x 256 rows + 176), every chunk listed once in the footers."""
    got, out, s = uninterrupted
    files = sorted(p.name for p in out.iterdir())
    assert files == ["_manifest.json"] + [f"part-{i:06d}.parquet" for i in range(5)] and s.info["files"] == 5
    md = [pq.read_metadata(out / f) for f in files[1:]]
    assert [m.num_rows for m in md] == [256] * 4 + [176]
    assert [[m.row_group(i).num_rows for i in range(m.num_row_groups)] for m in md] == [[64] * 4] * 4 + [[64, 64, 48]]
    assert _chunks_in_files(out) == {s: CHUNK for s in range(0, N_RANDOM, CHUNK)}
    np.testing.assert_array_equal(got["design"], np.arange(N_RANDOM))
    # a local run writes in design order: the files as they lie are already sorted
    np.testing.assert_array_equal(pq.read_table(out, columns=["design"]).column(0).to_numpy(), np.arange(N_RANDOM))


def test_read_by_plain_names_units_from_the_metadata(uninterrupted):
    """pyarrow, pandas and polars: ``df["theta3_max"]``, the status by name, the units from
    the Arrow field metadata and the schema metadata."""
    pd = pytest.importorskip("pandas")
    pl = pytest.importorskip("polars")
    ref, out, s = uninterrupted
    part = out / "part-000000.parquet"
    schema = pq.read_schema(part)
    units = {"a": "m", "d": "m", "theta3_max": "rad", "theta3_max_at": "rad", "theta4_dot_max": "rad/s",
             "theta4_ddot_travel": "rad/s^2", "transmission_angle_min": "rad", "final_theta4": "rad", "failed_points": "-"}
    for name, unit in units.items():
        assert schema.field(name).metadata[b"unit"].decode() == unit, name
    assert all(b"unit" not in (schema.field(n).metadata or {}) for n in ("design", "status", "status_code", "error"))
    meta = {k.decode(): v.decode() for k, v in schema.metadata.items()}
    assert meta["jaxmech.scene"] == "fourbar" and meta["jaxmech.version"] == __version__ and meta["jaxmech.mode"] == "figures"
    assert json.loads(meta["jaxmech.parameter_units"]) == {"a": "m", "b": "m", "c": "m", "d": "m"}
    assert {k: json.loads(meta["jaxmech.units"])[k] for k in units} == units
    assert not any("[" in n for n in schema.names)

    df = pd.read_parquet(out).sort_values("design")
    np.testing.assert_array_equal(df["theta3_max"].to_numpy(), ref["theta3_max"])
    np.testing.assert_array_equal(df["design"].to_numpy(), np.arange(N_RANDOM))
    assert list(df["status"].cat.categories) == STATUS_NAMES  # a Categorical whose codes are the Status codes
    np.testing.assert_array_equal(df["status"].cat.codes.to_numpy(), ref["status_code"])
    assert (df["status"] == "INFEASIBLE").sum() == s.counts["INFEASIBLE"] > 100

    lf = pl.read_parquet(f"{out}/*.parquet").sort("design")
    np.testing.assert_array_equal(lf["theta3_max"].to_numpy(), ref["theta3_max"])
    np.testing.assert_array_equal(lf["status"].cast(pl.String).to_numpy(), [STATUS_NAMES[c] for c in ref["status_code"]])
    assert json.loads(pl.read_parquet_metadata(part)["jaxmech.units"])["theta3_max"] == "rad"

    t = pq.read_table(out, columns=["design", "theta3_max"])
    assert t.num_rows == N_RANDOM and t.schema.field("theta3_max").metadata[b"unit"] == b"rad"
    assert sum(pq.read_metadata(f).num_rows for f in out.glob("*.parquet")) == N_RANDOM


def test_read_by_duckdb(uninterrupted):
    duckdb = pytest.importorskip("duckdb")  # benchmarks' extra, not the tests'
    ref, out, s = uninterrupted
    got = dict(duckdb.sql(f"SELECT status, count(*) FROM '{out}/*.parquet' GROUP BY status").fetchall())
    assert got == s.counts
    rows = duckdb.sql(f"SELECT design, theta3_max FROM '{out}/*.parquet' ORDER BY design").fetchall()
    np.testing.assert_array_equal(np.array(rows), np.column_stack([ref["design"], ref["theta3_max"]]))


def test_killed_sweep_resumes_to_the_uninterrupted_dataset(uninterrupted, tmp_path, capsys):
    """SIGKILL after the first file: the rerun (the command line, other row-group and file
    sizes) skips every chunk in a file or a staged row group, and ends with every design
    exactly once, equal to the uninterrupted run's dataset."""
    out = tmp_path / "killed.parquet"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    code = f"import test_sweep_dataset as t; t._sweep_random({str(out)!r})"
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        if out.exists() and any(out.glob("part-*.parquet")):
            os.kill(proc.pid, signal.SIGKILL)  # a real kill, mid-sweep
            break
        time.sleep(0.002)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the sweep ended before it could be killed"
    kept = _chunks_in_files(out)  # what the killed run finished and wrote
    parts = len(list(out.glob("part-*.parquet")))
    assert 16 <= len(kept) < N_RANDOM // CHUNK
    # The same sweep from the command line (in this process: it reuses the compiled kernel).
    ranges = [f"--range={k}={lo}:{hi}" for k, (lo, hi) in RANGES.items()]
    assert main(["sweep", "fourbar", "--random", str(N_RANDOM), "--seed", str(SEED), *ranges, "--figures",
                 "--figure", "final_theta4[rad]=test_sweep_dataset:final_rocker",
                 "--points", str(POINTS), "--chunk-size", str(CHUNK), "--out", str(out)]) == 0
    again = capsys.readouterr().out
    assert f"{len(kept)} chunks already there" in again and f"{N_RANDOM} designs" in again
    assert f"{N_RANDOM - CHUNK * len(kept)} rows written" in again  # nothing finished was run again
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary or staged file left
    assert len(list(out.glob("part-*.parquet"))) == parts + 1  # the rest in one file (10^5-row groups)
    got = _read(out)
    np.testing.assert_array_equal(got["design"], np.arange(N_RANDOM))  # none lost, none twice
    _assert_same_dataset(got, uninterrupted[0])
    assert 0.1 < np.mean(got["status_code"] != Status.CONVERGED) < 0.9  # failed designs are rows too


def test_interrupted_and_failed_chunks_are_resumed(uninterrupted, tmp_path, monkeypatch):
    """A Ctrl-C keeps every finished chunk (the row group in memory is staged first); a
    chunk whose run raises is a lost file of failed rows, retried by the next rerun."""
    out, n = tmp_path / "i.parquet", 10 * CHUNK
    real = sweep_run.run_chunk
    calls = []

    def flaky(fail_at, interrupt_at):
        def run_chunk(scene, job, start, params):
            calls.append(start)
            if len(calls) == interrupt_at:
                raise KeyboardInterrupt
            if len(calls) == fail_at:
                raise RuntimeError("worker lost")
            return real(scene, job, start, params)
        return run_chunk

    monkeypatch.setattr(sweep_run, "run_chunk", flaky(3, 7))  # chunk 32 fails, Ctrl-C at chunk 96
    with pytest.raises(KeyboardInterrupt):
        _sweep_random(out, n)
    assert calls == [0, 16, 32, 48, 64, 80, 96]
    assert _chunks_in_files(out) == {s: CHUNK for s in (0, 16, 48, 64, 80)}  # 80 was in memory: staged

    calls.clear()
    monkeypatch.setattr(sweep_run, "run_chunk", flaky(1, 0))  # chunk 32 fails again
    s = _sweep_random(out, n)
    assert calls == [32, 96, 112, 128, 144] and s.chunks_skipped == 5 and s.rows_written == 5 * CHUNK
    assert list(s.lost) == [32] and "RuntimeError: worker lost" in s.lost[32]
    assert s.info["lost_files"] == 1 and (out / "lost-000000000032.parquet").exists()
    got = _read(out)
    np.testing.assert_array_equal(got["design"], np.arange(n))  # every design once, the lost ones as failed rows
    lost = (got["design"] >= 32) & (got["design"] < 48)
    assert set(got["status"][lost]) == {"NONFINITE"} and np.isnan(got["theta4_max"][lost]).all()
    assert all("lost with its chunk (designs 32..47)" in e for e in got["error"][lost])

    calls.clear()
    monkeypatch.setattr(sweep_run, "run_chunk", real)
    s = _sweep_random(out, n)
    assert s.chunks_skipped == 9 and s.rows_written == CHUNK and not s.lost
    assert not (out / "lost-000000000032.parquet").exists()
    _assert_same_dataset(_read(out), {k: v[:n] for k, v in uninterrupted[0].items()})


def _write_first_layout(folder: Path, table, manifest: dict, lost=()):
    """A dataset as jaxmech wrote it before (``jaxmech-sweep-dataset/1``): a file per chunk
    named by its first design, ``NAME[UNIT]`` columns, ``status[-]`` codes."""
    folder.mkdir()
    (folder / "_manifest.json").write_text(json.dumps({**manifest, "format": "jaxmech-sweep-dataset/1"}))
    old = {f.name: (f.metadata or {}).get(b"jaxmech.column", f.name.encode()).decode() for f in table.schema}
    t = table.drop_columns(["status"]).rename_columns([old[n] for n in table.column_names if n != "status"])
    rows = manifest["chunk_size"] * (1 if manifest["mode"] == "figures" else manifest["points"])  # the table is in design order
    for i in range(0, t.num_rows, rows):
        c, s = t.slice(i, rows), int(t["design"][i].as_py())
        name = f"part-{s:012d}.parquet"
        if s in lost:
            cols = {k: (c[k] if k in ("design", "point", *manifest["parameters"]) else
                        pa.array(np.full(c.num_rows, 4 if k == "status[-]" else POINTS if k == "failed_points[-]" else np.nan),
                                 c.schema.field(k).type) if k != "error" else pa.array([f"lost with its chunk: {s}"] * c.num_rows))
                    for k in c.column_names}
            c, name = pa.table(cols), f"part-{s:012d}.lost.parquet"
        counts = json.dumps({Status(int(k)).name: int(v) for k, v in zip(*np.unique(c["status[-]"].to_numpy(), return_counts=True))})
        pq.write_table(c.replace_schema_metadata({"jaxmech.status_codes": "{}", "jaxmech.design_status": counts}), folder / name)


def test_first_layout_is_read_and_converted_then_resumed(uninterrupted, figures_and_traces, tmp_path):
    """A sweep of the first layout, unfinished (70 of 75 chunks, one of them lost): read as
    if written today; a rerun into it says how to convert it; converted, it resumes to the
    uninterrupted dataset."""
    ref, ref_out, _ = uninterrupted
    OLD = 70  # chunks written
    manifest = json.loads((ref_out / "_manifest.json").read_text())
    whole = read_dataset(ref_out)
    old = tmp_path / "old.parquet"
    _write_first_layout(old, whole.slice(0, OLD * CHUNK), manifest, lost={80})
    files = sorted(p.name for p in old.iterdir())
    assert files[:2] == ["_manifest.json", "part-000000000000.parquet"] and "part-000000000080.lost.parquet" in files
    assert "theta3_max[rad]" in pq.read_schema(old / files[1]).names

    got = read_dataset(old)
    assert got.schema.names == whole.schema.names and got.num_rows == OLD * CHUNK
    assert got.schema.field("theta3_max").metadata[b"unit"] == b"rad" and got.schema.field("a").metadata[b"unit"] == b"m"
    g, w = (_columns(t) for t in (got, whole.slice(0, OLD * CHUNK)))
    kept = (g["design"] < 80) | (g["design"] >= 96)  # the lost chunk's rows: failed, as it was written
    _assert_same_dataset({k: v[kept] for k, v in g.items()}, {k: v[kept] for k, v in w.items()})
    _assert_same_dataset({k: g[k][~kept] for k in ("design", "a", "b", "c", "d")}, {k: w[k][~kept] for k in ("design", "a", "b", "c", "d")})
    assert set(g["status"][~kept]) == {"NONFINITE"} and np.isnan(g["theta3_max"][~kept]).all()

    with pytest.raises(ValueError, match=r"first dataset layout .*convert_dataset\("):
        _sweep_random(old)
    new = convert_dataset(old, tmp_path / "new.parquet", rows_per_group=GROUP, rows_per_file=FILE)
    assert sorted(p.name for p in new.iterdir()) == ["_manifest.json", "lost-000000000080.parquet"] + [f"part-{i:06d}.parquet" for i in range(5)]
    assert [pq.read_metadata(new / f"part-{i:06d}.parquet").num_rows for i in range(5)] == [256] * 4 + [(OLD - 1) * CHUNK - 1024]
    s = _sweep_random(new)
    assert s.chunks_skipped == OLD - 1 and s.rows_written == N_RANDOM - (OLD - 1) * CHUNK and not (new / "lost-000000000080.parquet").exists()
    _assert_same_dataset(_read(new), ref)

    # trace mode: one row per design and sample
    _, _, _, _, tr, root = figures_and_traces
    trace = read_dataset(root / "t.parquet")
    tman = json.loads((root / "t.parquet" / "_manifest.json").read_text())
    _write_first_layout(tmp_path / "old_trace.parquet", trace, tman)
    assert "theta4_dot[rad/s]" in pq.read_schema(tmp_path / "old_trace.parquet" / "part-000000000000.parquet").names
    again = read_dataset(tmp_path / "old_trace.parquet")
    assert again.schema.equals(trace.schema, check_metadata=True)  # names, units, metadata: as written today
    _assert_same_dataset(_columns(again), _columns(trace))
    _assert_same_dataset(_columns(trace), tr)


def test_column_names_that_clash_without_units_are_refused():
    ds = Dataset(path="unused", figures=True, points=3, scene="x", parameter_units=(("a", "m"),))
    data = ChunkData(start=0, params={"a": np.ones(2)}, columns={"x[m]": np.ones(2), "x[mm]": np.ones(2),
                                                                   "failed_points[-]": np.zeros(2, np.int32)},
                     status=np.zeros(2, np.int32), errors={})
    with pytest.raises(ValueError, match=r"\['x'\] occur twice .*\['x\[m\]', 'x\[mm\]'\]"):
        ds.table(data)


def test_dask_cluster_writes_the_same_dataset(uninterrupted, tmp_path):
    """Two Dask workers (threads of this process: processes=False, so they reuse the
    compiled kernel) run the chunks; this process writes them; the dataset equals the
    local run's."""
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "dask.parquet"
    n = 20 * CHUNK  # the first designs of the same table: the same rows as the local run's
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        s = _sweep_random(out, n, client=client)
    assert s.info["backend"] == "dask" and s.chunks_written == 20 and not s.lost and s.info["files"] == 2
    assert _chunks_in_files(out) == {s: CHUNK for s in range(0, n, CHUNK)}
    _assert_same_dataset(_read(out), {k: v[:n] for k, v in uninterrupted[0].items()})


def test_rerun_with_other_arguments_is_refused(tmp_path, capsys):
    out = tmp_path / "s.parquet"
    table = _table_with_rejected()
    sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=POINTS, chunk_size=CHUNK, progress=False)
    with pytest.raises(ValueError, match=r"other arguments \(points: 41 there, 51 now\)"):
        sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=51, chunk_size=CHUNK)
    with pytest.raises(ValueError, match="other design values"):
        sweep_dataset(FOURBAR, out, table={**table, "c": table["c"] + 0.1}, figures=FIGURES, points=POINTS)
    with pytest.raises(ValueError, match="chunks of 16 designs"):
        sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=POINTS, chunk_size=8)
    with pytest.raises(ValueError, match="rows_per_file must be a positive integer"):
        sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=POINTS, rows_per_file=0)
    # The command line says it in one line (exit 2), as every user mistake.
    assert main(["sweep", "fourbar", "--grid", "a=1:2:3", "--figures", "--points", "51", "--out", str(out)]) == 2
    assert "other arguments" in capsys.readouterr().err


def test_unknown_figure_column_is_refused_before_compiling(figures_and_traces, tmp_path):
    with pytest.raises(ValueError, match=r"has no column\(s\) \['theta9\[rad\]'\]; its columns are: t\[s\]"):
        sweep_dataset(FOURBAR, tmp_path / "x.parquet", {"a": [1.0]}, figures=Figures(columns=["theta9[rad]"]), points=POINTS)


@pytest.mark.parametrize("args, match", [
    (["--grid", "a=1:2:3", "--random", "5"], "--grid or --random, not both"),
    (["--random", "5", "--figures", "--out", "x.csv"], "--figures writes a Parquet dataset"),
    (["--random", "5", "--range", "a=2:1"], "need finite LOW <= HIGH"),
    (["--grid", "a=1:2:3", "--range", "a=1:2"], "--range is for --random"),
    (["--random", "5", "--range", "zz=1:2", "--out", "x.parquet"], "has no parameter(s) ['zz']"),
    (["--random", "5", "--figures", "--figure", "f=no_such_module:f", "--out", "x.parquet"], "--figure f: cannot import"),
    (["--random", "5", "--figure", "f=math:cos", "--out", "x.parquet"], "give --figures too"),
])  # fmt: skip
def test_cli_sweep_mistakes_are_one_line(args, match, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "fourbar", *args]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1
