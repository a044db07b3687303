"""A linkage file's ``[stroke]`` says what Python's ``jm.Samples`` says (issue 35, item 2):
a rocking law and given samples (a table or a CSV beside the file) give what
``Linkage.inverse_dynamics(jm.Samples(...))`` gives, and ``jaxmech run --point-kinematics``
writes every named point's position, velocity and acceleration equal to ``res.points``."""

import csv

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.scenes.linkage_scene import scene_from_file  # noqa: E402

# A crank-rocker with masses and gravity (efforts and reactions are not zero).
LINKAGE = """driver = "crank"
ground = ["O2", "O4"]
gravity = 9.81
mass = { crank = 1.0, coupler = 3.0, rocker = 2.0 }
[points]
O2 = [0.0, 0.0]
A = [1.0, 0.0]
B = [2.8, 2.4]
O4 = [3.5, 0.0]
P = [1.9, 1.2]
[links]
crank = ["O2", "A"]
coupler = ["A", "B", "P"]
rocker = ["O4", "B"]
"""
ROCK = '[stroke]\nlaw = "rock"\nfrom = "-20deg"\nto = "70deg"\ncycles = 2\nperiod = 1.5\n'


def _run_file(tmp_path, text: str, *options) -> dict:
    """``jaxmech run`` on a file holding `text` (no store: this test's process stays as it
    was): the CSV's columns by name."""
    path = tmp_path / "rocker.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--plots", "none", "--out", str(out), *options]) == 0
    with open(out / "rocker.csv", newline="") as f:
        rows = list(csv.reader(f))
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}


def _close(got, want, what):
    want = np.asarray(want)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * (1.0 + np.max(np.abs(want))), err_msg=what)


def _check(table: dict, res, points: bool = False):
    """Every column of `table` against the Python result `res` (``InverseDynamics``)."""
    _close(table["theta_crank[rad]"], res.u[:, 0], "input")
    for k, name in enumerate(("theta_coupler", "theta_rocker")):
        _close(table[f"{name}[rad]"], res.q[:, k], name)
        _close(table[f"{name}_ddot[rad/s^2]"], res.q_ddot[:, k], name + "_ddot")
    _close(table["effort_theta_crank[N m]"], res.tau[:, 0], "effort")
    for joint, force in res.joints.items():
        _close(table[f"F_{joint}_x[N]"] + 1j * table[f"F_{joint}_y[N]"], force, f"reaction at {joint}")
    if points:
        assert res.points
        for name, triple in res.points.items():
            for prefix, z, unit in zip(("", "v", "a"), triple, ("m", "m/s", "m/s^2")):
                _close(table[f"{prefix}x_{name}[{unit}]"] + 1j * table[f"{prefix}y_{name}[{unit}]"], z, f"{prefix} of {name}")


def test_a_rocking_stroke_equals_python_samples_and_point_kinematics_equal_res_points(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXMECH_COMPILE_CACHE", "0")
    table = _run_file(tmp_path, LINKAGE + ROCK, "--points", "61", "--point-kinematics")
    # the documented law, written out: u = mid - amp cos(2 pi t / period), two periods of 1.5 s
    t = np.linspace(0.0, 3.0, 61)
    mid, amp, w = np.radians(25.0), np.radians(45.0), 2 * np.pi / 1.5
    drive = jm.Samples(mid - amp * np.cos(w * t), amp * w * np.sin(w * t), amp * w**2 * np.cos(w * t), t=t)
    res = jm.load_linkage(tmp_path / "rocker.toml").inverse_dynamics(drive)
    assert np.all(np.asarray(res.status) == 0) and np.all(table["status[-]"] == 0)
    _close(table["t[s]"], t, "t")
    assert np.ptp(table["effort_theta_crank[N m]"]) > 1.0  # a load that a wrong sample would show
    _check(table, res, points=True)
    # it reverses: at `to` mid-cycle, back at `from` after each of the two cycles
    _close(table["theta_crank[rad]"][[0, 15, 30, 45, 60]], np.radians([-20.0, 70.0, -20.0, 70.0, -20.0]), "cycles")


def test_samples_from_a_csv_beside_the_file_equal_python_samples(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXMECH_COMPILE_CACHE", "0")
    s = np.linspace(0.0, 1.0, 25)
    u, ud, udd = 0.3 + 0.9 * s**2, 1.8 * s, np.full_like(s, 1.8)  # the crank speeding up from rest
    lines = ["t,u,u_dot,u_ddot"] + [",".join(repr(float(x)) for x in row) for row in zip(s, u, ud, udd)]
    (tmp_path / "drive").mkdir()
    (tmp_path / "drive" / "samples.csv").write_text("\n".join(lines) + "\n")
    table = _run_file(tmp_path, LINKAGE + '[stroke]\nsamples = "drive/samples.csv"\n')
    res = jm.load_linkage(tmp_path / "rocker.toml").inverse_dynamics(jm.Samples(u, ud, udd, t=s))
    _close(table["t[s]"], s, "t")
    _check(table, res)
    # the same samples as a [stroke.samples] table give the same columns
    listed = "\n".join(f"{k} = [{', '.join(repr(float(x)) for x in v)}]" for k, v in (("u", u), ("u_dot", ud), ("u_ddot", udd), ("t", s)))
    again = _run_file(tmp_path, LINKAGE + "[stroke.samples]\n" + listed + "\n")
    for name, column in table.items():
        np.testing.assert_array_equal(again[name], column, err_msg=name)


@pytest.mark.parametrize("stroke, says", [
    ('law = "rok"\nfrom = 0\nto = 1\n', "law = 'rok' is not one of ['sweep', 'rock'] (or give samples); did you mean 'rock'?"),
    ('law = "rock"\nfrom = 0\n', "[stroke] needs both from and to"),
    ('law = "rock"\nfrom = 0\nto = 1\ncycles = 0\n', "[stroke] cycles = 0 must be a positive number"),
    ('from = 0\nto = 1\ncycles = 2\n', "[stroke] ['cycles'] belong to law = \"rock\""),
    ('samples = "missing.csv"\n', "[stroke] samples = 'missing.csv': cannot read missing.csv"),
    ('samples = "x.csv"\nfrom = 0\n', "[stroke] samples give the whole drive; leave out ['from']"),
    ('[stroke.samples]\nu = [0, 1]\nu_dot = [0]\nu_ddot = [0, 0]\n', "one value per sample"),
    ('[stroke.samples]\nu = [0, 1]\nudot = [0, 0]\nu_ddot = [0, 0]\n', "unknown ['udot'], missing ['u_dot']"),
])  # fmt: skip
def test_a_bad_stroke_is_refused_naming_the_file_and_the_key(stroke, says, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("JAXMECH_COMPILE_CACHE", "0")
    text = LINKAGE + ("" if stroke.startswith("[") else "[stroke]\n") + stroke
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(ValueError) as err:
        scene_from_file(tmp_path / "bad.toml")
    assert str(err.value).startswith("bad.toml: ") and says in str(err.value)
    assert main(["run", str(tmp_path / "bad.toml"), "--plots", "none", "--out", str(tmp_path / "o")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and says in lines[0]
