"""Joint friction where a linkage runs as a scene (``run_scene``, ``jaxmech run FILE``,
``sweep_scene``) and in ``Trajectory.dynamics``, against independent truths:

- a driven bar (``tests/test_forward_friction``'s pendulum: Coulomb friction and viscous
  damping at its pivot O) turning at constant speed: the scene's effort is the numpy
  moment balance about O written here, ``tau = m g c cos(th) + mu r |F| tanh(w / (width W))
  + c_v w`` with the pin force ``F = m (a_G - g)`` from the closed-form kinematics (``W = w``:
  the stroke's own speed scale), and its pin force that ``F``; the offset slider-crank of
  ``tests/test_friction_power`` with friction at its three pins and in its guide: the
  scene's effort and every joint's reaction are ``Linkage.inverse_dynamics``' at the same
  samples;
- ``jaxmech run`` on ``tests/test_friction_files``' press file with its ``[friction]`` table:
  the CSV's effort differs from the file's without friction and is Python's
  ``inverse_dynamics`` with friction; ``--set`` takes a friction parameter with its unit;
- a sweep over the pivot's ``mu_O``: the effort grows with ``mu`` by ``r |F|`` per unit
  ``mu`` (numpy), and at ``mu = 0`` it is the frictionless linkage's sweep;
- the slider-crank with ``mu = 3`` in its guide: where the rod pushes the block against
  its load at a steep angle friction jams it (no effort drives it: the friction Newton has
  no root), those samples alone have status ``MAX_STEPS`` (NaN in the table), every other
  sample is ``inverse_dynamics``', the effort's gradient in ``mu`` over the others is
  finite and agrees with central differences, and ``scene_problem``'s rows over the jammed
  stroke are not finite and a ``scene_figure`` over it is not ok (both finite at ``mu = 0.5``);
- a forward run of the pendulum with pivot friction, released (no motor, no load): its
  ``Trajectory.dynamics`` applies the run's friction, so the effort balancing the run's
  accelerations is zero (the run's actual effort), the pin force is ``m (a_G - g)`` and
  the friction moment ``-mu r |F| tanh(w / (width W)) - c_v w`` at the run's speed scale.
"""

import jax

jax.config.update("jax_enable_x64", True)

import functools  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jaxmech as jm  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402
import test_forward_friction as PEN  # noqa: E402
import test_friction_files as PRESS  # noqa: E402
import test_friction_power as SC  # noqa: E402
from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.scenes import run_scene  # noqa: E402
from jaxmech.design import scene_figure, scene_problem  # noqa: E402
from jaxmech.scenes.columns import design_columns, design_motion  # noqa: E402
from jaxmech.sweep import sweep_scene  # noqa: E402

OMEGA = 2.0  # rad/s, the pendulum's drive speed
POINTS = 37


def bar(damping: bool = True, friction: bool = True):
    """``test_forward_friction``'s bar O-A driven at O, with friction at O (and its damping)."""
    fr = {"all": {"mu": PEN.MU, "radius": PEN.RPIN, **({"damping": PEN.CV} if damping else {})}, "width": PEN.WIDTH}
    return jm.Linkage(points={"O": (0, 0), "A": (PEN.L, 0)}, links={"arm": "O A"}, ground="O", driver="arm",
                      mass={"arm": PEN.MASS}, gravity=PEN.G, **({"friction": fr} if friction else {}))


def bar_pin_force(th, om, al):
    """The ground's force on the bar at O (N, complex): ``m (a_G - g)``."""
    return PEN.MASS * PEN.C * np.exp(1j * th) * (1j * al - om * om) + 1j * PEN.MASS * PEN.G


def samples_of(result):
    """The scene's samples as ``Samples`` for ``Linkage.inverse_dynamics``."""
    mo = result.motion
    return jm.Samples(*(np.asarray(x)[:, 0] for x in (mo.u, mo.u_dot, mo.u_ddot)), np.asarray(mo.t))


def effort(table):
    (name,) = [k for k in table if k.startswith("effort_")]
    return np.asarray(table[name])


def assert_like_inverse_dynamics(table, res, rows, rtol=1e-12):
    """The scene's effort and every joint's reaction at `rows` against ``inverse_dynamics``' `res`."""
    scale = np.max(np.abs(np.asarray(res.tau)[rows]))
    np.testing.assert_allclose(effort(table)[rows], np.asarray(res.tau)[rows, 0], rtol=0, atol=rtol * scale)
    for joint, force in res.joints.items():
        col = joint.replace(" ", "_")
        f = np.asarray(force)[rows]
        fscale = np.max(np.abs(f))
        np.testing.assert_allclose(table[f"F_{col}_x[N]"][rows], f.real, rtol=0, atol=rtol * fscale, err_msg=joint)
        np.testing.assert_allclose(table[f"F_{col}_y[N]"][rows], f.imag, rtol=0, atol=rtol * fscale, err_msg=joint)
    for joint, moment in res.joint_moments.items():
        m = np.asarray(moment)[rows]
        np.testing.assert_allclose(table[f"M_{joint.replace(' ', '_')}[N m]"][rows], m, rtol=0,
                                   atol=rtol * max(np.max(np.abs(m)), scale), err_msg=joint)


# --------------------------------------------------------------------------- (a) run_scene
@functools.lru_cache(maxsize=None)
def bar_run():
    return run_scene(bar().scene(stroke=(0.0, 2 * np.pi), speed=OMEGA), POINTS)


def test_a_bar_scene_with_pin_friction_is_the_numpy_moment_balance():
    res = bar_run()
    table = res.table()
    assert np.all(table["status[-]"] == jm.Status.CONVERGED)
    th = np.asarray(res.motion.u[:, 0])
    f = bar_pin_force(th, OMEGA, 0.0)
    # W = OMEGA (the stroke's largest speed at O), so the sign is tanh(1 / width)
    want = PEN.MASS * PEN.G * PEN.C * np.cos(th) + PEN.MU * PEN.RPIN * np.abs(f) * np.tanh(1.0 / PEN.WIDTH) + PEN.CV * OMEGA
    np.testing.assert_allclose(effort(table), want, rtol=0, atol=1e-13 * np.max(np.abs(want)))
    np.testing.assert_allclose(table["F_O_x[N]"] + 1j * table["F_O_y[N]"], f, rtol=0, atol=1e-13 * np.max(np.abs(f)))
    # friction takes part: without it the effort is the gravity moment alone
    assert np.min(want - PEN.MASS * PEN.G * PEN.C * np.cos(th)) > 0.05
    # and it is inverse_dynamics' at the same samples
    assert_like_inverse_dynamics(table, bar().inverse_dynamics(samples_of(res)), slice(None))


def test_a_slider_crank_scene_with_friction_everywhere_is_inverse_dynamics():
    lk = SC.linkage(friction=SC.FRICTION)
    scene = lk.scene(stroke=(SC.TH0, SC.TH0 + 2 * np.pi), speed=2.0)
    assert scene.parameters["mu_block_B"] == ("-", "joint friction") and scene.parameters["rpin_A"][0] == "m"
    assert scene.parameters["cv_A"][0] == "N m s/rad" and scene.parameters["cv_block_B"][0] == "N s/m"
    res = run_scene(scene, 41)
    table = res.table()
    assert np.all(table["status[-]"] == jm.Status.CONVERGED)
    assert_like_inverse_dynamics(table, lk.inverse_dynamics(samples_of(res)), slice(None))
    bare = run_scene(SC.linkage().scene(stroke=(SC.TH0, SC.TH0 + 2 * np.pi), speed=2.0), 41).table()
    assert np.max(np.abs(effort(table) - effort(bare))) > 0.05 * np.max(np.abs(effort(bare)))


# --------------------------------------------------------------------------- (b) the command line
def test_jaxmech_run_on_a_file_with_friction_writes_the_friction_effort(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "press.toml").write_text(PRESS.DRAWING + PRESS.FRICTION_TOML)
    (tmp_path / "bare.toml").write_text(PRESS.DRAWING.replace('name = "press"', 'name = "bare"'))
    assert main(["run", "press.toml", "--plots", "none", "--points", "41", "--out", "out"]) == 0
    assert main(["run", "bare.toml", "--plots", "none", "--points", "41", "--out", "out"]) == 0
    assert main(["run", "press.toml", "--plots", "none", "--points", "41", "--out", "more", "--set", "mu_A=0.3"]) == 0
    capsys.readouterr()
    read = lambda p: np.genfromtxt(p, delimiter=",", names=True, deletechars="")  # noqa: E731
    got, bare, more = read("out/press.csv"), read("out/bare.csv"), read("more/press.csv")
    (name,) = [k for k in got.dtype.names if k.startswith("effort_")]
    assert np.all(got["status[-]"] == 0)
    lk = PRESS.in_python(friction=PRESS.FRICTION_JSON)
    t = got["t[s]"]
    th = got[name.replace("effort_", "").split("[")[0] + "[rad]"]
    s = jm.Samples(th, np.full_like(t, 1.0), np.zeros_like(t), t)  # the file's stroke: a whole turn at 1 rad/s
    want = np.asarray(lk.inverse_dynamics(s).tau[:, 0])
    np.testing.assert_allclose(got[name], want, rtol=0, atol=1e-12 * np.max(np.abs(want)))
    assert np.max(np.abs(got[name] - bare[name])) > 0.02 * np.max(np.abs(bare[name]))
    want_more = np.asarray(lk.inverse_dynamics(s, p={"mu_A": 0.3}).tau[:, 0])
    np.testing.assert_allclose(more[name], want_more, rtol=0, atol=1e-12 * np.max(np.abs(want_more)))
    # a negative coefficient is one line naming the parameter
    assert main(["run", "press.toml", "--plots", "none", "--out", "bad", "--set", "mu_A=-0.1"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "mu_A" in err and "must not be negative" in err, err


# --------------------------------------------------------------------------- (c) sweeps
def test_a_sweep_over_mu_grows_the_effort_and_at_zero_is_the_frictionless_sweep():
    mus = np.array([0.0, 0.1, 0.3])
    scene = bar(damping=False).scene(stroke=(0.0, 2 * np.pi), speed=OMEGA)
    sw = sweep_scene(scene, table={"mu_O": mus}, points=POINTS)
    assert np.all(sw.status == jm.Status.CONVERGED)
    (name,) = [k for k in sw.columns if k.startswith("effort_")]
    e = np.asarray(sw.columns[name])
    th = np.asarray(sw.columns["theta_arm[rad]"][0])
    grow = PEN.RPIN * np.abs(bar_pin_force(th, OMEGA, 0.0)) * np.tanh(1.0 / PEN.WIDTH)  # d effort / d mu
    for k in (1, 2):
        np.testing.assert_allclose(e[k] - e[0], mus[k] * grow, rtol=0, atol=1e-12 * np.max(np.abs(e)))
    assert np.all(np.diff(e, axis=0) > 0.01)
    bare = sweep_scene(bar(friction=False).scene(stroke=(0.0, 2 * np.pi), speed=OMEGA), points=POINTS)
    for col, v in bare.columns.items():
        scale = max(np.max(np.abs(v)), 1.0)
        np.testing.assert_allclose(sw.columns[col][0], v[0], rtol=0, atol=1e-13 * scale, err_msg=col)


# --------------------------------------------------------------------------- (d) a jammed sample
def test_samples_jammed_by_friction_are_marked_and_their_neighbours_are_untouched():
    lk = SC.linkage(friction={"block_B": {"mu": 3.0}})
    scene = lk.scene(stroke=(SC.TH0, SC.TH0 + 2 * np.pi), speed=0.5)
    res = run_scene(scene, 73)
    table = res.table()
    status = table["status[-]"]
    jammed = status == jm.Status.MAX_STEPS
    assert 3 <= np.count_nonzero(jammed) <= 30 and np.all(jammed | (status == jm.Status.CONVERGED))
    # where it jams the rod pushes the block against its load (+x) at a steep angle
    th = np.asarray(res.motion.u[:, 0])
    phi = np.arcsin((SC.E - SC.R * np.sin(th)) / SC.L)
    v_block = np.array([SC.relative_speeds(a, 0.5)["block_B on ground"] for a in th])
    assert np.all(v_block[jammed] > 0) and np.all(np.abs(np.tan(phi[jammed])) > 0.8 / 3.0)
    assert np.all(np.isnan(effort(table)[jammed])) and np.all(np.isfinite(effort(table)[~jammed]))
    ref = lk.inverse_dynamics(samples_of(res))
    assert np.array_equal(np.asarray(ref.status), status)
    assert_like_inverse_dynamics(table, ref, ~jammed)

    # the effort's gradient in mu over the samples that move: finite, as central differences say
    p = dict(scene.defaults)

    def total(mu):
        cols, st = design_columns(scene, 73, {**p, "mu_block_B": mu})
        e = cols[[k for k in cols if k.startswith("effort_")][0]]
        return jnp.sum(jnp.where(st == jm.Status.CONVERGED, e, 0.0) * jnp.asarray(~jammed))

    g = float(jax.grad(total)(jnp.asarray(3.0)))
    h = 1e-5
    fd = (float(total(3.0 + h)) - float(total(3.0 - h))) / (2 * h)
    assert np.isfinite(g) and abs(fd) > 1.0 and abs(g - fd) <= 1e-5 * abs(fd), (g, fd)

    # a refinement's rows over a jammed stroke are not finite (the design is not ok); over a free one they are
    (name,) = [k for k in table if k.startswith("effort_")]
    problem = scene_problem(scene, {"mu_block_B": (0.1, 3.0)}, peak=name, points=73)

    @jax.jit
    def peak_rows(mu):
        q = {**p, "mu_block_B": mu}
        mo, _ = design_motion(scene, 73, q)
        return problem.rows(q, mo).peak

    assert np.all(np.isnan(np.asarray(peak_rows(3.0))))
    free = np.asarray(peak_rows(0.5))
    assert np.all(np.isfinite(free)) and np.max(free) > 10.0
    # and a design figure over it is not ok
    figure = scene_figure(scene, lambda c, p_: jnp.max(c[name]), points=73)
    value, ok = figure({"mu_block_B": 3.0})
    assert not bool(ok) and np.isnan(float(value))
    value, ok = figure({"mu_block_B": 0.5})
    assert bool(ok) and abs(float(value) - np.max(free)) <= 1e-12 * np.max(free)


# --------------------------------------------------------------------------- (e) Trajectory.dynamics
def test_trajectory_dynamics_applies_the_runs_friction():
    lk = bar()
    tr = lk.forward_dynamics(h=1.0 / 200, steps=160, friction_speed=PEN.W)
    assert int(tr.status) == jm.Status.CONVERGED, tr.message()
    assert tr.friction == lk.friction and tr.friction_speed == (PEN.W,)
    dyn = tr.dynamics(lk.model, lk.params)
    th, om, al = (np.asarray(x)[:, 0] for x in (tr.u, tr.u_dot, tr.u_ddot))
    assert np.count_nonzero(np.diff(np.sign(om[1:]))) >= 1  # it swings back
    f = bar_pin_force(th, om, al)
    friction = -PEN.MU * PEN.RPIN * np.abs(f) * np.tanh(om / (PEN.WIDTH * PEN.W)) - PEN.CV * om
    gravity = PEN.MASS * PEN.G * PEN.C
    # released: nothing drives the bar, so the effort balancing its accelerations with friction is zero
    assert np.max(np.abs(np.asarray(dyn.tau[:, 0]))) <= 1e-10 * gravity
    np.testing.assert_allclose(np.asarray(dyn.joints["O"]), f, rtol=0, atol=1e-10 * np.max(np.abs(f)))
    np.testing.assert_allclose(np.asarray(dyn.joint_friction["O"]), friction, rtol=0, atol=1e-10 * gravity)
    assert np.all(np.asarray(dyn.status) == jm.Status.CONVERGED)
    # and it is inverse dynamics with friction at the run's states, its sign at the run's speed scale
    at = jm.inverse_dynamics_at(lk.model, tr.u, tr.u_dot, tr.u_ddot, lk.params, tr.q, t=tr.t, friction=lk.friction,
                                friction_speed=PEN.W)
    np.testing.assert_array_equal(np.asarray(at.tau), np.asarray(dyn.tau))
    # the frictionless inverse dynamics would have the drive supply friction's moment
    own = {k: v for k, v in lk.params.items() if k in lk.model.parameters}
    bare = jm.inverse_dynamics_at(lk.model, tr.u, tr.u_dot, tr.u_ddot, own, tr.q, t=tr.t)
    np.testing.assert_allclose(np.asarray(bare.tau[:, 0]), friction, rtol=0, atol=1e-10 * gravity)
    assert np.max(np.abs(friction)) > 0.01


def test_the_friction_speed_of_inverse_dynamics_at_is_asked_for():
    lk = bar()
    with pytest.raises(ValueError, match="needs friction_speed="):
        jm.inverse_dynamics_at(lk.model, 0.0, 1.0, 0.0, lk.params, np.zeros(len(lk.mechanism.coords)), friction=lk.friction)
