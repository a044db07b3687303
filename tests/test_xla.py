"""The CPU fusion workaround (jaxmech.solver.xla.unfused) does what it is there for: fewer sine
evaluations in the compiled residual-and-Jacobian program, the same values."""

import warnings
import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
import jaxmech.solver.xla as xla  # noqa: E402


def _program(mech, p):
    """Residual, Jacobian and a second directional derivative of one sample, vmapped."""

    def one(q, u):
        r = mech.residual(q, u, p)
        j = jax.jacfwd(mech.residual)(q, u, p)
        h = jax.jvp(lambda q_: jax.jvp(lambda x: mech.residual(x, u, p), (q_,), (j[0],))[1], (q,), (j[1],))[1]
        return r, j, h

    return jax.jit(jax.vmap(one))


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the workaround is limited to the CPU backend")
def test_unfused_saves_sines_on_cpu(monkeypatch):
    def mech():  # a fresh mechanism each time: the trace must be taken anew
        return jm.Mechanism(
            coords=("theta3", "theta4"), inputs=("theta2",), params=("a", "b", "c", "d"), lengths=("a", "b", "c", "d"),
            constraints=lambda q, u, p: [p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d],
            name=f"fourbar{np.random.randint(1 << 30)}",
        )  # fmt: skip

    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    q = jnp.asarray(np.random.default_rng(0).uniform(-3, 3, (64, 2)))
    u = jnp.linspace(0.0, 6.0, 64)[:, None]

    def compiled():
        f = _program(mech(), p)
        text = f.lower(q, u).compile().as_text()
        return f(q, u), text.count(" sine(") + text.count(" cosine(")

    with_it, n_with = compiled()
    monkeypatch.setattr(xla, "_on_cpu", lambda: False)
    without, n_without = compiled()
    assert n_with < n_without, (n_with, n_without)  # measured: 6 against 14
    for a, b in zip(jax.tree_util.tree_leaves(with_it), jax.tree_util.tree_leaves(without)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-15, atol=1e-15)


#: How far the classic CPU emitters may round differently from the default ones, in units of
#: the float64 epsilon relative to the largest value of each output (measured: 0 for fourbar,
#: landing_gear and arc_track_flap; 4.8 for flap_msd; 7.0 for sma_flap).
ROUNDING_EPS = 16


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the options are the CPU compiler's; other backends refuse them")
# flap_msd left out: XLA's default CPU options (the fusion emitters) segfaulted compiling its
# stroke in CI (jaxlib 0.10.2, backend_compile, 2026-11-28); the library never compiles with them
@pytest.mark.parametrize("scene_name", ["fourbar", "sma_flap"])
def test_compiler_options_give_the_same_values(scene_name):
    """The library compiles its programs with ``xla.COMPILER_OPTIONS`` (the classic CPU
    emitters, for compile time): a whole stroke with its derivatives and points comes out as
    XLA's default options give it, with the same statuses and values equal to rounding."""
    from jaxmech.scenes import get_scene
    from jaxmech.sweep.evaluate import design_motion

    scene = get_scene(scene_name)
    p = scene.params()

    def motion(p_):
        return design_motion(scene, 41, p_)

    with_options = jax.jit(motion, compiler_options=xla.COMPILER_OPTIONS)(p)
    default = jax.jit(motion)(p)
    assert bool(jnp.all(with_options[1]))  # every sample converged: the values are real
    np.testing.assert_array_equal(np.asarray(with_options[0].status), np.asarray(default[0].status))
    eps = np.finfo(np.float64).eps
    for a, b in zip(jax.tree_util.tree_leaves(with_options), jax.tree_util.tree_leaves(default)):
        a, b = np.asarray(a), np.asarray(b)
        scale = float(np.max(np.abs(b))) if b.size else 0.0
        np.testing.assert_allclose(a, b, rtol=0, atol=ROUNDING_EPS * eps * scale)


def test_other_backends_compile_without_the_cpu_options(monkeypatch):
    """A GPU refuses the CPU compiler's options (``No such compile option``, seen on an H200):
    off the CPU a top-level call, ``lower`` and ``trace`` go to the plain ``jax.jit``."""
    f = xla.jit(lambda x: 2.0 * x + 1.0)

    def refuse(*args, **kwargs):
        raise RuntimeError("INVALID_ARGUMENT: No such compile option: 'xla_cpu_use_fusion_emitters'")

    monkeypatch.setattr(f, "_top", type("Refusing", (), {"__call__": refuse, "lower": refuse, "trace": refuse})())
    monkeypatch.setattr(xla, "_on_cpu", lambda: False)
    assert float(f(jnp.asarray(3.0))) == 7.0
    assert "mul" in f.lower(jnp.asarray(3.0)).as_text()
    monkeypatch.setattr(xla, "_on_cpu", lambda: True)  # on the CPU the options' program is the one called
    with pytest.raises(RuntimeError, match="No such compile option"):
        f(jnp.asarray(3.0))


def test_a_cpu_compiler_that_refuses_the_options_compiles_with_its_defaults(tmp_path):
    """jaxlib 0.11.2's CPU compiler refuses ``xla_cpu_use_fusion_emitters`` as the GPU's does
    (every library program failed there): a compiler that does not know an option of
    ``COMPILER_OPTIONS`` is found once, and the library's programs (a stroke, a scene's two
    programs through the store) compile with its defaults and give the same statuses. Here
    an option no compiler knows stands for it, in a new process with a store of its own."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = (
        "import jax, numpy as np\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "import jaxmech.solver.xla as x\n"
        "x.COMPILER_OPTIONS['xla_cpu_no_such_option_in_any_compiler'] = True\n"
        "import jaxmech as jm\n"
        "from jaxmech.scenes import run_scene\n"
        "from jaxmech.scenes.classic import fourbar_mechanism\n"
        "q, qd, qdd = jm.stroke_kinematics(fourbar_mechanism, np.linspace(0, 6.28, 37), dict(a=1.0, b=3.0, c=2.5, d=3.5), np.array([0.4, 1.7]))\n"
        "r = run_scene('fourbar', points=37)\n"
        "print(x._with_options(), jm.status_counts(q.status), jm.status_counts(r.motion.status))\n"
    )
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "JAXMECH_COMPILE_CACHE": str(tmp_path), "PYTHONPATH": str(root)}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split("\n")[-2] == "False {'CONVERGED': 37} {'CONVERGED': 37}", out.stdout


def test_the_installed_jax_sums_a_vmapped_product_right():
    """jaxlib 0.10.2 (excluded by pyproject.toml) summed a vmapped 3x3 matrix-vector product
    wrong under jit on the CPU from 16,385 rows (jax-ml/jax#39103, 0.8% off in float64): the
    shape of every batched residual here.  Row ``i`` is ``(i, 0, 0)``: the sum is ``i**2``."""
    n = 16_385
    i = jnp.arange(n, dtype=jnp.float64)
    x = jnp.stack((i, jnp.zeros_like(i), jnp.zeros_like(i)), axis=1)
    f = jax.jit(lambda x: jax.vmap(lambda row: jnp.sum((jnp.eye(3) @ row) ** 2))(x))
    np.testing.assert_array_equal(np.asarray(f(x)), np.arange(n, dtype=np.float64) ** 2)


def test_a_jaxlib_that_computes_wrong_values_is_warned_at_import(monkeypatch):
    from importlib import metadata

    monkeypatch.setattr(metadata, "version", lambda name: "0.10.2")
    with pytest.warns(RuntimeWarning, match=r"jaxlib 0.10.2 computes wrong values .*jax-ml/jax#39103.*pip install 'jax!=0.10.2'"):
        xla.warn_if_wrong_jaxlib()
    monkeypatch.setattr(metadata, "version", lambda name: "0.10.1")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        xla.warn_if_wrong_jaxlib()


def _module_level(k, x):
    return x * k


def test_the_store_serves_module_level_programs_only_and_gives_their_values(monkeypatch):
    """The runner (the executable store, installed by ``import jaxmech``) is handed a
    program's top-level call only where a key can determine it: a module-level function
    whose static arguments lead.  A closure (its captured value is in no key), static
    arguments that do not lead or are named, and traced calls go straight to JAX; every
    route gives the function's own value."""
    assert xla._RUNNER[0] is not None  # import jaxmech installed the store
    handed = []

    def runner(fn, n_static, args):
        handed.append((fn.__name__, n_static))
        return fn.direct(*args)

    monkeypatch.setattr(xla, "_RUNNER", [runner])
    scale = 3.0
    closure = xla.jit(lambda x: x * scale)
    leading = xla.jit(_module_level, static_argnums=(0,))
    trailing = xla.jit(lambda x, k: x * k, static_argnums=(1,))
    named = xla.jit(_module_level, static_argnames=("k",))
    x = jnp.arange(3.0)
    np.testing.assert_allclose(np.asarray(closure(x)), 3.0 * np.arange(3.0))
    np.testing.assert_allclose(np.asarray(trailing(x, 2)), 2.0 * np.arange(3.0))
    np.testing.assert_allclose(np.asarray(named(k=4, x=x)), 4.0 * np.arange(3.0))
    assert handed == []
    np.testing.assert_allclose(np.asarray(leading(5, x)), 5.0 * np.arange(3.0))
    assert handed == [("_module_level", 1)]
    np.testing.assert_allclose(np.asarray(jax.jit(lambda y: leading(5, y))(x)), 5.0 * np.arange(3.0))  # traced
    np.testing.assert_allclose(float(jax.grad(lambda y: leading(5, y).sum())(x)[0]), 5.0)
    assert handed == [("_module_level", 1)]
