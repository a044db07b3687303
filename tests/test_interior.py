"""The interior-point method with exact Hessians (``jaxmech.design.interior``) on problems with
known solutions, several starts in one vmapped program: Hock-Schittkowski 71, a Rosenbrock
valley cut by a disc, a start that cannot be evaluated."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxmech.design.interior import IPStatus, cholesky_small, interior_point, second_order  # noqa: E402


def hs071(x):
    """min x1 x4 (x1 + x2 + x3) + x3  s.t.  x1 x2 x3 x4 >= 25,  sum x^2 = 40,  1 <= x <= 5."""
    f = x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2]
    h = jnp.array([jnp.sum(x**2) - 40.0])
    g = jnp.concatenate([jnp.array([25.0 - jnp.prod(x)]), x - 5.0, 1.0 - x])
    return f, h, g, jnp.asarray(True)


HS071_X = np.array([1.0, 4.74299963, 3.82114998, 1.37940829])  # the published optimum, f = 17.0140173


def test_hs071_from_three_starts_in_one_program():
    evaluate, _ = second_order(hs071, 1)
    starts = jnp.array([[1.0, 5.0, 5.0, 1.0], [2.0, 2.0, 2.0, 2.0], [4.5, 1.5, 3.0, 1.2]])
    st, pulled = jax.jit(jax.vmap(lambda x0: interior_point(evaluate, x0, 1, 9)))(starts)
    assert np.all(np.asarray(st.status) == IPStatus.CONVERGED), np.asarray(st.status)
    assert np.all(np.asarray(st.error) <= 1e-8)
    np.testing.assert_allclose(np.asarray(st.x), np.broadcast_to(HS071_X, (3, 4)), atol=2e-8)
    np.testing.assert_allclose(np.asarray(st.f), 17.0140173, rtol=1e-8)
    assert np.all(np.asarray(pulled) == 0)


def test_a_constrained_valley_and_a_start_that_cannot_be_evaluated():
    def valley(x):
        f = (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2
        return f, jnp.zeros((0,)), jnp.array([x[0] ** 2 + x[1] ** 2 - 1.5]), jnp.asarray(True)

    evaluate, _ = second_order(valley, 0)
    st, _ = jax.jit(jax.vmap(lambda x0: interior_point(evaluate, x0, 0, 1)))(jnp.array([[-1.2, 1.0], [0.0, 0.0], [1.0, -1.0]]))
    assert np.all(np.asarray(st.status) == IPStatus.CONVERGED)
    # the exact optimum: the KKT system on the disc (grad f + lam grad g = 0, g = 0), solved
    # by scipy; an interior point stops on the barrier's last mu, its constraint slack
    # mu / lam ~ 1e-8: positions agree to about that
    from scipy.optimize import fsolve

    def kkt(v):
        x, y, lam = v
        return [-2 * (1 - x) - 400 * x * (y - x * x) + 2 * lam * x, 200 * (y - x * x) + 2 * lam * y, x * x + y * y - 1.5]

    exact = fsolve(kkt, [0.9, 0.8, 0.1], xtol=1e-14)
    assert exact[2] > 0 and max(abs(v) for v in kkt(exact)) < 1e-12
    np.testing.assert_allclose(np.asarray(st.x), np.broadcast_to(exact[:2], (3, 2)), atol=1e-7)

    def positive_only(x):  # cannot be evaluated where x <= 0: the start moves towards ref
        return jnp.sum((x - 2.0) ** 2), jnp.zeros((0,)), jnp.array([x[0] + x[1] - 3.0]), jnp.all(x > 0)

    evaluate, _ = second_order(positive_only, 0)
    st, pulled = jax.jit(jax.vmap(lambda x0: interior_point(evaluate, x0, 0, 1, ref=jnp.array([1.0, 1.0]))))(jnp.array([[-3.0, -1.0], [0.5, 0.5]]))
    assert np.all(np.asarray(st.status) == IPStatus.CONVERGED)
    np.testing.assert_allclose(np.asarray(st.x), 1.5, atol=1e-8)
    assert list(np.asarray(pulled)) == [3, 0]


def test_cholesky_without_lapack():
    a = np.random.default_rng(1).normal(size=(6, 6))
    spd = a @ a.T + 6 * np.eye(6)
    L, ok = cholesky_small(jnp.asarray(spd))
    assert bool(ok)
    np.testing.assert_allclose(np.asarray(L), np.linalg.cholesky(spd), rtol=1e-12, atol=1e-12)
    _, ok = cholesky_small(jnp.asarray(spd - 20 * np.eye(6)))
    assert not bool(ok)
