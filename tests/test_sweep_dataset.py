"""Sweeps streamed to Parquet: figures against closed forms and the traces they reduce,
failed designs kept as rows, a sweep killed by a real signal and resumed equals an
uninterrupted one, a Dask cluster writes the same dataset, other arguments are refused.

Every figures sweep here is the four-bar at 41 points in chunks of 16 designs: one
compiled kernel (and the command-line subprocesses load it from the persistent cache)."""

import jax

jax.config.update("jax_enable_x64", True)

import os  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
import pytest  # noqa: E402

from jaxmech import Status  # noqa: E402
from jaxmech.cli import main  # noqa: E402
from jaxmech.scenes.classic import FOURBAR  # noqa: E402
from jaxmech.sweep import Figures, grid, random_designs, sweep_dataset, sweep_scene  # noqa: E402

from helpers import fourbar_closed  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POINTS = 41
CHUNK = 16
CLOSED_TOL = 1e-10  # rad, solver vs closed form
# c = 1.0 cannot be assembled over part of the stroke (see test_sweep.GRID); a = -1 is rejected.
GRID = {"a": [0.9, 1.0, 1.1], "c": [1.0, 2.5, 3.0]}
# The random sweep of the kill test: about a third of the designs (c < ~2) fail somewhere.
RANGES = {"a": (0.9, 1.1), "c": (1.0, 3.0)}
N_RANDOM, SEED = 1200, 7


def final_rocker(cols, p):
    """A user figure: the rocker angle at the end of the stroke (rad).  Module-level, so
    the command line imports it (``--figure``) and every sweep here shares one kernel."""
    return cols["theta4[rad]"][-1]


FIGURES = Figures(functions={"final_theta4[rad]": final_rocker})


def _table_with_rejected():
    t = grid(GRID)
    return {k: np.append(v, -1.0 if k == "a" else 2.5) for k, v in t.items()}


def _read(path):
    """The dataset as numpy columns sorted by design (and point): pyarrow, no jaxmech."""
    t = pq.read_table(path)
    keys = [("design", "ascending")] + ([("point", "ascending")] if "point" in t.column_names else [])
    t = t.sort_by(keys)
    return {k: t.column(k).to_numpy(zero_copy_only=False) for k in t.column_names}


def _assert_same_dataset(x, y):
    assert list(x) == list(y)
    for k in x:
        np.testing.assert_array_equal(x[k], y[k], err_msg=k)  # NaN equals NaN here


@pytest.fixture(scope="module")
def figures_and_traces(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    table = _table_with_rejected()
    s_fig = sweep_dataset(FOURBAR, root / "f.parquet", table=table, figures=FIGURES, points=POINTS, chunk_size=CHUNK, progress=False)
    s_tr = sweep_dataset(FOURBAR, root / "t.parquet", table=table, points=POINTS, chunk_size=CHUNK, progress=False)
    return table, s_fig, _read(root / "f.parquet"), s_tr, _read(root / "t.parquet")


def test_figures_against_closed_form_and_failed_rows_kept(figures_and_traces):
    table, summary, f, _, tr = figures_and_traces
    d = len(table["a"])
    np.testing.assert_array_equal(f["design"], np.arange(d))  # one row per design, none dropped
    th2 = np.linspace(0.0, 2 * np.pi, POINTS)
    status = tr["status[-]"].reshape(d, POINTS)
    for i in range(d):
        p = {**FOURBAR.defaults, **{k: table[k][i] for k in table}}
        if p["a"] < 0:  # rejected before solving: a row with its reason
            assert f["status[-]"][i] == Status.NONFINITE and "length 'a'" in f["error"][i]
            assert np.isnan(f["theta4_max[rad]"][i])
            continue
        assert f["error"][i] is None
        bad = status[i] != Status.CONVERGED
        assert f["failed_points[-]"][i] == bad.sum()
        if bad.any():  # the first failing sample's status, figures NaN
            assert p["c"] == 1.0 and f["status[-]"][i] == status[i][np.argmax(bad)] == Status.INFEASIBLE
            assert np.isnan(f["theta4_travel[rad]"][i]) and np.isnan(f["final_theta4[rad]"][i])
            continue
        # Independent truth: the closed-form open assembly at the same samples.
        t3, t4 = (np.asarray(x) for x in fourbar_closed(th2, p["a"], p["b"], p["c"], p["d"]))
        mu = np.arccos(np.abs(np.cos(t4 - t3)))
        assert abs(f["theta4_max[rad]"][i] - t4.max()) < CLOSED_TOL
        assert abs(f["theta4_min[rad]"][i] - t4.min()) < CLOSED_TOL
        assert abs(f["theta4_travel[rad]"][i] - (t4.max() - t4.min())) < CLOSED_TOL
        assert abs(f["transmission_angle_min[rad]"][i] - mu.min()) < CLOSED_TOL
        assert abs(f["final_theta4[rad]"][i] - t4[-1]) < CLOSED_TOL
        # the positions: samples where the closed form reaches its extreme (ties at 0 and 2 pi)
        for at, truth, best in ((f["theta4_max_at[rad]"][i], t4, t4.max()), (f["theta4_min_at[rad]"][i], t4, t4.min()),
                                (f["transmission_angle_min_at[rad]"][i], mu, mu.min())):
            assert abs(truth[np.flatnonzero(th2 == at)[0]] - best) < CLOSED_TOL
    assert summary.counts == {"CONVERGED": 6, "INFEASIBLE": 3, "NONFINITE": 1} and summary.rows_written == d


def test_figures_are_the_reductions_of_the_traces(figures_and_traces):
    """Reduced inside the kernel == numpy reductions of the trace dataset (same samples)."""
    table, _, f, _, tr = figures_and_traces
    d = len(table["a"])
    ok = f["status[-]"] == Status.CONVERGED
    for col in ("theta3[rad]", "theta4_dot[rad/s]", "theta4_ddot[rad/s^2]", "transmission_angle[rad]"):
        v = tr[col].reshape(d, POINTS)[ok]
        base, unit = col[:-1].split("[")
        np.testing.assert_allclose(f[f"{base}_max[{unit}]"][ok], v.max(axis=1), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(f[f"{base}_min[{unit}]"][ok], v.min(axis=1), rtol=1e-12, atol=1e-12)


def test_trace_dataset_equals_the_sweep_in_memory(figures_and_traces):
    table, _, _, summary, tr = figures_and_traces
    mem = sweep_scene(FOURBAR, table=table, points=POINTS, chunk_size=CHUNK)
    d = len(table["a"])
    assert summary.rows_written == d * POINTS and summary.info["mode"] == "trace"
    np.testing.assert_array_equal(tr["point"], np.tile(np.arange(POINTS), d))
    for k, v in mem.columns.items():
        np.testing.assert_array_equal(tr[k], v.reshape(-1), err_msg=k)
    np.testing.assert_array_equal(tr["status[-]"], mem.status.reshape(-1))
    np.testing.assert_array_equal(tr["a"], np.repeat(table["a"], POINTS))
    assert all(e is None for e in tr["error"][: (d - 1) * POINTS]) and "length 'a'" in tr["error"][-1]


def _cli_args(out):
    ranges = [f"--range={k}={lo}:{hi}" for k, (lo, hi) in RANGES.items()]
    return ["sweep", "fourbar", "--random", str(N_RANDOM), "--seed", str(SEED), *ranges, "--figures",
            "--figure", "final_theta4[rad]=test_sweep_dataset:final_rocker",
            "--points", str(POINTS), "--chunk-size", str(CHUNK), "--out", str(out)]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "ref.parquet"
    table = random_designs(RANGES, N_RANDOM, seed=SEED)
    sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=POINTS, chunk_size=CHUNK, progress=False)
    return _read(out)


def test_killed_sweep_resumes_to_the_uninterrupted_dataset(uninterrupted, tmp_path, capsys):
    out = tmp_path / "killed.parquet"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    cmd = [sys.executable, "-m", "jaxmech.cli", *_cli_args(out)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    n_chunks = -(-N_RANDOM // CHUNK)
    deadline = time.monotonic() + 300
    parts = []
    while proc.poll() is None and time.monotonic() < deadline:
        parts = list(out.glob("part-*.parquet")) if out.exists() else []
        if parts:
            os.kill(proc.pid, signal.SIGKILL)  # a real kill, mid-sweep
            break
        time.sleep(0.002)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the sweep ended before it could be killed"
    written = len(list(out.glob("part-*.parquet")))
    assert 1 <= written < n_chunks
    # The same command again (in this process: it reuses the compiled kernel).
    assert main(_cli_args(out)) == 0
    again = capsys.readouterr().out
    assert f"{written} chunks already there" in again and f"{N_RANDOM} designs" in again
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary file left
    got = _read(out)
    np.testing.assert_array_equal(got["design"], np.arange(N_RANDOM))  # none lost, none twice
    _assert_same_dataset(got, uninterrupted)
    assert 0.1 < np.mean(got["status[-]"] != Status.CONVERGED) < 0.9  # failed designs are rows too


def test_dask_cluster_writes_the_same_dataset(uninterrupted, tmp_path):
    """Two Dask workers (threads of this process: processes=False, so they reuse the
    compiled kernel) write the chunks themselves; the dataset equals the local run's."""
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "dask.parquet"
    n = 20 * CHUNK  # the first designs of the same table: the same rows as the local run's
    table = {k: v[:n] for k, v in random_designs(RANGES, N_RANDOM, seed=SEED).items()}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        s = sweep_dataset(FOURBAR, out, table=table, figures=FIGURES, points=POINTS, chunk_size=CHUNK, client=client, progress=False)
    assert s.info["backend"] == "dask" and s.chunks_written == 20 and not s.lost
    _assert_same_dataset(_read(out), {k: v[:n] for k, v in uninterrupted.items()})


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
