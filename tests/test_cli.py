"""The ``jaxmech`` command, run as a user runs it (``python -m jaxmech``), every verb and
the user's mistakes: one line on stderr, exit status 2, never a traceback."""

import jax

jax.config.update("jax_enable_x64", True)

import csv  # noqa: E402
import math  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.scenes import scene_names  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LINKAGES = ROOT / "tests" / "data" / "linkages"  # broken linkage files, one mistake each
FOURBAR_COLUMNS = [
    "t[s]", "theta2[rad]", "theta2_dot[rad/s]", "theta2_ddot[rad/s^2]",
    "theta3[rad]", "theta3_dot[rad/s]", "theta3_ddot[rad/s^2]",
    "theta4[rad]", "theta4_dot[rad/s]", "theta4_ddot[rad/s^2]",
    "transmission_angle[rad]", "status[-]",
]  # fmt: skip
N = 101  # the default --points: every run below shares one compiled kernel
POS_TOL = 1e-12  # rad


def jaxmech(*args, cwd=None, timeout=300):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "jaxmech", *map(str, args)],
        capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout,
    )  # fmt: skip


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def theta4_at_zero(a, b, c, d):
    """Open four-bar at theta2 = 0: triangle A(a, 0), O4(d, 0), B; law of cosines at O4."""
    f = d - a
    return math.pi - math.acos((c * c + f * f - b * b) / (2 * c * f))


# ----------------------------------------------------------------------- help and listing
def test_scenes_one_line_each():
    proc = jaxmech("scenes")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert [ln.split()[0] for ln in lines] == scene_names()
    assert "four-bar" in lines[0]


@pytest.mark.parametrize("verb", ["scenes", "run", "animate", "sweep", "report"])
def test_help_on_every_verb(verb, capsys):
    with pytest.raises(SystemExit) as exc:
        main([verb, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: jaxmech {verb}")


def test_top_level_help_as_a_command():
    proc = jaxmech("--help")
    assert proc.returncode == 0
    for verb in ("scenes", "run", "animate", "sweep", "report"):
        assert verb in proc.stdout


def test_scene_lists_its_parameters_with_units_and_defaults():
    """``jaxmech scenes SCENE``: one row per parameter (name, SI unit, default, meaning), the
    defaults equal to the scene's own and angles also shown in degrees."""
    from jaxmech.scenes import get_scene

    proc = jaxmech("scenes", "arc_track_flap")
    assert proc.returncode == 0, proc.stderr
    scene = get_scene("arc_track_flap")
    rows = {ln.split()[0]: ln.split() for ln in proc.stdout.splitlines()[5:]}
    assert list(rows) == list(scene.defaults)
    assert rows["a1"][1] == "m" and float(rows["a1"][2]) == pytest.approx(0.275, rel=1e-6)
    assert rows["alpha0"][1] == "rad" and rows["alpha0"][3:5] == ["(65", "deg)"]  # the thesis's 65 deg
    assert rows["M12_i"][1:4] == ["N", "m", "750"]
    assert proc.stdout.splitlines()[0].startswith("arc_track_flap: ") and "cruise" in proc.stdout.splitlines()[0]


def test_every_scene_describes_every_parameter():
    from jaxmech.scenes import get_scene

    for name in scene_names():
        scene = get_scene(name)
        assert list(scene.parameters) == list(scene.defaults), name
        assert all(unit and meaning for unit, meaning in scene.parameters.values()), name


def test_a_scene_must_describe_exactly_its_parameters():
    import dataclasses

    from jaxmech.scenes import get_scene

    scene = get_scene("fourbar")
    with pytest.raises(ValueError, match=r"undescribed \['b', 'c', 'd'\], not a default \['e'\]"):
        dataclasses.replace(scene, parameters={"a": ("m", "crank"), "e": ("m", "not a parameter")})


# ----------------------------------------------------------------------- run
def test_run_writes_csv_plots_and_summary(tmp_path):
    """``--set d=340cm`` is d = 3.4 m (a value with its unit); the CSV is SI, the summary
    reads angles in degrees and says what was changed."""
    proc = jaxmech("run", "fourbar", "--set", "d=340cm", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    head, data = read_csv(tmp_path / "fourbar.csv")
    assert head == FOURBAR_COLUMNS
    assert data.shape == (N, len(FOURBAR_COLUMNS))
    np.testing.assert_allclose(data[:, 1], np.linspace(0, 2 * np.pi, N), atol=1e-15)
    assert np.all(data[:, -1] == 0)  # every position converged
    theta4 = data[0, FOURBAR_COLUMNS.index("theta4[rad]")]
    assert abs(theta4 - theta4_at_zero(1.0, 3.0, 2.5, 3.4)) < POS_TOL  # --set d=3.4 was used
    for kind in ("coordinates", "velocities", "accelerations", "outputs", "transmission", "poses"):
        with Image.open(tmp_path / f"fourbar_{kind}.png") as im:
            assert im.format == "PNG"
    assert "scene fourbar" in proc.stdout and "status: {'CONVERGED': 101}" in proc.stdout
    assert "changed from the defaults: d = 3.4 m" in proc.stdout
    row = next(ln.split() for ln in proc.stdout.splitlines() if ln.startswith("theta2[deg]"))
    assert float(row[1]) == 0.0 and float(row[2]) == pytest.approx(360.0, rel=1e-12)  # one crank turn, in degrees
    row = next(ln.split() for ln in proc.stdout.splitlines() if ln.startswith("theta4[deg]"))
    assert float(row[1]) == pytest.approx(math.degrees(data[:, 7].min()), rel=1e-5)  # the CSV's radians, read in degrees
    assert f"wrote {tmp_path / 'fourbar.csv'}" in proc.stdout


# A user's mistakes, each answered by one line on stderr and exit status 2 (``MISTAKES``):
# names, values, units, files, grid shapes and sizes, designs that cannot be assembled,
# command-line syntax.  All run in process (``main``, quick: most are caught before JAX is set
# up, the rest share one compiled four-bar stroke); ``AS_A_USER`` runs a few of them as the
# command a user types.
MISTAKES = {
    # names
    "unknown scene": (["run", "fivebar"], "unknown scene 'fivebar'"),
    "unknown scene, other case": (["run", "FOURBAR"], "unknown scene 'FOURBAR'"),
    "unknown scene to sweep": (["sweep", "fivebar", "--grid", "a=1:2:3"], "unknown scene 'fivebar'"),
    "misspelt parameter": (["run", "arc_track_flap", "--set", "M12i=220"], "has no parameter 'M12i'; did you mean 'M12_i'?"),
    "wrong unit": (["run", "arc_track_flap", "--set", "alpha0=65mm"], "--set alpha0: unit 'mm' does not fit a quantity in rad"),
    "misspelt scene to describe": (["scenes", "arc_track"], "unknown scene 'arc_track'; did you mean 'arc_track_flap'?"),
    "misspelt scene": (["run", "fourbr"], "unknown scene 'fourbr'; did you mean 'fourbar'?"),
    "misspelt scene to report": (["report", "--scenes", "fourbar", "slider_crnk"], "unknown scene(s) ['slider_crnk']; did you mean 'slider_crank'?"),
    "misspelt grid parameter": (["sweep", "fourbar", "--grid", "aa=1:2:3"], "has no parameter(s) ['aa']; did you mean 'a'?"),
    "report unknown scene": (["report", "--scenes", "fivebar"], "unknown scene(s) ['fivebar']"),
    "unknown parameter": (["run", "fourbar", "--set", "e=1"], "has no parameter 'e'; its parameters are: a, b, c, d"),
    "a coordinate is not a parameter": (["run", "fourbar", "--set", "theta3=1"], "has no parameter 'theta3'"),
    "parameter in the wrong case": (["animate", "fourbar", "--set", "A=1"], "has no parameter 'A'"),
    "unknown grid parameter": (["sweep", "fourbar", "--grid", "z=1:2:3"], "has no parameter(s) ['z']"),
    # values and units
    "bad value": (["run", "fourbar", "--set", "a=one"], "'one' is not a number"),
    "value with a unit of another quantity": (["run", "fourbar", "--set", "a=1kg"], "--set a: unit 'kg' does not fit a quantity in m"),
    "value in degrees": (["run", "fourbar", "--set", "a=10deg"], "--set a: unit 'deg' does not fit a quantity in m"),
    "empty value": (["run", "fourbar", "--set", "a="], "'' is not a number"),
    "infinite value": (["run", "fourbar", "--set", "a=inf"], "value must be finite, got 'inf'"),
    "value that overflows": (["run", "fourbar", "--set", "a=1e400"], "value must be finite, got '1e400'"),
    "negative length": (["run", "fourbar", "--set", "a=-1"], "length 'a' must be positive, got -1.0"),
    "zero length": (["run", "fourbar", "--set", "d=0"], "length 'd' must be positive, got 0.0"),
    "negative spring stiffness": (["run", "sma_flap", "--set", "k1=-5"], "k1 must be >= 0 N/m, got -5.0"),
    # designs that cannot be assembled
    "unassemblable four-bar": (["run", "fourbar", "--set", "a=10"], "cannot be assembled"),
    "four-bar that overflows": (["run", "fourbar", "--set", "b=1e300"], "cannot be assembled"),
    "unassemblable flap": (["run", "flap_msd", "--set", "a=10"], "loop 1 cannot close"),
    "stroke that does not fit": (["run", "landing_gear", "--set", "x2=100"], "does not fit"),
    "unassemblable animation": (["animate", "fourbar", "--set", "a=10", "--out", "x.gif"], "cannot be assembled"),
    # --set syntax
    "not NAME=VALUE": (["run", "fourbar", "--set", "a"], "--set expects NAME=VALUE"),
    "no name": (["run", "fourbar", "--set", "=1"], "--set expects NAME=VALUE"),
    "set twice": (["animate", "fourbar", "--set", "a=1", "--set", "a=2"], "--set a is given twice"),
    # grids: syntax, empty, too large
    "bad grid syntax": (["sweep", "fourbar", "--grid", "a=1:2"], "--grid expects NAME=START:STOP:N"),
    "grid without a name": (["sweep", "fourbar", "--grid", "1:2:3"], "--grid expects NAME=START:STOP:N"),
    "grid start not a number": (["sweep", "fourbar", "--grid", "a=x:2:3"], "START and STOP must be numbers"),
    "infinite grid end": (["sweep", "fourbar", "--grid", "a=1:inf:3"], "START and STOP must be finite"),
    "bad grid count": (["sweep", "fourbar", "--grid", "a=1:2:x"], "N must be a whole number"),
    "grid count missing": (["sweep", "fourbar", "--grid", "a=1:2:"], "N must be a whole number"),
    "empty grid": (["sweep", "fourbar", "--grid", "a=1:2:0"], "N must be at least 1, got 0"),
    "negative grid count": (["sweep", "fourbar", "--grid", "a=1:2:-3"], "N must be at least 1, got -3"),
    "grid twice": (["sweep", "fourbar", "--grid", "a=1:2:3", "--grid", "a=1:2:3"], "--grid a is given twice"),
    "no grid": (["sweep", "fourbar"], "at least one --grid"),
    "grid too large": (["sweep", "fourbar", "--grid", "a=1:2:1000000000000000"], "out of memory"),
    "grid product too large": (["sweep", "fourbar", "--grid", "a=1:2:100000", "--grid", "b=1:2:100000", "--grid", "c=1:2:100000"],
                               "out of memory"),
    # counts
    "too few points": (["run", "fourbar", "--points", "1"], "--points must be at least 2, got 1"),
    # the limit a message states is the limit enforced: 0, -5 and 1 all say "at least 2"
    "zero points": (["run", "fourbar", "--points", "0"], "--points must be at least 2, got 0"),
    "negative points": (["sweep", "fourbar", "--grid", "a=1:2:3", "--points", "-5"], "--points must be at least 2, got -5"),
    "points not a number": (["report", "--points", "many"], "--points must be a whole number"),
    "points in exponent form": (["run", "fourbar", "--points", "1e3"], "--points must be a whole number, got '1e3'"),
    "bad chunk size": (["sweep", "fourbar", "--grid", "a=1:2:3", "--chunk-size", "0"], "--chunk-size must be at least 1"),
    "no frames": (["animate", "fourbar", "--frames", "0"], "--frames must be at least 1, got 0"),
    "frame rate not a number": (["animate", "fourbar", "--fps", "x"], "--fps must be a whole number"),
    # files
    "animation format": (["animate", "fourbar", "--out", "x.avi"], "must end in .gif, .mp4 or .html"),
    "sweep output is a folder": (["sweep", "fourbar", "--grid", "a=1:2:3", "--out", "."], "is a folder; give a file name"),
    "animation output is a folder": (["animate", "fourbar", "--out", "made.gif"], "is a folder; give a file name"),
    "run output is a file": (["run", "fourbar", "--out", "a_file"], "is a file, not a folder"),
    # only the folder named is made, never the folders above it, nor a file's folder
    "run output in a missing folder": (["run", "fourbar", "--out", "missing/out"], "the folder 'missing' does not exist"),
    "export into a missing folder": (["export", "fourbar", "--out", "missing/x.dxf"], "the folder 'missing' does not exist"),
    "sweep into a missing folder": (["sweep", "fourbar", "--grid", "a=1:2:3", "--out", "missing/x.csv"], "the folder 'missing' does not exist"),
    "unknown plots choice": (["run", "fourbar", "--plots", "some"], "argument --plots: invalid choice: 'some'"),
    "vary beside ranges": (["sweep", "fourbar", "--random", "5", "--range", "a=1:2", "--vary", "all"], "--vary chooses the default ranges"),
    # linkage files
    "linkage file that is not there": (["run", str(LINKAGES / "nope.toml")], "cannot read"),
    "linkage file with an unknown key": (["run", str(LINKAGES / "unknown_key.toml")], "unknown key(s) ['joints']"),
    "linkage file that is not TOML": (["run", str(LINKAGES / "not_toml.toml")], "not valid TOML"),
    "linkage naming a point it lacks": (["animate", str(LINKAGES / "unknown_point.json")], "names point 'B', which is not in points"),
    "linkage with a degree of freedom too many": (["run", str(LINKAGES / "open_chain.toml")], "degree(s) of freedom left"),
    "linkage with a point given twice (JSON)": (["run", str(LINKAGES / "duplicate_point.json")],
                                                "duplicate_point.json: 'A' is given twice in points"),
    "linkage with a point given twice (TOML)": (["run", str(LINKAGES / "duplicate_point.toml")],
                                                "duplicate_point.toml: 'A' is given twice in [points] (line 9)"),
    "linkage with a zero-length link": (["export", str(LINKAGES / "zero_length.toml"), "--out", "x.svg"],
                                        "zero_length.toml: points 'O2' and 'A' of one link are both at (0, 0)"),
    "linkage driver misspelt": (["run", str(LINKAGES / "misspelt_driver.toml")], "misspelt_driver.toml: misspelt_driver: driver "
                                "'crankk' is not a link, a slider or an actuator; did you mean 'crank'?"),
    "linkage parameter misspelt": (["run", str(ROOT / "examples" / "linkages" / "watt_sixbar.toml"), "--set", "len_A_C=1"],
                                   "has no parameter 'len_A_C'; did you mean 'len_A_B'?"),
    # command-line syntax
    "no verb": ([], "required"),
    "unknown verb": (["plot"], "invalid choice"),
    "no scene": (["run"], "the following arguments are required: SCENE"),
    "extra argument": (["run", "fourbar", "extra"], "unrecognized arguments: extra"),
    "report without scene names": (["report", "--scenes"], "expected at least one argument"),
}
AS_A_USER = ["unknown scene", "value with a unit of another quantity", "unassemblable four-bar", "grid too large"]
NUMPY_REPR = ("np.", "array(", "float64(", "dtype(")  # what a person must never read in a message


@pytest.mark.parametrize("verb", [["run", "fourbar"], ["report"], ["animate", "fourbar"], ["sweep", "fourbar", "--grid", "a=1:2:2"]])
def test_unwritable_destination_fails_before_computing(verb, tmp_path, capsys, monkeypatch):
    """--out under a file (not a folder) is refused in one line, exit 2, before JAX is set up
    (``_setup_jax`` is replaced by a trap: reaching it means computing would have started)."""
    import jaxmech.cli.commands as cli

    def trap():
        raise AssertionError("the destination was not checked before computing")

    monkeypatch.setattr(cli, "_setup_jax", trap)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file")
    name = {"animate": "out.gif", "sweep": "out.csv"}.get(verb[0], "out")
    assert main([*verb, "--out", str(blocker / name)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jaxmech: error: --out"), err
    assert "is a file, not a folder" in err[0] and str(blocker) in err[0]


def test_parameter_messages_print_plain_numbers():
    """No numpy repr (``np.float64(-1.0)``) in a message a person reads."""
    import jaxmech as jm
    from jaxmech.scenes.classic import fourbar_mechanism as FB

    for bad, shown in [(np.float64(-1.0), "got -1.0"), (np.array([1.0, -2.0]), "got [1.0, -2.0]"), (np.float32(np.nan), "got nan")]:
        with pytest.raises(ValueError) as e:
            jm.solve(FB, 0.3, {"a": bad, "b": 3.0, "c": 2.5, "d": 3.5}, np.array([0.5, 1.5]))
        assert shown in str(e.value) and "np." not in str(e.value) and "array(" not in str(e.value)


def one_line_error(err: str, match: str) -> str:
    """The single stderr line of a user error, checked: prefix, match, no traceback, no numpy repr."""
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("jaxmech: error: ") and match in line, line
    assert not any(r in line for r in NUMPY_REPR), line
    return line


def test_there_are_at_least_twenty_mistakes():
    assert len(MISTAKES) >= 20 and set(AS_A_USER) <= set(MISTAKES)


@pytest.mark.parametrize("case", list(MISTAKES))
def test_mistakes_are_one_line_exit_2(case, tmp_path, capsys, monkeypatch):
    args, match = MISTAKES[case]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a_file").write_text("a file")
    (tmp_path / "made.gif").mkdir()
    assert main(args) == 2
    out, err = capsys.readouterr()
    one_line_error(err, match)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "made.gif"]  # nothing written


@pytest.mark.parametrize("case", AS_A_USER)
def test_mistakes_as_a_user_types_them(case, tmp_path):
    args, match = MISTAKES[case]
    proc = jaxmech(*args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    one_line_error(proc.stderr, match)
    assert not list(tmp_path.iterdir())  # nothing written


# ----------------------------------------------------------------------- animate, sweep, report
def test_animate_gif(tmp_path):
    out = tmp_path / "fb.gif"
    proc = jaxmech("animate", "fourbar", "--frames", "5", "--out", out)
    assert proc.returncode == 0, proc.stderr
    with Image.open(out) as im:
        assert im.n_frames == 5
    assert "5 frames" in proc.stdout


def test_animate_mp4(tmp_path):
    """An MP4 (H.264, through the ``video`` extra's ffmpeg): an ISO media file, one frame per --frames."""
    import imageio_ffmpeg

    out = tmp_path / "fb.mp4"
    proc = jaxmech("animate", "fourbar", "--frames", "5", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[4:8] == b"ftyp"  # the ISO base media file's first box
    assert imageio_ffmpeg.count_frames_and_secs(str(out))[0] == 5
    assert "5 frames" in proc.stdout


def test_animate_mp4_without_ffmpeg(tmp_path, capsys, monkeypatch):
    """Neither the ``video`` extra nor an ffmpeg for Matplotlib: one line naming the extra,
    exit 2, before JAX is set up and with nothing written."""
    import matplotlib

    import jaxmech.cli.commands as cli

    def trap():
        raise AssertionError("ffmpeg was not looked for before computing")

    monkeypatch.setattr(cli, "_setup_jax", trap)
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # its import fails
    monkeypatch.setitem(matplotlib.rcParams, "animation.ffmpeg_path", str(tmp_path / "no-ffmpeg"))
    assert main(["animate", "fourbar", "--out", str(tmp_path / "fb.mp4")]) == 2
    one_line_error(capsys.readouterr().err, 'pip install "jaxmech[video]"')
    assert not list(tmp_path.iterdir())


def test_sweep_writes_one_row_per_design_and_point(tmp_path):
    out = tmp_path / "sweep.csv"
    proc = jaxmech("sweep", "fourbar", "--grid", "a=0.9:1.1:2", "--grid", "d=3.4:3.6:2", "--points", N, "--chunk-size", 4, "--out", out)
    assert proc.returncode == 0, proc.stderr
    head, data = read_csv(out)
    for col in ("a", "d", *FOURBAR_COLUMNS):
        assert col in head
    assert head[-len(FOURBAR_COLUMNS):] == FOURBAR_COLUMNS  # the order `jaxmech run` writes
    assert data.shape[0] == 4 * N
    a, d = data[:, head.index("a")], data[:, head.index("d")]
    assert sorted({(x, y) for x, y in zip(a, d)}) == [(0.9, 3.4), (0.9, 3.6), (1.1, 3.4), (1.1, 3.6)]
    start = data[:, head.index("theta2[rad]")] == 0.0
    assert start.sum() == 4
    for row in data[start]:
        expect = theta4_at_zero(row[head.index("a")], 3.0, 2.5, row[head.index("d")])
        assert abs(row[head.index("theta4[rad]")] - expect) < POS_TOL
    assert np.all(data[:, head.index("status[-]")] == 0)
    assert "4 designs" in proc.stdout


def test_report_runs_scenes_into_a_folder(tmp_path):
    proc = jaxmech("report", "--scenes", "fourbar", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    head, data = read_csv(tmp_path / "fourbar" / "fourbar.csv")
    assert head == FOURBAR_COLUMNS and data.shape[0] == N
    readme = (tmp_path / "README.md").read_text()
    assert "## fourbar" in readme and "status: {'CONVERGED': 101}" in readme
    images = [ln[ln.index("(") + 1 : -1] for ln in readme.splitlines() if ln.startswith("![")]
    assert len(images) == 6
    for rel in images:
        assert (tmp_path / rel).is_file()
    assert "scene fourbar" in proc.stdout


def test_run_a_linkage_file_gives_every_joint_force(tmp_path):
    """``jaxmech run FILE.toml``: the six-bar file's table holds the crank torque and every
    joint's reaction, equal to the Python API's along the same constant-speed stroke."""
    import jaxmech as jm

    path = ROOT / "examples" / "linkages" / "watt_sixbar.toml"
    proc = jaxmech("run", path, "--points", 37, "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    head, data = read_csv(tmp_path / "watt_sixbar.csv")
    assert np.all(data[:, head.index("status[-]")] == 0)
    lk = jm.load_linkage(path)
    t = data[:, head.index("t[s]")]
    res = lk.inverse_dynamics(jm.ConstantSpeed(np.pi / 3, 2 * np.pi), t)  # [stroke]: from 60deg at 60rpm
    tau = np.asarray(res.tau[:, 0])
    assert np.max(np.abs(data[:, head.index("effort_theta_crank[N m]")] - tau)) <= 1e-9 * np.max(np.abs(tau))
    for joint in lk.joints:
        f = np.asarray(res.joints[joint])
        got = data[:, head.index(f"F_{joint}_x[N]")] + 1j * data[:, head.index(f"F_{joint}_y[N]")]
        assert np.max(np.abs(got - f)) <= 1e-9 * np.max(np.abs(f)), joint
