"""The README's example runs as written, and its set-up commands are the ones CI runs."""

import re
from pathlib import Path

import jax
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_readme_example_runs_and_its_torque_is_the_power_balance():
    text = (ROOT / "README.md").read_text()
    code = re.findall(r"```python\n(.*?)```", text, flags=re.S)[0]
    ns: dict = {}
    exec(compile(code, "README.md", "exec"), ns)  # noqa: S102 - the README is ours
    res, p, jm, jnp = ns["res"], ns["p"], ns["jm"], ns["jnp"]
    assert np.all(np.asarray(res.status) == jm.Status.CONVERGED)
    # tau * u_dot = dT/dt + dV/dt (no other loads): check by differences along the stroke
    model = ns["model"]
    t = np.linspace(0, 2 * np.pi, 361)
    energy = lambda q, u, ud: jm.kinetic_energy(model, q, u, ud, p) + jm.potential_energy(model, q, u, p)  # noqa: E731
    e = np.asarray(jax.jit(jax.vmap(energy))(res.q, res.u, res.u_dot))  # one program, not 361 eager calls
    de = np.gradient(e, t, edge_order=2)
    tau = np.asarray(res.tau[:, 0])
    scale = np.max(np.abs(tau))
    assert np.max(np.abs(tau[5:-5] - de[5:-5])) < 1e-3 * scale  # second-order differences on a 1-degree grid
    assert np.isfinite(float(ns["dtheta4_da"]))


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    blocks = re.findall(r"```\n(.*?)\n```", readme, flags=re.S)
    test_cmd = [b for b in blocks if "pytest" in b][0].strip()
    assert test_cmd in ci
