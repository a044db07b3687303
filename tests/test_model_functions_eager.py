"""The public model functions (``mass_matrix``, ``generalized_forces``, ``kinetic_energy``,
``potential_energy``) called eagerly compile once per model and shapes: a second call with
new values compiles nothing (counted, never timed), and gives the same numbers as the same
function traced inside a user's ``jax.jit``; the effort by virtual power equals the joints'
Newton-Euler effort of ``Linkage.inverse_dynamics`` (another computation)."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxmech as jm  # noqa: E402

LK = jm.Linkage(points={"O": (0, 0), "A": (0.3, 0.4), "B": (1.2, 0.0)}, links={"crank": "O A", "rod": "A B"}, ground="O",
                sliders={"B": {"angle": "0deg"}}, driver="crank", mass={"crank": 1.0, "rod": 2.0, "block_B": 0.5}, gravity=9.81)


def _compiles(fn):
    return fn._cache_size()


def test_eager_calls_compile_once_and_agree_with_a_users_jit_and_newton_euler():
    model, p = LK.model, LK.params
    res = LK.inverse_dynamics(jm.ConstantSpeed(0.9, 1.3), np.linspace(0.0, 1.0, 6))
    calls = {
        jm.mass_matrix: lambda i: (model, res.q[i], res.u[i], p),
        jm.generalized_forces: lambda i: (model, res.q[i], res.u[i], res.u_dot[i], res.u_ddot[i], p),
        jm.kinetic_energy: lambda i: (model, res.q[i], res.u[i], res.u_dot[i], p),
        jm.potential_energy: lambda i: (model, res.q[i], res.u[i], p),
    }
    for fn, args in calls.items():
        fn(*args(0))
        before = _compiles(fn)
        eager = [fn(*args(i)) for i in range(1, 6)]
        assert _compiles(fn) == before, f"{fn.__name__}: an eager call with new values compiled again"
        traced = jax.jit(lambda *a, fn=fn: fn(model, *a))
        for i, e in zip(range(1, 6), eager):
            want = traced(*args(i)[1:])
            for a, b in zip(jax.tree_util.tree_leaves(e), jax.tree_util.tree_leaves(want)):
                np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-13, atol=1e-13)
    tau = np.array([float(jm.generalized_forces(model, res.q[i], res.u[i], res.u_dot[i], res.u_ddot[i], p)[0][0]) for i in range(6)])
    np.testing.assert_allclose(tau, np.asarray(res.tau[:, 0]), rtol=1e-10, atol=1e-12 * np.max(np.abs(tau)))
