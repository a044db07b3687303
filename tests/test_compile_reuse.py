"""Compiled code is reused when nothing structural changed (an identical mechanism rebuilt,
a stroke one point longer); stored executables carry programs to a new process, with JAX's
persistent cache off (the default) or on (the user's)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
P = dict(a=1.0, b=3.0, c=2.5, d=3.5)


def fourbar(c_scale=1.0):
    return jm.Mechanism(
        coords=("theta3", "theta4"), inputs=("theta2",), params=("a", "b", "c", "d"), lengths=("a", "b", "c", "d"),
        constraints=lambda q, u, p: [p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - c_scale * p.c * jm.cis(q.theta4) - p.d],
        branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
    )  # fmt: skip


class CompileCounter:
    """Counts XLA compiles through jax.monitoring while active."""

    def __init__(self):
        self.n = 0
        self.on = False
        jax.monitoring.register_event_duration_secs_listener(self._listen)

    def _listen(self, event, duration, **kw):
        if self.on and event == "/jax/core/compile/backend_compile_duration":
            self.n += 1


COUNTER = CompileCounter()


def test_identical_mechanisms_are_equal_and_share_compiled_code():
    a, b, other = fourbar(), fourbar(), fourbar(c_scale=2.0)
    assert a == b and hash(a) == hash(b)
    assert a != other  # a different constant inside the equations is a different program
    us = np.linspace(0.0, 2 * np.pi, 361)
    first = jm.stroke_kinematics(a, us, P, np.array([0.4, 1.7]))
    COUNTER.n, COUNTER.on = 0, True
    try:
        again = jm.stroke_kinematics(b, us, P, np.array([0.4, 1.7]))
        longer = jm.stroke_kinematics(b, np.linspace(0.0, 2 * np.pi, 362), P, np.array([0.4, 1.7]))
    finally:
        COUNTER.on = False
    assert COUNTER.n == 0, f"{COUNTER.n} programs compiled for a rebuilt mechanism and a stroke one point longer"
    np.testing.assert_array_equal(np.asarray(again[0].q), np.asarray(first[0].q))
    assert longer[0].q.shape == (362, 2) and np.all(np.asarray(longer[0].ok))
    # both strokes end at the same crank angle (a full turn): the same pose
    np.testing.assert_allclose(np.asarray(longer[0].q[-1]), np.asarray(first[0].q[-1]), atol=1e-12)


def _seen(env, code="import jax, jaxmech; from jaxmech._compile.stored import store_dir; print(jax.config.jax_compilation_cache_dir, store_dir())"):
    env = {k: v for k, v in {**os.environ, **env}.items() if v is not None}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().split()


def test_cache_switches(tmp_path):
    """``import jaxmech`` switches no JAX cache on; the store's folder follows
    ``JAXMECH_COMPILE_CACHE`` and ``XDG_CACHE_HOME``; ``enable_compile_cache`` is the opt-in."""
    base = {"JAX_COMPILATION_CACHE_DIR": None, "JAXMECH_EXPORT_CACHE": None, "PYTHONPATH": str(ROOT)}
    assert _seen({**base, "JAXMECH_COMPILE_CACHE": "0"}) == ["None", "None"]
    here = tmp_path / "here"
    assert _seen({**base, "JAXMECH_COMPILE_CACHE": str(here)}) == ["None", str(here / "executables")]
    theirs = str(tmp_path / "theirs")  # JAX's own variable: theirs, and the store is still ours
    xdg = tmp_path / "xdg"
    assert _seen({**base, "JAXMECH_COMPILE_CACHE": None, "JAX_COMPILATION_CACHE_DIR": theirs, "XDG_CACHE_HOME": str(xdg)}) == [
        theirs, str(xdg / "jaxmech" / "executables")]  # fmt: skip
    assert _seen({**base, "JAXMECH_COMPILE_CACHE": None, "XDG_CACHE_HOME": str(xdg)}) == [
        "None", str(xdg / "jaxmech" / "executables")]  # fmt: skip
    opt_in = "import jax, jaxmech; print(jaxmech.enable_compile_cache(), jax.config.jax_compilation_cache_dir)"
    assert _seen({**base, "JAXMECH_COMPILE_CACHE": None, "XDG_CACHE_HOME": str(xdg)}, opt_in) == [str(xdg / "jaxmech" / "xla")] * 2
    assert (xdg / "jaxmech" / "xla").is_dir()


_NEW_PROCESS = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
if sys.argv[3] != "-":
    jax.config.update("jax_compilation_cache_dir", sys.argv[3])  # the user's own JAX cache
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
import numpy as np
import jaxmech as jm
from jaxmech._compile.stored import store_stats, wait_for_stores
sys.path.insert(0, sys.argv[2])
from test_compile_reuse import P, fourbar
sol, d1, d2 = jm.stroke_kinematics(fourbar(), np.linspace(0.0, 2 * np.pi, 361), P, np.array([0.4, 1.7]))
np.savez(sys.argv[1], q=sol.q, status=sol.status, d1=d1, d2=d2)
wait_for_stores()  # written on a thread of their own
print(json.dumps(store_stats()))
"""


def _new_process(out: Path, store: Path, jax_cache="-", script=_NEW_PROCESS):
    """``script`` in a fresh interpreter with its store in ``store`` (JAX's cache: off, or
    ``jax_cache`` switched on by the script as a user would); its store counts."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "JAXMECH_EXPORT_CACHE")}
    env.update(JAXMECH_COMPILE_CACHE=str(store), PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", script, str(out), str(Path(__file__).parent), str(jax_cache)],
                          env=env, capture_output=True, text=True, timeout=300, cwd=ROOT)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _same_bits(path, res):
    r = np.load(path)
    sol, d1, d2 = res
    for name, mine in (("q", sol.q), ("status", sol.status), ("d1", d1), ("d2", d2)):
        np.testing.assert_array_equal(r[name], np.asarray(mine), err_msg=name)


def test_a_new_process_runs_the_stored_program_bit_for_bit(tmp_path, monkeypatch):
    """A first process (JAX's cache off: the default) compiles and stores the stroke
    executable; a second loads it (no tracing); both give the bits of the plain jitted
    program."""
    us, g = np.linspace(0.0, 2 * np.pi, 361), np.array([0.4, 1.7])
    monkeypatch.setenv("JAXMECH_EXPORT_CACHE", "0")
    plain = jm.stroke_kinematics(fourbar(), us, P, g)  # traced and jitted as without the store
    first = _new_process(tmp_path / "1.npz", tmp_path / "store")
    second = _new_process(tmp_path / "2.npz", tmp_path / "store")
    assert first["stored"] >= 1 and first["loaded"] == 0, first
    assert second["loaded"] >= 1 and second["stored"] == 0, second
    for f in ("1.npz", "2.npz"):
        _same_bits(tmp_path / f, plain)
    assert np.all(np.asarray(plain[0].ok))


def test_a_program_from_the_users_jax_cache_is_used_and_not_stored(tmp_path, monkeypatch):
    """With the user's JAX cache on, a program compiled anew is stored (and kept by JAX); one
    that JAX's cache served (a new store: an edited library whose stroke program did not
    change) runs, and is not stored: an executable JAX loaded from its cache, serialised
    again, loses kernels (jaxlib 0.10)."""
    us, g = np.linspace(0.0, 2 * np.pi, 361), np.array([0.4, 1.7])
    monkeypatch.setenv("JAXMECH_EXPORT_CACHE", "0")
    plain = jm.stroke_kinematics(fourbar(), us, P, g)
    jax_cache = tmp_path / "jax-cache"
    compiled = _new_process(tmp_path / "1.npz", tmp_path / "store1", jax_cache)
    served = _new_process(tmp_path / "2.npz", tmp_path / "store2", jax_cache)
    assert compiled["stored"] >= 1, compiled
    assert served["stored"] == 0 and served["loaded"] == 0, served
    assert not (tmp_path / "store2" / "executables").exists() or not any((tmp_path / "store2" / "executables").glob("*.jaxexec"))
    for f in ("1.npz", "2.npz"):
        _same_bits(tmp_path / f, plain)


_NEW_SCENE_PROCESS = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
from jaxmech.scenes import get_scene, run_scene
from jaxmech._compile.stored import store_stats, wait_for_stores
table = run_scene(get_scene("sma_flap"), 101).table()
np.savez(sys.argv[1], **{str(i): np.asarray(v) for i, v in enumerate(table.values())})
wait_for_stores()
print(json.dumps(store_stats()))
"""


def test_a_new_process_runs_a_scenes_two_stored_programs_bit_for_bit(tmp_path, monkeypatch):
    """``run_scene``'s two programs (the stroke, then kinematics and outputs, compiled at once
    on two threads) are stored by a first process; a second loads both and gives the same
    table, bit for bit, as the two programs compiled without the store."""
    from jaxmech.scenes import get_scene, run_scene

    monkeypatch.setenv("JAXMECH_EXPORT_CACHE", "0")
    plain = run_scene(get_scene("sma_flap"), 101).table()  # compiled for this process only
    first = _new_process(tmp_path / "1.npz", tmp_path / "store", script=_NEW_SCENE_PROCESS)
    second = _new_process(tmp_path / "2.npz", tmp_path / "store", script=_NEW_SCENE_PROCESS)
    assert first["stored"] >= 2, first
    assert second["loaded"] >= 2 and second["stored"] == 0, second
    for f in ("1.npz", "2.npz"):
        r = np.load(tmp_path / f)
        assert len(r.files) == len(plain)
        for i, name in enumerate(plain):
            np.testing.assert_array_equal(r[str(i)], np.asarray(plain[name]), err_msg=name)


_ROOM_PROCESS = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
from jaxmech.scenes import get_scene, run_scene
from jaxmech._compile import room, stored
first = run_scene(get_scene("fourbar"), 37).table()
stored.wait_for_stores()
far = room.make_room(limit=10**9)
before = room.map_count()
released = room.make_room(limit=before)
after = room.map_count()
again = run_scene(get_scene("fourbar"), 37).table()
same = all(np.array_equal(np.asarray(first[k]), np.asarray(again[k]), equal_nan=True) for k in first)
print(json.dumps(dict(far=far, released=released, before=before, after=after, same=same, **stored.store_stats())))
"""


def test_compiled_code_is_released_near_the_limit_on_mappings(tmp_path):
    """A process near the kernel's limit on memory mappings (``vm.max_map_count``) dies in
    its next compile; ``make_room`` releases the compiled programs first: far from the
    limit it does nothing, past ``ROOM`` of it the process's mappings drop, and the scene
    then runs again (its programs loaded from the store) to the same table."""
    if sys.platform != "linux":
        pytest.skip("memory mappings are counted on Linux only")
    env = dict(os.environ, JAXMECH_COMPILE_CACHE=str(tmp_path / "store"))
    out = subprocess.run([sys.executable, "-c", _ROOM_PROCESS], env=env, capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert not r["far"] and r["released"], r
    assert r["after"] < r["before"] - 50, r  # a scene's compiled code maps a few hundred
    assert r["same"] and r["loaded"] >= 2, r


def _watt(shift=0.0, scale=1.0):
    """A Watt six-bar drawn with its joints at the given coordinates (moved by `shift` and
    scaled by `scale`: another drawing of the same topology)."""
    pts = {"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)}
    pts = {k: ((x + shift) * scale, (y - shift) * scale) for k, (x, y) in pts.items()}
    return jm.Linkage(pts, {"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "O6 F"},
                      ground="O2 O4 O6", driver="crank", mass={"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 2.5}, gravity=9.81)


def test_a_new_drawing_of_a_compiled_topology_compiles_nothing():
    s = np.linspace(0.0, 2 * np.pi, 40)
    drive = jm.Samples(1.2 + 0.8 * np.sin(s), 0.8 * np.cos(s), -0.8 * np.sin(s))
    first = _watt().inverse_dynamics(drive)
    other = _watt(shift=0.3, scale=1.1)
    assert other.mechanism == _watt().mechanism and other.model is _watt().model
    COUNTER.n, COUNTER.on = 0, True
    try:
        second = other.inverse_dynamics(drive)
    finally:
        COUNTER.on = False
    assert COUNTER.n == 0, f"{COUNTER.n} programs compiled for a new drawing of a compiled topology"
    assert np.all(np.asarray(first.status) == 0) and np.all(np.asarray(second.status) == 0)
    # the new drawing really is another linkage: a scaled copy turns the same way, with
    # reactions that scale as forces do (masses unchanged, lengths x1.1)
    np.testing.assert_allclose(np.asarray(second.q), np.asarray(first.q), rtol=0, atol=1e-9)
    assert not np.allclose(np.asarray(second.tau), np.asarray(first.tau))


def test_a_program_that_calls_lapack_is_not_stored():
    """An executable with a LAPACK custom call crashes the process that loads it (jaxlib 0.10):
    it runs here and is never written; a LAPACK-free one is."""
    from jaxmech._compile import stored

    if stored.store_dir() is None:
        pytest.skip("the store is switched off in this environment")
    a, b = jnp.eye(3) * 2.0, jnp.ones(3)
    assert stored.calls_lapack(jax.jit(jnp.linalg.solve).lower(a, b).compile())
    assert not stored.calls_lapack(jax.jit(jnp.matmul).lower(a, b).compile())
    # programs of their own, new to every cache (a constant drawn per run): compiled here,
    # through the store, not found in the suite's JAX cache
    k = float(np.random.default_rng().uniform(1.0, 2.0))  # static: part of the store's key

    def scaled_solve(k, a, b):  # the store keys a program by its function's name
        return jnp.linalg.solve(a, b) * k

    def scaled_product(k, a, b):
        return (a @ b) * k

    solve, plain = jax.jit(scaled_solve, static_argnums=0), jax.jit(scaled_product, static_argnums=0)
    before = stored.store_stats()["stored"]
    np.testing.assert_allclose(np.asarray(stored.cached_call(solve, (k,), (a, b))), 0.5 * k)
    stored.wait_for_stores()
    assert stored.store_stats()["stored"] == before
    np.testing.assert_allclose(np.asarray(stored.cached_call(plain, (k,), (a, b))), 2.0 * k)
    stored.wait_for_stores()
    assert stored.store_stats()["stored"] == before + 1


def test_determinants_without_lapack_match_numpy():
    """The automatic assembly-mode indicator of a block larger than 3x3 is its determinant by
    elimination (no LAPACK call in a stored program)."""
    from jaxmech.solver.linalg import det_small

    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 5, 6):
        for _ in range(5):
            a = rng.normal(size=(n, n))
            assert abs(float(det_small(jnp.asarray(a))) - np.linalg.det(a)) <= 1e-12 * max(1.0, abs(np.linalg.det(a)))
    swap = np.array([[0.0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])  # needs a pivot
    assert float(det_small(jnp.asarray(swap))) == -1.0


def test_enable_default_cache_is_deprecated_and_respects_the_switch(monkeypatch):
    """The old import-time switch still works when called, with a DeprecationWarning that
    names its replacement; switched off, it changes nothing."""
    import pytest

    from jaxmech._compile.cache import enable_default_cache

    monkeypatch.setenv("JAXMECH_COMPILE_CACHE", "0")
    before = dict(jax.config.values)
    with pytest.warns(DeprecationWarning, match="enable_compile_cache"):
        enable_default_cache()
    assert dict(jax.config.values) == before


def test_a_model_of_the_librarys_parts_has_a_store_key_and_one_with_a_callback_has_none():
    """A ``Model`` without ``program_key`` is known by its parts: two equal ones in any
    process have one key (its inverse-dynamics program is stored), a different gravity
    direction (a complex number) another, and a load with a function of the user's none."""
    from jaxmech._compile.stored import static_token

    def model(direction=-1j, loads=()):
        return jm.Model(fourbar(), loads=(jm.Gravity(direction=direction),) + tuple(loads), params=("g",))

    a, b = static_token(model()), static_token(model())
    assert a is not None and a == b
    assert static_token(model(direction=-1.0)) not in (None, a)
    assert static_token(model(loads=(jm.Moment("theta3", lambda q, u, p: 1.0),))) is None


def test_a_loaded_executable_that_cannot_run_is_compiled_anew_and_never_loaded_again(monkeypatch):
    """A stored executable this runtime loads but cannot run (a kernel missing after
    deserialisation, its error raised only when the result is waited for) is run through
    the jit path instead, with the right answer; a tombstone then keeps the key from being
    loaded or stored again."""
    from jaxmech._compile import stored

    folder = stored.store_dir()
    if folder is None:
        import pytest

        pytest.skip("the store is switched off in this environment")
    k = float(np.random.default_rng().uniform(1.0, 2.0))  # static: a key of its own

    def scaled_sum(k, a):  # the store keys a program by its function's name
        return a * k + 1.0

    fn = jax.jit(scaled_sum, static_argnums=0)
    a = jnp.arange(3.0)

    class Broken:
        def block_until_ready(self):
            raise RuntimeError("NOT_FOUND: Function iota.455_kernel not found")

    loads = []

    def fake_load(path):
        loads.append(path)
        return lambda *args: Broken()

    monkeypatch.setattr(stored, "_load", fake_load)
    np.testing.assert_allclose(np.asarray(stored.cached_call(fn, (k,), (a,))), np.arange(3.0) * k + 1.0)
    assert len(loads) == 1
    tombstones = list(folder.glob("*.unloadable"))
    assert any(t.stem == loads[0].stem for t in tombstones)
    stored._PROGRAMS.clear()  # as a new process: the tombstone, not the file, answers
    np.testing.assert_allclose(np.asarray(stored.cached_call(fn, (k,), (a,))), np.arange(3.0) * k + 1.0)
    assert len(loads) == 1
    stored.wait_for_stores()
    assert not loads[0].exists()  # and the freshly compiled program was not stored
