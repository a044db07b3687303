"""``jaxmech simulate FILE``: forward dynamics of a linkage file from the command line, against
independent truths.

- A uniform bar swinging about its pivot under gravity (a compound pendulum: ``J_O theta'' =
  T - m g (l/2) cos theta`` with ``J_O = m l^2 / 3``), free and under a constant torque: the
  CSV's final angle and rate equal ``scipy.integrate.solve_ivp`` (Radau, rtol 1e-12) of that
  equation, written here, to 1e-8; its pivot reaction is ``m a_G - m g`` at every row.
- A slider-crank with a spring, a damper and a DC motor (``[simulate.motor]``): the CSV is
  ``Linkage.forward_dynamics`` in Python with the same motor, to round-off, and its end state
  the independent numpy model of ``tests/test_forward_runs.py`` (integrated by Radau) to 1e-8.
- Joint friction: ``friction_speed`` read from the file, the run equal to Python's.
- A second run of another duration compiles nothing; ``--plots none`` writes no PNG; every
  mistake (no table, unknown key, bad unit, no friction_speed...) is one line naming the key.
"""

import jax

jax.config.update("jax_enable_x64", True)

import csv  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.linkage.files import read_linkage_tables  # noqa: E402
from jaxmech.linkage.simulate_file import read_simulate, run_simulation, simulation_columns  # noqa: E402
from test_cli_edges import one_line  # noqa: E402
from test_forward_runs import (C, DA, F0, G, K, KM, L0, LA, MASS, RA, S, TH0, V, kinematics,  # noqa: E402
                               reference)

ROOT = Path(__file__).resolve().parents[1]

# --------------------------------------------------------------------------- compound pendulum
M_BAR, L_BAR, G_BAR = 2.0, 0.3, 9.81  # kg, m, m/s^2
TH_START, OM_START = np.radians(30.0), 1.0  # rad, rad/s
DURATION, STEP = 0.4, 1e-3  # s

PENDULUM = f"""name = "bar"
ground = "O"
driver = "crank"
gravity = {G_BAR!r}

[points]
O = [0.0, 0.0]
A = ["{L_BAR * 1000!r}mm", "0mm"]

[links]
crank = "O A"

[mass]
crank = "{M_BAR * 1000!r}g"
"""
SIMULATE = f"""
[simulate]
duration = "{DURATION * 1000!r} ms"
step = "{STEP * 1000!r}ms"
u0 = "30deg"
u_dot0 = "{OM_START!r} rad/s"
"""


def pendulum_rhs(torque):
    """The bar about its pivot, theta from +x, gravity along -y (independent of jaxmech)."""
    J = M_BAR * L_BAR**2 / 3.0

    def rhs(t, y):
        th, om = y
        return [om, (torque - M_BAR * G_BAR * 0.5 * L_BAR * np.cos(th)) / J]

    return rhs


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {name: np.array([float(r[k]) for r in rows[1:]]) for k, name in enumerate(rows[0])}


def simulate(tmp_path, text, *args, file="bar.toml", name="bar"):
    """``jaxmech simulate`` on `text` written to `file` in `tmp_path` (its linkage called
    `name`); the CSV's columns and the output folder."""
    path = tmp_path / file
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--out", str(out), *args]) == 0
    return read_csv(out / f"{name}_simulate.csv"), out


@pytest.mark.parametrize("torque", [None, 1.5])
def test_compound_pendulum_against_scipy_radau(torque, tmp_path, capsys):
    text = PENDULUM + SIMULATE + ("" if torque is None else f'torque = "{torque!r} N m"\n')
    cols, out = simulate(tmp_path, text, *(["--plots", "none"] if torque else []))
    t, th, om, al = (cols[k] for k in ("t[s]", "theta_crank[rad]", "theta_crank_dot[rad/s]", "theta_crank_ddot[rad/s^2]"))
    assert t.size == round(DURATION / STEP) + 1 and t[-1] == pytest.approx(DURATION, abs=1e-15)
    assert np.all(cols["status[-]"] == 0)
    assert th[0] == pytest.approx(TH_START, abs=1e-15) and om[0] == OM_START
    sol = solve_ivp(pendulum_rhs(torque or 0.0), (0.0, DURATION), [TH_START, OM_START], method="Radau", rtol=1e-12, atol=1e-12)
    assert sol.success
    assert abs(th[-1] - sol.y[0, -1]) <= 1e-8 and abs(om[-1] - sol.y[1, -1]) <= 1e-8, (th[-1] - sol.y[0, -1], om[-1] - sol.y[1, -1])
    assert abs(th[-1] - th[0]) > 0.2  # it swings (rad)
    # every row: the acceleration of the equation at the row's own state, the effort, the pivot's reaction m a_G - m g
    rhs = pendulum_rhs(torque or 0.0)
    np.testing.assert_allclose(al, [rhs(0, [a, b])[1] for a, b in zip(th, om)], rtol=0, atol=1e-10 * np.max(np.abs(al)))
    np.testing.assert_array_equal(cols["effort_theta_crank[N m]"], torque or 0.0)
    a_G = 0.5 * L_BAR * (1j * al - om**2) * np.exp(1j * th)
    force = M_BAR * a_G + 1j * M_BAR * G_BAR  # ground on the bar
    scale = np.max(np.abs(force))
    np.testing.assert_allclose(cols["F_O_x[N]"], force.real, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(cols["F_O_y[N]"], force.imag, rtol=0, atol=1e-10 * scale)
    printed = capsys.readouterr().out
    assert f"{round(DURATION / STEP)} steps" in printed and "status ok" in printed
    assert sorted(p.name for p in out.iterdir()) == (["bar_simulate.csv"] if torque else ["bar_simulate.csv", "bar_simulate.png"])


# --------------------------------------------------------------------------- DC motor
def slider_crank_file() -> str:
    """tests/test_forward_runs.py's slider-crank as a linkage file, driven by its motor."""
    A, B, _ = kinematics(TH0)
    xy = lambda z: f"[{float(np.real(z))!r}, {float(np.imag(z))!r}]"  # noqa: E731
    return f"""name = "slider_crank_motor"
ground = "O S D"
driver = "crank"
gravity = {G!r}

[points]
O = [0.0, 0.0]
A = {xy(A[0])}
B = [{float(B[0])!r}, 0.0]
S = {xy(S)}
D = {xy(DA)}

[links]
crank = "O A"
rod = "A B"

[sliders]
B = {{ angle = 0.0 }}

[mass]
crank = {MASS['crank']!r}
rod = {MASS['rod']!r}
block_B = {MASS['block_B']!r}

[springs.s1]
between = ["S", "B"]
on = ["ground", "block_B"]
k = {K!r}
free_length = {L0!r}
preload = {F0!r}

[dampers.d1]
between = "D A"
on = "ground crank"
c = {C!r}

[simulate]
duration = "1 s"
step = "2.5 ms"

[simulate.motor]
R_a = "{RA!r} ohm"
K_m = "{KM!r} N m/A"
L_a = "{LA * 1000!r} mH"
voltage = "{V!r} V"
"""


def test_motor_run_equals_python_and_the_independent_model(tmp_path):
    text = slider_crank_file()
    cols, _ = simulate(tmp_path, text, "--plots", "none", file="sc.toml", name="slider_crank_motor")
    lk = jm.load_linkage(tmp_path / "sc.toml")
    motor = jm.DCMotor("R_a", "K_m", inductance="L_a", voltage="voltage")
    tr = lk.forward_dynamics(h=2.5e-3, steps=400, p={"R_a": RA, "K_m": KM, "L_a": LA, "voltage": V}, motor=motor)
    assert int(tr.status) == 0, tr.message()
    for col, want in (("t[s]", tr.t), ("theta_crank[rad]", tr.u[:, 0]), ("theta_crank_dot[rad/s]", tr.u_dot[:, 0]),
                      ("theta_crank_ddot[rad/s^2]", tr.u_ddot[:, 0]), ("current[A]", tr.current[:, 0])):
        want = np.asarray(want)
        np.testing.assert_allclose(cols[col], want, rtol=0, atol=1e-13 * np.max(np.abs(want)), err_msg=col)
    for k, name in enumerate(lk.mechanism.coords):
        np.testing.assert_allclose(cols[f"{name}[{'m' if name in lk.mechanism.lengths else 'rad'}]"], np.asarray(tr.q[:, k]),
                                   rtol=0, atol=1e-13)
    # the independent model's state at 1 s (crank angle, rate, current)
    want = reference(1.0)
    got = np.array([cols[c][-1] for c in ("theta_crank[rad]", "theta_crank_dot[rad/s]", "current[A]")])
    assert np.all(np.abs(got - want) <= 1e-8), got - want
    # the effort is the motor's torque K i, and inverse dynamics along the run says the same
    np.testing.assert_allclose(cols["effort_theta_crank[N m]"], KM * cols["current[A]"], rtol=1e-15, atol=0)
    res = tr.dynamics(lk.model, {**lk.params})
    np.testing.assert_allclose(cols["effort_theta_crank[N m]"], np.asarray(res.tau[:, 0]), rtol=0,
                               atol=1e-9 * np.max(np.abs(cols["effort_theta_crank[N m]"])))
    for j in lk.joints:
        col = j.replace(" ", "_")
        f = np.asarray(res.joints[j])
        np.testing.assert_allclose(cols[f"F_{col}_x[N]"] + 1j * cols[f"F_{col}_y[N]"], f, rtol=0, atol=1e-12 * np.max(np.abs(f)))


def test_a_second_duration_compiles_nothing(tmp_path, capsys):
    path = tmp_path / "bar.toml"
    path.write_text(PENDULUM + SIMULATE)
    run = lambda d, *more: main(["simulate", str(path), "--out", str(tmp_path / d), "--plots", "none", "--duration", d,  # noqa: E731
                                 *more])
    assert run("0.2s") == 0
    seen = []
    listen = lambda event, *a, **k: seen.append(event)  # noqa: E731
    jax.monitoring.register_event_duration_secs_listener(listen)
    jax.monitoring.register_event_listener(listen)
    try:
        assert run("300ms", "--step", "1.5ms", "--set", "m_crank=3kg") == 0  # another duration, step and mass
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
        jax.monitoring.unregister_event_listener(listen)
    compiled = [e for e in seen if "backend_compile" in e or "compilation_cache" in e]
    assert not compiled, compiled
    assert read_csv(tmp_path / "300ms" / "bar_simulate.csv")["t[s]"].size == 201


def test_friction_speed_from_the_file(tmp_path):
    text = PENDULUM + '\n[friction.O]\nmu = 0.2\nradius = "10 mm"\ndamping = "0.01 N m s/rad"\n' + SIMULATE \
        + 'friction_speed = "2 rad/s"\n'
    cols, _ = simulate(tmp_path, text, "--plots", "none", "--duration", "100ms")
    lk = jm.load_linkage(tmp_path / "bar.toml")
    tr = lk.forward_dynamics(h=STEP, steps=100, u0=TH_START, u_dot0=OM_START, friction_speed=2.0)
    assert int(tr.status) == 0, tr.message()
    np.testing.assert_allclose(cols["theta_crank[rad]"], np.asarray(tr.u[:, 0]), rtol=0, atol=1e-14)
    # the reactions with friction: the pin's force is m a_G - m g whatever the friction
    # moment, and the bar's moment balance about O closes with the friction law written out
    # here (mu r |F| tanh(w / (width W)) + c w against the rotation, width 1e-3, W = 2 rad/s)
    th, om, al = (cols[k] for k in ("theta_crank[rad]", "theta_crank_dot[rad/s]", "theta_crank_ddot[rad/s^2]"))
    force = M_BAR * 0.5 * L_BAR * (1j * al - om**2) * np.exp(1j * th) + 1j * M_BAR * G_BAR
    scale = np.max(np.abs(force))
    np.testing.assert_allclose(cols["F_O_x[N]"] + 1j * cols["F_O_y[N]"], force, rtol=0, atol=1e-10 * scale)
    moment = -(0.2 * 0.010 * np.abs(force) * np.tanh(om / (1e-3 * 2.0)) + 0.01 * om)
    J = M_BAR * L_BAR**2 / 3.0
    np.testing.assert_allclose(J * al, -M_BAR * G_BAR * 0.5 * L_BAR * np.cos(th) + moment, rtol=0, atol=1e-9 * np.max(np.abs(J * al)))
    free, _ = simulate(tmp_path, PENDULUM + SIMULATE, "--plots", "none", "--duration", "100ms", file="free.toml")
    assert abs(free["theta_crank_dot[rad/s]"][-1] - cols["theta_crank_dot[rad/s]"][-1]) > 1e-4  # friction acts


def test_the_example_file(tmp_path, capsys):
    path = ROOT / "examples" / "linkages" / "fourbar_motor.toml"
    lk, _, table = read_linkage_tables(path)
    sim = read_simulate(table, lk, duration="20ms")
    assert sim.drive == "motor" and sim.steps == 20 and sim.step == 1e-3 and sim.motor.inductance == "L_a"
    assert dict(sim.values) == {"R_a": 2.0, "K_m": 0.04, "L_a": 1e-3, "ratio": 20.0, "voltage": 12.0}
    tr, p = run_simulation(lk, sim, {"voltage": 6.0})
    cols = simulation_columns(lk, sim, tr, p)
    # docs/linkage_files.md's Python for the same run
    motor = jm.DCMotor("R_a", "K_m", inductance="L_a", ratio="ratio", voltage="voltage")
    py = lk.forward_dynamics(h=1e-3, steps=20, motor=motor, p={"R_a": 2.0, "K_m": 0.04, "L_a": 1e-3, "ratio": 20.0, "voltage": 6.0})
    np.testing.assert_array_equal(cols["theta_crank[rad]"], np.asarray(py.u[:, 0]))
    np.testing.assert_array_equal(cols["current[A]"], np.asarray(py.current[:, 0]))
    # from rest the current rises towards V / R = 3 A with L / R = 0.5 ms (less the back-EMF n K w)
    assert 0.8 * 3.0 * (1 - np.exp(-2.0)) < cols["current[A]"][1] < 3.0
    np.testing.assert_allclose(cols["effort_theta_crank[N m]"], 20 * 0.04 * cols["current[A]"], rtol=1e-15)
    assert cols["theta_crank_dot[rad/s]"][-1] > 0.1
    # a step far too large: the run stops at once; exit 0, the reason and its fix printed, the rows after it NaN
    assert main(["simulate", str(path), "--step", "0.1s", "--duration", "0.5s", "--plots", "none", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "status not_converged at t = 0 s" in printed and "stopped early:" in printed and "smaller h" in printed, printed
    stopped = read_csv(tmp_path / "fourbar_motor_simulate.csv")
    assert stopped["status[-]"][0] == 0 and np.all(stopped["status[-]"][1:] == jm.Status.NOT_CONVERGED) and np.all(np.isnan(stopped["theta_crank[rad]"][1:]))


# --------------------------------------------------------------------------- mistakes
FRICTION = '\n[friction.O]\nmu = 0.2\nradius = "10 mm"\n'
MISTAKES = {  # file text, extra arguments -> what the one line says
    "no table": (PENDULUM, [], ["no [simulate] table", "--duration and --step"]),
    "no duration": (PENDULUM + '[simulate]\nstep = "1 ms"\n', [], ["[simulate] needs duration", "--duration"]),
    "unknown key": (PENDULUM + SIMULATE + 'durration = "1 s"\n', [], ["['durration']", "did you mean 'duration'?"]),
    "bad unit": (PENDULUM + SIMULATE.replace('"1.0ms"', '"1 kg"'), [], ["[simulate] step", "'1 kg'"]),
    "bad --step": (PENDULUM + SIMULATE, ["--step", "fast"], ["--step", "'fast'"]),
    "no friction_speed": (PENDULUM + FRICTION + SIMULATE, [], ["[simulate] needs friction_speed", "friction_speed = 2.0"]),
    "friction_speed without friction": (PENDULUM + SIMULATE + "friction_speed = 1.0\n", [], ["friction_speed", "no [friction]"]),
    "motor key": (PENDULUM + SIMULATE + '[simulate.motor]\nR_a = 1.0\nK_m = 0.1\nvoltag = "12 V"\n', [],
                  ["['voltag']", "did you mean 'voltage'?"]),
    "motor missing": (PENDULUM + SIMULATE + '[simulate.motor]\nR_a = 1.0\nK_m = 0.1\n', [], ["[simulate.motor] needs voltage"]),
    "motor unit": (PENDULUM + SIMULATE + '[simulate.motor]\nR_a = "1 N"\nK_m = 0.1\nvoltage = 12\n', [],
                   ["[simulate.motor] R_a", "ohm"]),
    "motor and torque": (PENDULUM + SIMULATE + 'torque = 1.0\n[simulate.motor]\nR_a = 1.0\nK_m = 0.1\nvoltage = 12\n', [],
                         ["[simulate.motor] or by torque, not both"]),
    "torque unit": (PENDULUM + SIMULATE + 'torque = "3 N"\n', [], ["[simulate] torque", "N m"]),
    "--set name": (PENDULUM + SIMULATE, ["--set", "m_crnk=1"], ["--set m_crnk", "did you mean 'm_crank'?"]),
    "--set unit": (PENDULUM + SIMULATE + 'torque = 1.0\n', ["--set", "torque=2 kg"], ["--set torque", "N m"]),
    "not a file": (None, [], ["simulate runs a linkage file"]),
}


@pytest.mark.parametrize("case", list(MISTAKES))
def test_each_mistake_is_one_line_naming_the_key(case, tmp_path, capsys, monkeypatch):
    text, extra, says = MISTAKES[case]
    monkeypatch.chdir(tmp_path)
    if text is not None:
        (tmp_path / "bar.toml").write_text(text)
    assert main(["simulate", "bar.toml" if text is not None else "fourbar", *extra, "--plots", "none"]) == 2
    line = one_line(capsys.readouterr().err, *says)
    assert text is None or case.startswith(("--set", "bad --")) or line.startswith("jaxmech: error: bar.toml: "), line
    assert not (tmp_path / "jaxmech-out" / "bar_simulate.csv").exists()


def test_a_mistake_in_a_real_process_is_one_line(tmp_path):
    (tmp_path / "bar.toml").write_text(PENDULUM + FRICTION + SIMULATE)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "jaxmech", "simulate", "bar.toml"], capture_output=True, text=True,
                          cwd=tmp_path, env=env, timeout=300)
    assert proc.returncode == 2
    one_line(proc.stderr, "bar.toml: [simulate] needs friction_speed")


def test_help_and_an_unwritable_destination_before_computing(tmp_path, capsys, monkeypatch):
    import jaxmech.cli.commands as cli

    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--help"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("usage: jaxmech simulate")
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "simulate" in capsys.readouterr().out

    def trap():
        raise AssertionError("the destination was not checked before computing")

    monkeypatch.setattr(cli, "_setup_jax", trap)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file")
    assert main(["simulate", str(ROOT / "examples" / "linkages" / "fourbar_motor.toml"), "--out", str(blocker / "out")]) == 2
    one_line(capsys.readouterr().err, "--out", "is a file, not a folder")


def test_a_json_file_reads_the_same_table(tmp_path):
    (tmp_path / "bar.toml").write_text(PENDULUM + SIMULATE + '[simulate.motor]\nR_a = "500 mohm"\nK_m = "50 mN m/A"\n'
                                       'L_a = "200 uH"\nratio = 10\nvoltage = "24 V"\ncurrent0 = "100 mA"\n')
    (tmp_path / "bar.json").write_text(
        '{"name": "bar", "ground": "O", "driver": "crank", "gravity": 9.81, "points": {"O": [0, 0], "A": [0.3, 0]},'
        ' "links": {"crank": "O A"}, "mass": {"crank": 2.0},'
        ' "simulate": {"duration": 0.4, "step": "1ms", "u0": "30deg", "u_dot0": 1.0,'
        '              "motor": {"R_a": 0.5, "K_m": 0.05, "L_a": 2e-4, "ratio": 10, "voltage": 24, "current0": 0.1}}}')
    sims = []
    for name in ("bar.toml", "bar.json"):
        lk, _, table = read_linkage_tables(tmp_path / name)
        sims.append(read_simulate(table, lk))
    toml, json = sims
    assert toml.steps == json.steps == 400 and toml.u0 == pytest.approx(json.u0, rel=1e-15) and toml.u_dot0 == json.u_dot0
    assert toml.motor == json.motor and toml.current0 == pytest.approx(json.current0, rel=1e-15)
    assert dict(json.values) == {"R_a": 0.5, "K_m": 0.05, "L_a": 2e-4, "ratio": 10.0, "voltage": 24.0}
    assert dict(toml.values) == pytest.approx(dict(json.values), rel=1e-15)
