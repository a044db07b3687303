"""Design sweeps: agreement with run_scene and closed forms, failures kept, chunking,
export round trips, and the same sweep on a local Dask cluster."""

import jax

jax.config.update("jax_enable_x64", True)

import dataclasses  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech import Status  # noqa: E402
from jaxmech.scenes import run_scene  # noqa: E402
from jaxmech.scenes.classic import FOURBAR  # noqa: E402
from jaxmech.sweep import SweepResult, grid, random_designs, sweep_scene  # noqa: E402

from helpers import fourbar_closed, fourbar_feasible  # noqa: E402

POINTS = 41
TABLE_RTOL = 0.0  # sweep vs run_scene: one program (scenes.evaluation), bit for bit
PROGRAMS_RTOL = 1e-12  # two compiled programs (with and without the outputs traced in)
CLOSED_TOL = 1e-10  # rad, solver vs closed form
# a = 0.9..1.1 with b = 3, d = 3.5 needs c >= 0.5 + a to turn fully: c = 1.0 cannot be
# assembled over part of the stroke, c = 2.5 and 3.0 can.
GRID = {"a": [0.9, 1.0, 1.1], "c": [1.0, 2.5, 3.0]}


@pytest.fixture(scope="module")
def fourbar_grid():
    return sweep_scene(FOURBAR, GRID, points=POINTS)


def _assert_same(x, y, rtol=0.0):
    x, y = np.asarray(x, float), np.asarray(y, float)
    np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
    np.testing.assert_allclose(x[~np.isnan(x)], y[~np.isnan(y)], rtol=rtol, atol=rtol)


def test_grid_helper_is_full_factorial():
    g = grid({"a": [1, 2], "c": [3, 4, 5]})
    assert list(g["a"]) == [1, 1, 1, 2, 2, 2]
    assert list(g["c"]) == [3, 4, 5, 3, 4, 5]
    with pytest.raises(ValueError, match="axis 'a'"):
        grid({"a": []})


def test_random_designs_in_box_and_reproducible():
    r = random_designs({"a": (0.5, 1.5), "c": (1.0, 4.0)}, 200, seed=3, method="lhs", log=("c",))
    assert r["a"].shape == (200,) and np.all((r["a"] >= 0.5) & (r["a"] <= 1.5))
    assert np.all((r["c"] >= 1.0) & (r["c"] <= 4.0))
    # Latin hypercube: exactly one draw per stratum.
    assert sorted(np.floor((r["a"] - 0.5) * 200).astype(int)) == list(range(200))
    r2 = random_designs({"a": (0.5, 1.5), "c": (1.0, 4.0)}, 200, seed=3, method="lhs", log=("c",))
    np.testing.assert_array_equal(r["c"], r2["c"])


@pytest.mark.parametrize("name", ["flap_msd", "sma_flap"])
def test_one_design_sweep_is_run_scene_bit_for_bit(name):
    """A scene with outputs (torque, voltage; tensions): ``run_scene`` and a sweep of its
    one design give the same table, every column equal to the last bit (NaN where failed)."""
    from jaxmech.scenes import get_scene

    scene = get_scene(name)
    ref = run_scene(scene, points=POINTS).table()
    r = sweep_scene(scene, points=POINTS)
    got = r.table(0)
    assert list(got) == list(ref)
    for k in ref:
        np.testing.assert_array_equal(got[k], ref[k], err_msg=k)


def test_grid_matches_run_scene(fourbar_grid):
    r = fourbar_grid
    assert r.n_designs == 9 and r.n_points == POINTS
    np.testing.assert_array_equal(r.params["a"], grid(GRID)["a"])
    np.testing.assert_array_equal(r.params["d"], np.full(9, FOURBAR.defaults["d"]))
    compared = 0
    for i in range(r.n_designs):
        if not r.ok[i]:
            continue
        ref = run_scene(FOURBAR, points=POINTS, **r.design(i)).table()
        assert list(ref) == list(r.columns) + ["status[-]"]
        # the same columns in the same order (scenes.columns.table_columns), the same
        # numbers: run_scene runs the sweep's program (two copies of its design) and the
        # design's result does not depend on its chunk (9 designs here)
        for k in r.columns:
            _assert_same(r.columns[k][i], ref[k], TABLE_RTOL)
        np.testing.assert_array_equal(r.status[i], ref["status[-]"])
        compared += 1
    assert compared == 6


def test_unassemblable_designs_kept_with_infeasible_status(fourbar_grid):
    r = fourbar_grid
    th2 = r.columns["theta2[rad]"]
    for i in range(r.n_designs):
        p = r.design(i)
        feasible, f = fourbar_feasible(th2[i], p["a"], p["b"], p["c"], p["d"])
        margin = np.minimum(p["b"] + p["c"] - f, f - abs(p["b"] - p["c"]))
        clearly_out = margin < -1e-3
        assert np.all(r.status[i][clearly_out] != Status.CONVERGED)
        assert np.all(np.isnan(r.columns["theta3[rad]"][i][clearly_out]))
        if p["c"] == 1.0:
            assert np.any(clearly_out) and not r.ok[i]
            assert np.sum(r.status[i] == Status.INFEASIBLE) >= 0.5 * np.sum(clearly_out)
        else:
            assert r.ok[i]
            # Independent truth: the closed-form open assembly.
            t3, t4 = fourbar_closed(th2[i], p["a"], p["b"], p["c"], p["d"])
            d3 = np.angle(np.exp(1j * (r.columns["theta3[rad]"][i] - np.asarray(t3))))
            d4 = np.angle(np.exp(1j * (r.columns["theta4[rad]"][i] - np.asarray(t4))))
            assert np.max(np.abs(d3)) < CLOSED_TOL and np.max(np.abs(d4)) < CLOSED_TOL
    assert not r.errors


def test_memory_budget_chunking_is_identical(fourbar_grid):
    small = sweep_scene(FOURBAR, GRID, points=POINTS, memory_budget=1.0)
    assert small.info["chunk_size"] == jax.device_count() and small.info["n_chunks"] == 9
    assert fourbar_grid.info["n_chunks"] == 1
    assert fourbar_grid.info["bytes_per_design"] > 0
    for k in fourbar_grid.columns:
        _assert_same(small.columns[k], fourbar_grid.columns[k])
    np.testing.assert_array_equal(small.status, fourbar_grid.status)


def test_two_devices_shard_the_batch_with_identical_results(fourbar_grid, tmp_path):
    # A fresh process with two host "devices": the chunk is laid out over a 1-D mesh.
    script = (
        "import jax, sys; jax.config.update('jax_enable_x64', True)\n"
        "from jaxmech.sweep import sweep_scene\n"
        "from jaxmech.scenes.classic import FOURBAR\n"
        f"r = sweep_scene(FOURBAR, {GRID!r}, points={POINTS})\n"
        "assert jax.device_count() == 2 and r.info['devices'] == 2, r.info\n"
        "r.to_npz(sys.argv[1])\n"
    )
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env = {**os.environ, "XLA_FLAGS": flags.strip(), "JAX_PLATFORMS": "cpu"}
    out = tmp_path / "two.npz"
    subprocess.run([sys.executable, "-c", script, str(out)], env=env, check=True, timeout=600)
    two = SweepResult.from_npz(out)
    for k in fourbar_grid.columns:
        _assert_same(two.columns[k], fourbar_grid.columns[k], TABLE_RTOL)
    np.testing.assert_array_equal(two.status, fourbar_grid.status)


def test_csv_and_npz_round_trip(fourbar_grid, tmp_path):
    r = dataclasses.replace(fourbar_grid, errors={4: "an example message"})
    r.to_csv(tmp_path / "s.csv")
    header = (tmp_path / "s.csv").read_text().splitlines()[0].split(",")
    assert header[:6] == ["design", "point", "a", "b", "c", "d"] and header[-1] == "status[-]"
    back = SweepResult.from_csv(tmp_path / "s.csv", scene="fourbar")
    r.to_npz(tmp_path / "s.npz")
    back_npz = SweepResult.from_npz(tmp_path / "s.npz")
    assert back_npz.errors == {4: "an example message"} and back_npz.scene == "fourbar"
    for b in (back, back_npz):
        assert list(b.columns) == list(r.columns) and list(b.params) == list(r.params)
        for k in r.columns:
            _assert_same(b.columns[k], r.columns[k])
        for k in r.params:
            np.testing.assert_array_equal(b.params[k], r.params[k])
        np.testing.assert_array_equal(b.status, r.status)


def test_rejected_design_kept_and_names_checked():
    with pytest.raises(ValueError, match="no parameter"):
        sweep_scene(FOURBAR, {"zz": [1.0]})
    with pytest.raises(ValueError, match="differ in length"):
        sweep_scene(FOURBAR, table={"a": [1.0, 1.1], "c": [2.5]})
    r = sweep_scene(FOURBAR, table={"a": [1.0, -1.0, 1.1]}, points=POINTS, chunk_size=16)
    assert r.n_designs == 3 and r.params["a"][1] == -1.0
    assert "length 'a'" in r.errors[1] and list(r.errors) == [1]
    assert np.all(r.status[1] == Status.NONFINITE) and np.all(np.isnan(r.columns["theta3[rad]"][1]))
    assert r.ok[0] and r.ok[2]
    ref = run_scene(FOURBAR, points=POINTS, a=1.1).table()
    _assert_same(r.columns["theta4[rad]"][2], ref["theta4[rad]"], TABLE_RTOL)


def _python_outputs(p, mo):
    """Outputs written with Python floats: not vmappable, evaluated design by design."""
    if float(p["a"]) > 1.05:
        raise RuntimeError("this output model fails for a > 1.05")
    mu = np.arccos(np.abs(np.cos(np.asarray(mo.q[:, 1]) - np.asarray(mo.q[:, 0]))))
    return {"transmission_angle": (mu, "rad")}


def test_non_vmappable_outputs_and_a_failed_chunk(fourbar_grid):
    scene = dataclasses.replace(FOURBAR, outputs=_python_outputs)
    r = sweep_scene(scene, GRID, points=POINTS, chunk_size=3)
    assert r.info["outputs"] == "per design"
    # Designs 0-5 (a <= 1.0) run; the chunk with a = 1.1 raises and is lost, nothing else.
    for i in range(6):
        for k in fourbar_grid.columns:
            _assert_same(r.columns[k][i], fourbar_grid.columns[k][i], PROGRAMS_RTOL)
    assert sorted(r.errors) == [6, 7, 8] and "RuntimeError" in r.errors[6]
    assert np.all(r.status[6:] == Status.NONFINITE)
    assert "design 6" in r.summary()


def test_progress_line_on_stderr(capfd):
    sweep_scene(FOURBAR, {"a": [1.0, 1.05]}, points=POINTS, chunk_size=16, progress=True)
    err = capfd.readouterr().err
    assert "sweep fourbar" in err and "2 designs" in err


def test_dask_cluster_gives_identical_results(fourbar_grid):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0"
    ) as cluster, distributed.Client(cluster) as client:
        r = sweep_scene(FOURBAR, GRID, points=POINTS, client=client, chunk_size=5)
    assert r.info["backend"] == "dask" and r.info["n_chunks"] == 2
    assert not r.errors
    for k in fourbar_grid.columns:
        _assert_same(r.columns[k], fourbar_grid.columns[k], TABLE_RTOL)
    np.testing.assert_array_equal(r.status, fourbar_grid.status)


def test_sweep_columns_in_the_order_run_scene_writes_them(fourbar_grid, tmp_path):
    """One column order everywhere: the sweep's columns and CSV header follow run_scene's
    table (theta2_dot before theta2_ddot), not the sorted order of a compiled program."""
    from jaxmech.scenes import run_scene

    table = [k for k in run_scene(FOURBAR, POINTS).table() if k != "status[-]"]
    assert list(fourbar_grid.columns) == table
    fourbar_grid.to_csv(tmp_path / "s.csv")
    head = (tmp_path / "s.csv").read_text().splitlines()[0].split(",")
    assert head[2 + len(fourbar_grid.params):-1] == table
