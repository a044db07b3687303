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


def test_readme_linkage_example_runs_and_balances_every_body():
    """The README's linkage example as written: every sample converged, and the reactions it
    prints balance the crank (ground pivot O2, pin A, drive torque, gravity, inertia)."""
    text = (ROOT / "README.md").read_text()
    first, second = re.findall(r"```python\n(.*?)```", text, flags=re.S)[:2]
    ns: dict = {}
    exec(compile(first + second, "README.md", "exec"), ns)  # noqa: S102 - the README is ours
    res, hold, jm, watt = ns["res"], ns["hold"], ns["jm"], ns["watt"]
    assert np.all(np.asarray(res.status) == jm.Status.CONVERGED) and np.all(np.asarray(hold.status) == jm.Status.CONVERGED)
    p = watt.params
    m, _, J = watt.mass_properties()["crank"]
    g = p["g"]
    # crank: F_O2 (ground on crank) - F_A (crank on coupler) + m g = m a_G; moments about G_crank
    G, _, aG = (np.asarray(x) for x in res.points["G_crank"])
    A, O2 = np.asarray(res.points["A"][0]), np.asarray(res.points["O2"][0])
    FO2, FA = np.asarray(res.joints["O2"]), np.asarray(res.joints["A"])
    alpha = np.asarray(res.u_ddot[:, 0])
    force = FO2 - FA - 1j * m * g - m * aG
    cross = lambda r, f: r.real * f.imag - r.imag * f.real  # noqa: E731
    moment = cross(O2 - G, FO2) - cross(A - G, FA) + np.asarray(res.tau[:, 0]) - J * alpha
    scale = np.max(np.abs(FA))
    assert np.max(np.abs(force)) < 1e-10 * scale and np.max(np.abs(moment)) < 1e-10 * scale
