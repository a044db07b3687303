"""The command line's edges: a Ctrl-C during a sweep (one line, exit 130, the dataset
resumes to the uninterrupted one), destinations that cannot be written refused before
anything is computed (``/proc``, ``/sys``, missing folders; no folder made above the one
named), ``--plots``, a progress bar that ends with the work, ``--figure`` from the current
folder, the default random ranges (the drawing's geometry), every linkage file error naming
the file, and "did you mean" for every misspelt name."""

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
from PIL import Image  # noqa: E402

import jaxmech as jm  # noqa: E402
import jaxmech.sweep  # noqa: E402
from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.cli.values import figure_functions  # noqa: E402
from jaxmech.export.pose import export_pose  # noqa: E402
from jaxmech.scenes import get_scene  # noqa: E402
from jaxmech.scenes.classic import FOURBAR  # noqa: E402
from jaxmech.sweep.dataset import DatasetWriter  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WATT = ROOT / "examples" / "linkages" / "watt_sixbar.toml"
NUMPY_REPR = ("np.", "array(", "float64(", "dtype(")


def one_line(err: str, *matches: str) -> str:
    """The single stderr line of a user error: no traceback, no numpy repr, every match in it."""
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxmech: ") and all(m in lines[0] for m in matches), (lines[0], matches)
    assert not any(r in lines[0] for r in NUMPY_REPR), lines[0]
    return lines[0]


def _read(path):
    """A dataset's columns sorted by design and point (pyarrow, no jaxmech)."""
    t = pq.read_table(path).sort_by([("design", "ascending"), ("point", "ascending")])
    return {k: t.column(k).to_numpy(zero_copy_only=False) for k in t.column_names}


# ----------------------------------------------------------------------- Ctrl-C
#: ``python -m jaxmech ARGS`` with SIGINT's handler set first: a shell starts a background
#: job (a CI script run with ``&``) with SIGINT ignored and its children inherit that, so a
#: Ctrl-C sent to the command under test, or ``_thread.interrupt_main``, would not reach it.
CTRL_C_REACHES = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
                  "sys.argv[0] = 'jaxmech'; runpy.run_module('jaxmech', run_name='__main__', alter_sys=True)")


def test_ctrl_c_during_a_sweep_is_one_line_and_the_rerun_resumes(tmp_path, capsys):
    """SIGINT once the first chunk is in the folder (chunks of 1000 designs x 101 points:
    a row group each, staged as soon as it is computed): one line on stderr naming the
    sweep and the resume, exit 130; the same command again completes the dataset, equal
    row for row to an uninterrupted run's."""
    sweep = ["sweep", "fourbar", "--random", "6000", "--seed", "3", "--chunk-size", "1000"]
    assert main([*sweep, "--out", str(tmp_path / "whole.parquet")]) == 0  # also compiles the kernel for the others
    capsys.readouterr()
    out = tmp_path / "cut.parquet"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # "-m jaxmech.cli" with SIGINT's default handler first (see CTRL_C_REACHES)
    proc = subprocess.Popen([sys.executable, "-c", CTRL_C_REACHES, *sweep, "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline and not any(out.glob(".stage-*")):
        time.sleep(0.005)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, (proc.returncode, stdout, stderr)
    line = one_line(stderr, "interrupted: sweep fourbar", str(out), "rerun the same command to resume the dataset")
    assert "error" not in line
    kept = {p.name for p in out.iterdir()}
    assert ".stage-000000.rows" in kept and not any(n.startswith("part-") for n in kept)  # interrupted mid-sweep
    assert main([*sweep, "--out", str(out)]) == 0
    assert "chunks already there" in capsys.readouterr().out
    got, whole = _read(out), _read(tmp_path / "whole.parquet")
    assert len(got["design"]) == 6000 * 101
    assert list(got) == list(whole)
    for k in got:
        np.testing.assert_array_equal(got[k], whole[k], err_msg=k)


def test_ctrl_c_in_a_garbage_collector_callback_still_stops(monkeypatch, capsys):
    """A Ctrl-C that lands in a callback Python cannot raise from (a ``__del__``, JAX's gc
    callback) is printed as "Exception ignored" and lost: the command goes on.  It stops
    instead, in one line."""
    import jaxmech.cli.commands as cli

    class Dropped:
        def __del__(self):
            raise KeyboardInterrupt  # where a Ctrl-C may land

    def setup():
        Dropped()  # collected at once: its __del__ raises into the void
        for _ in range(2000):  # the command goes on (it is interrupted here, at once)
            time.sleep(0.001)

    monkeypatch.setattr(cli, "_setup_jax", setup)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # not ignored (see CTRL_C_REACHES)
    try:
        assert main(["scenes"]) == 130
    finally:
        signal.signal(signal.SIGINT, previous)
    out, err = capsys.readouterr()
    one_line(err, "jaxmech: interrupted: scenes")
    assert out == ""  # the scenes were not listed: it stopped


# ----------------------------------------------------------------------- destinations
LINUX = Path("/proc/self").is_dir() and Path("/sys/kernel").is_dir()
SYSTEM = [  # (command line, --out, what the one line says)
    (["run", "fourbar"], "/proc/jaxmech-test-out", "cannot be written"),
    (["run", "fourbar"], "/sys/jaxmech-test-out", "cannot be written"),
    (["report", "--scenes", "fourbar"], "/proc/jaxmech-missing/out", "the folder '/proc/jaxmech-missing' does not exist"),
    (["run", "fourbar"], "/sys/jaxmech-missing/out", "the folder '/sys/jaxmech-missing' does not exist"),
    (["sweep", "fourbar", "--grid", "a=1:2:2"], "/sys/kernel/jaxmech-test.csv", "cannot be written"),
    (["sweep", "fourbar", "--random", "3", "--figures"], "/proc/jaxmech-test.parquet", "cannot be written"),
    (["animate", "fourbar"], "/sys/jaxmech-test.gif", "cannot be written"),
    (["export", "fourbar"], "/proc/jaxmech-test.dxf", "cannot be written"),
    (["export", "fourbar"], "/nonexistent_jaxmech_dir/x.dxf", "the folder '/nonexistent_jaxmech_dir' does not exist"),
]


@pytest.fixture
def no_computing(monkeypatch):
    """``_setup_jax`` (the step before any computation) replaced by a trap."""
    import jaxmech.cli.commands as cli

    def trap():
        raise AssertionError("the destination was not checked before computing")

    monkeypatch.setattr(cli, "_setup_jax", trap)


@pytest.mark.skipif(not LINUX, reason="/proc and /sys are Linux's")
@pytest.mark.parametrize("args, out, says", SYSTEM)
def test_unwritable_system_destinations_are_refused_before_computing(args, out, says, no_computing, capsys):
    """Root may pass ``os.access`` for ``/proc`` and ``/sys``: the check writes (and removes)
    a probe, so these fail in one line before anything is computed (the trap)."""
    assert main([*args, "--out", out]) == 2
    one_line(capsys.readouterr().err, "jaxmech: error: --out", repr(out), says)
    assert not Path(out).exists() and not Path("/proc/jaxmech-missing").exists()


@pytest.mark.parametrize("args, out", [
    (["export", "fourbar"], "nonexistent_dir/x.dxf"),
    (["animate", "fourbar"], "nonexistent_dir/x.gif"),
    (["sweep", "fourbar", "--grid", "a=1:2:2"], "nonexistent_dir/x.csv"),
    (["run", "fourbar"], "nonexistent_dir/deeper/out"),
    (["sweep", "fourbar", "--random", "3", "--figures"], "nonexistent_dir/x.parquet/"),
])  # fmt: skip
def test_no_folder_is_made_above_the_one_named(args, out, tmp_path, no_computing, capsys):
    """A file's folder, and the folders above a named output folder, must exist: refused in
    one line naming the missing folder, and nothing made."""
    target = tmp_path / out
    assert main([*args, "--out", str(target)]) == 2
    one_line(capsys.readouterr().err, f"the folder {str(target.parent)!r} does not exist")
    assert list(tmp_path.iterdir()) == []


def test_export_library_makes_no_folder(tmp_path):
    with pytest.raises(ValueError, match="the folder .*nonexistent_dir' does not exist; create it first"):
        export_pose(FOURBAR, None, tmp_path / "nonexistent_dir" / "x.dxf")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------- --plots
def test_plots_none_writes_no_png_and_summary_two(tmp_path, capsys):
    """``--plots none``: the CSV only (into the named folder, made since its parent exists);
    ``summary``: the poses and the outputs; the CSVs equal."""
    assert main(["run", "fourbar", "--plots", "none", "--out", str(tmp_path / "none")]) == 0
    assert sorted(p.name for p in (tmp_path / "none").iterdir()) == ["fourbar.csv"]
    assert main(["run", "fourbar", "--plots", "summary", "--out", str(tmp_path / "summary")]) == 0
    names = sorted(p.name for p in (tmp_path / "summary").iterdir())
    assert names == ["fourbar.csv", "fourbar_outputs.png", "fourbar_poses.png"]
    for name in names[1:]:
        with Image.open(tmp_path / "summary" / name) as im:
            assert im.format == "PNG"
    assert (tmp_path / "none" / "fourbar.csv").read_bytes() == (tmp_path / "summary" / "fourbar.csv").read_bytes()
    assert "wrote" in capsys.readouterr().out


# ----------------------------------------------------------------------- progress
def test_progress_bar_ends_with_the_work(tmp_path, monkeypatch, capsys):
    """The bar counts a streamed sweep's last chunk once its files are written: short of the
    total when the writer closes, at the total when the sweep returns."""
    import tqdm

    events = []
    real_update, real_close = tqdm.tqdm.update, DatasetWriter.close

    def update(bar, n=1):
        events.append(("update", n))
        return real_update(bar, n)

    def close(writer):
        events.append(("close", 0))
        return real_close(writer)

    monkeypatch.setattr(tqdm.tqdm, "update", update)
    monkeypatch.setattr(DatasetWriter, "close", close)
    d = 64
    table = jaxmech.sweep.random_designs({"a": (0.9, 1.1)}, d, seed=0)
    jaxmech.sweep.sweep_dataset(FOURBAR, tmp_path / "p.parquet", table=table, points=41, chunk_size=16, progress=True)
    at_close = events.index(("close", 0))
    assert sum(n for _, n in events[:at_close]) == d - 16  # the last chunk is still being written
    assert sum(n for _, n in events) == d
    assert "64/64" in capsys.readouterr().err


# ----------------------------------------------------------------------- --figure
def test_figure_imports_from_the_current_folder(tmp_path, monkeypatch):
    """A module beside the user (not on the import path: the installed ``jaxmech`` script's
    path is its own folder) imports, and the import path is left as it was."""
    name = f"user_figures_{os.getpid()}"
    (tmp_path / f"{name}.py").write_text("def travel(columns, p):\n    return columns['x'].max() - columns['x'].min()\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path), ".")])
    before = list(sys.path)
    fn = figure_functions([f"travel[m]={name}:travel"])["travel[m]"]
    assert fn({"x": np.array([0.5, 2.0, -1.0])}, {}) == 3.0
    assert sys.path == before
    sys.modules.pop(name, None)


# ----------------------------------------------------------------------- default random ranges
class _Box(Exception):
    pass


@pytest.mark.parametrize("scene", ["arc_track_flap", str(WATT)])
@pytest.mark.parametrize("vary", [None, "all"])
def test_default_random_ranges_vary_the_geometry_only(scene, vary, tmp_path, monkeypatch):
    """``--random`` without ``--range``: lengths, angles and positions (m, rad) within +-10 %;
    masses, inertias, g and loads only with ``--vary all``."""
    def capture(box, count, seed=0):
        raise _Box(box)

    monkeypatch.setattr(jaxmech.sweep, "random_designs", capture)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(_Box) as got:
        main(["sweep", scene, "--random", "5", *(["--vary", vary] if vary else [])])
    box = got.value.args[0]
    defaults = jm.load_linkage(scene).params if scene.endswith(".toml") else dict(get_scene(scene).defaults)
    loads = {"g", "m_flap", "M12_i", "M12_f", "m_crank", "m_coupler", "m_rocker", "m_link5", "m_link6", "f"} & set(defaults)
    geometry = {"a1", "alpha0", "beta1", "len_O2_A", "len_A_B", "x_O4", "y_O6"} & set(defaults)
    assert len(loads) >= 3 and len(geometry) >= 3
    assert geometry <= set(box)
    assert (loads <= set(box)) if vary == "all" else not (loads & set(box))
    for k, (lo, hi) in box.items():
        assert sorted((lo, hi)) == sorted((0.9 * defaults[k], 1.1 * defaults[k])) and defaults[k] != 0


# ----------------------------------------------------------------------- file errors
FILES = {  # a linkage file's text -> what its one line says (after the file's name)
    "zero.toml": ('driver = "crank"\nground = "O2 O4"\n[points]\nO2 = [0, 0]\nA = [0, 0]\nB = [3, 2]\nO4 = [3.5, 0]\n'
                  '[links]\ncrank = "O2 A"\ncoupler = "A B"\nrocker = "O4 B"\n', "points 'O2' and 'A' of one link are both at (0, 0)"),
    "links.json": ('{"driver": "crank", "ground": "O2 O4", "points": {"O2": [0, 0], "A": [0, 1], "B": [3, 2], "O4": [3.5, 0]}, '
                   '"links": {"crank": "O2 A", "coupler": "A B", "crank": "O4 B"}}', "'crank' is given twice in links"),
    "top.json": ('{"points": {"O2": [0, 0]}, "links": {}, "points": {"O2": [0, 0]}}', "'points' is given twice;"),
    "table.toml": ('[points]\nO2 = [0, 0]\n[links]\nc = "O2 A"\n[points]\nA = [0, 1]\n', "table [points] is given twice (line 5)"),
    "inline.toml": ('sliders = { piston = { angle = 0, angle = 1 } }\n', "Duplicate inline table key 'angle'"),
    "stroke.toml": ('driver = "crank"\nground = "O2 O4"\n[points]\nO2 = [0, 0]\nA = [0, 1]\nB = [3, 2]\nO4 = [3.5, 0]\n'
                    '[links]\ncrank = "O2 A"\ncoupler = "A B"\nrocker = "O4 B"\n[stroke]\nfrom = "10deg"\n', "[stroke] needs both from and to"),
    "speed.toml": ('driver = "crank"\nground = "O2 O4"\n[points]\nO2 = [0, 0]\nA = [0, 1]\nB = [3, 2]\nO4 = [3.5, 0]\n'
                   '[links]\ncrank = "O2 A"\ncoupler = "A B"\nrocker = "O4 B"\n[stroke]\nspeed = "fast"\n', "'fast'"),
    "key.toml": ('driver = "crank"\nponts = 1\n', "unknown key(s) ['ponts']"),
}


@pytest.mark.parametrize("name", list(FILES))
def test_every_linkage_file_error_names_the_file(name, tmp_path, monkeypatch, capsys):
    text, says = FILES[name]
    (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    assert main(["run", name, "--plots", "none"]) == 2
    line = one_line(capsys.readouterr().err, says)
    assert line.startswith(f"jaxmech: error: {name}: "), line
    assert not (tmp_path / "jaxmech-out").exists()


# ----------------------------------------------------------------------- did you mean
FOURBAR_DRAWING = {"O2": (0, 0), "A": (0, 1), "B": (3, 2), "O4": (3.5, 0)}
FOURBAR_LINKS = {"crank": "O2 A", "coupler": "A B", "rocker": "O4 B"}
MISSPELT = {  # Linkage arguments changed -> the name suggested
    "driver": (dict(driver="crankk"), "driver 'crankk' is not a link, a slider or an actuator; did you mean 'crank'?"),
    "point of a link": (dict(links={**FOURBAR_LINKS, "coupler": "A BB"}), "names point 'BB', which is not in points; did you mean 'B'?"),
    "ground point": (dict(ground="O2 O44"), "names point 'O44', which is not in points; did you mean 'O4'?"),
    "link of a mass": (dict(mass={"rocer": 1.0}), "mass: 'rocer' is not a link; did you mean 'rocker'?"),
    "link of a moment": (dict(moments={"coupler_": 1.0}), "moments: 'coupler_' is not a link; did you mean 'coupler'?"),
    "link of a force": (dict(forces={"B": {"force": (0, 1), "on": "rockr"}}), "did you mean 'rocker'?"),
    "slot's body": (dict(slots={"B": {"on": "rocke", "angle": 0.0}}), "'rocke' is not a link or 'ground'; did you mean 'rocker'?"),
    "slot's through point": (dict(slots={"B": {"through": "O44"}}), "through= 'O44' is not in points; did you mean 'O4'?"),
    "slider's through point": (dict(links={**FOURBAR_LINKS, "rocker": "B"}, ground="O2", sliders={"rocker": {"through": "A2"}}),
                               "through= 'A2' is not in points; did you mean 'A'?"),
}


@pytest.mark.parametrize("case", list(MISSPELT))
def test_did_you_mean_for_every_misspelt_linkage_name(case):
    change, says = MISSPELT[case]
    args = {**dict(points=FOURBAR_DRAWING, links=FOURBAR_LINKS, ground="O2 O4", driver="crank"), **change}
    with pytest.raises(ValueError) as err:
        jm.Linkage(args.pop("points"), args.pop("links"), **args)
    assert says in str(err.value)


def test_did_you_mean_for_a_linkage_parameter():
    lk = jm.Linkage(FOURBAR_DRAWING, FOURBAR_LINKS, ground="O2 O4", driver="crank")
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['len_A_C'\]; did you mean 'len_A_B'\?"):
        lk.solve(np.array([0.0, 0.1]), p={"len_A_C": 3.0})


@pytest.mark.parametrize("text, says", [
    ('driver = "crank"\nponts = 1\n', "did you mean 'points'?"),
    ('[points]\nO2 = [0, 0]\n[links]\n[stroke]\nspeeed = 1\n', "unknown [stroke] key(s) ['speeed']; it takes from, to, speed, summary, law, cycles, period, samples; did you mean 'speed'?"),
])  # fmt: skip
def test_did_you_mean_for_file_keys(text, says, tmp_path):
    (tmp_path / "k.toml").write_text(text)
    with pytest.raises(ValueError) as err:
        jm.load_linkage(tmp_path / "k.toml")
    assert str(err.value).startswith("k.toml: ") and says in str(err.value)
