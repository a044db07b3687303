"""The library leaves the process as it found it: ``import jaxmech`` and its calls (a solve,
a stroke, stroke kinematics, inverse dynamics, a scene run, an in-process sweep) change no
``jax.config`` value, whether they compile and store their programs or load them, and whether
JAX's persistent cache is off (the default) or the user's own."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Run in a fresh interpreter: x64 is the script's own choice, made before the snapshot.
_SCRIPT = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
if sys.argv[1] != "-":
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])  # the user's own JAX cache
before = {k: repr(v) for k, v in jax.config.values.items()}
import numpy as np
import jax.numpy as jnp
import jaxmech as jm
from jaxmech.scenes import get_scene, run_scene
from jaxmech._compile.stored import store_stats, wait_for_stores
from jaxmech.sweep import sweep_scene
after_import = {k: repr(v) for k, v in jax.config.values.items()}
scene = get_scene("fourbar")  # a registry scene: its programs are stored
fourbar, p = scene.mechanism, dict(scene.defaults)
g = np.asarray(scene.guess(p))
us = np.linspace(0.0, 2 * np.pi, 61)
one = jm.solve(fourbar, 0.5, p, g)
stroke = jm.solve_stroke(fourbar, us, p, g)
sol, d1, d2 = jm.stroke_kinematics(fourbar, us, p, g)
model = jm.Model(fourbar, bodies=[jm.Body("P", 2.0, angle="theta3", inertia=1.5)], loads=[jm.Gravity(9.81)])
inv = jm.inverse_dynamics(model, jm.ConstantSpeed(0.0, 1.0), np.linspace(0.0, 2 * np.pi, 61), p, g)
table = run_scene(scene, 21).table()
sweep = sweep_scene("fourbar", {"a": [0.9, 1.0, 1.1]}, points=21, progress=False)
jax.block_until_ready((one.q, stroke.q, d2, inv.tau))
wait_for_stores()
after = {k: repr(v) for k, v in jax.config.values.items()}
print(json.dumps({
    "changed_by_import": {k: [before.get(k), v] for k, v in after_import.items() if before.get(k) != v},
    "changed": {k: [before.get(k), v] for k, v in after.items() if before.get(k) != v},
    "ok": bool(np.all(np.asarray(stroke.ok)) and np.all(np.asarray(sol.ok)) and np.all(np.asarray(inv.status) == 0)),
    "theta4_at_0": float(np.asarray(stroke.q)[0, 1]),
    "designs": int(sweep.n_designs), "sweep_ok": bool(np.all(sweep.ok)),
    "stats": store_stats(),
}))
"""


def _run(store: Path, jax_cache: str = "-") -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "JAXMECH_EXPORT_CACHE")}
    env.update(JAXMECH_COMPILE_CACHE=str(store), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _SCRIPT, jax_cache], env=env, capture_output=True, text=True,
                         timeout=600, cwd=ROOT)  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _theta4_at_zero(a=1.0, b=3.0, c=2.5, d=3.5):
    """Open four-bar at theta2 = 0: the law of cosines at O4 (independent of the solver)."""
    import math

    f = d - a
    return math.pi - math.acos((c * c + f * f - b * b) / (2 * c * f))


def test_import_and_calls_leave_every_jax_config_value_unchanged(tmp_path):
    store = tmp_path / "store"
    first = _run(store)  # compiles and stores the library's programs
    second = _run(store)  # loads them
    assert first["stats"]["stored"] >= 1 and second["stats"]["loaded"] >= 1, (first["stats"], second["stats"])
    for res in (first, second):
        assert res["changed_by_import"] == {}
        assert res["changed"] == {}
        assert res["ok"] and res["designs"] == 3 and res["sweep_ok"]
        assert abs(res["theta4_at_0"] - _theta4_at_zero()) < 1e-12
    # with the user's JAX cache on, the same (the store watches JAX's cache hits meanwhile)
    theirs = _run(tmp_path / "store2", str(tmp_path / "jax-cache"))
    assert theirs["changed_by_import"] == {} and theirs["changed"] == {} and theirs["ok"]
