"""The SQP with exact Hessians (``jaxmech.design.sqp``) and its QP subproblems (``design.qp``)
on problems with known solutions, several starts in one vmapped program: Hock-Schittkowski
71, a Rosenbrock valley cut by a disc, a start that cannot be evaluated, random convex QPs
against scipy."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from jaxmech import Status  # noqa: E402
from jaxmech.design.nlp import cholesky_small, second_order  # noqa: E402
from jaxmech.design.qp import solve_qp  # noqa: E402
from jaxmech.design.sqp import queue, sqp  # noqa: E402


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
    st, pulled = jax.jit(jax.vmap(lambda x0: sqp(evaluate, x0, jnp.zeros(1), jnp.zeros(9))))(starts)
    assert np.all(np.asarray(st.status) == Status.CONVERGED), np.asarray(st.status)
    assert np.all(np.asarray(st.error) <= 1e-8)
    np.testing.assert_allclose(np.asarray(st.x), np.broadcast_to(HS071_X, (3, 4)), atol=1e-8)
    np.testing.assert_allclose(np.asarray(st.f), 17.0140173, rtol=1e-8)
    assert np.all(np.asarray(pulled) == 0)


def test_a_constrained_valley_and_a_start_that_cannot_be_evaluated():
    def valley(x):
        f = (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2
        return f, jnp.zeros((0,)), jnp.array([x[0] ** 2 + x[1] ** 2 - 1.5]), jnp.asarray(True)

    evaluate, _ = second_order(valley, 0)
    st, _ = jax.jit(jax.vmap(lambda x0: sqp(evaluate, x0, jnp.zeros(0), jnp.zeros(1))))(jnp.array([[-1.2, 1.0], [0.0, 0.0], [1.0, -1.0]]))
    assert np.all(np.asarray(st.status) == Status.CONVERGED)
    # the exact optimum: the KKT system on the disc (grad f + lam grad g = 0, g = 0), solved
    # by scipy
    from scipy.optimize import fsolve

    def kkt(v):
        x, y, lam = v
        return [-2 * (1 - x) - 400 * x * (y - x * x) + 2 * lam * x, 200 * (y - x * x) + 2 * lam * y, x * x + y * y - 1.5]

    exact = fsolve(kkt, [0.9, 0.8, 0.1], xtol=1e-14)
    assert exact[2] > 0 and max(abs(v) for v in kkt(exact)) < 1e-12
    np.testing.assert_allclose(np.asarray(st.x), np.broadcast_to(exact[:2], (3, 2)), atol=1e-9)
    np.testing.assert_allclose(np.asarray(st.z)[:, 0], exact[2], rtol=1e-7)

    def positive_only(x):  # cannot be evaluated where x <= 0: the start moves towards ref
        return jnp.sum((x - 2.0) ** 2), jnp.zeros((0,)), jnp.array([x[0] + x[1] - 3.0]), jnp.all(x > 0)

    evaluate, _ = second_order(positive_only, 0)
    st, pulled = jax.jit(jax.vmap(lambda x0: sqp(evaluate, x0, jnp.zeros(0), jnp.zeros(1), ref=jnp.array([1.0, 1.0]))))(jnp.array([[-3.0, -1.0], [0.5, 0.5]]))
    assert np.all(np.asarray(st.status) == Status.CONVERGED)
    np.testing.assert_allclose(np.asarray(st.x), 1.5, atol=1e-9)
    assert list(np.asarray(pulled)) == [3, 0]


def test_trial_points_that_cannot_be_evaluated_shorten_the_step():
    """The minimiser lies beside a region where the problem cannot be evaluated (a design
    that does not assemble): the full steps that land there are refused by the line search
    and the start still converges, to the exact optimum."""
    def fenced(x):  # min (x0 - 3)^2 + (x1 - 1)^2 s.t. x0 <= 2; undefined for x0 > 2.5
        return (x[0] - 3.0) ** 2 + (x[1] - 1.0) ** 2, jnp.zeros((0,)), jnp.array([x[0] - 2.0]), x[0] <= 2.5

    evaluate, _ = second_order(fenced, 0)
    st, _ = jax.jit(jax.vmap(lambda x0: sqp(evaluate, x0, jnp.zeros(0), jnp.zeros(1))))(jnp.array([[-6.0, 4.0], [0.0, 0.0]]))
    assert np.all(np.asarray(st.status) == Status.CONVERGED)
    np.testing.assert_allclose(np.asarray(st.x), [[2.0, 1.0], [2.0, 1.0]], atol=1e-10)
    np.testing.assert_allclose(np.asarray(st.z)[:, 0], 2.0, rtol=1e-9)  # the multiplier: 2 (3 - x0) at x0 = 2


def test_convex_qps_against_scipy():
    """Feasible random QPs (one with a variable that enters only linearly, as an epigraph
    variable does): the objective agrees with scipy's SLSQP, and the answer meets the KKT
    conditions within the solver's stated tolerance (``ok_tol`` = 1e-9 of the data's
    size; exactly where the active-set polish applies)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(1)
    solve = jax.jit(solve_qp)
    for trial in range(8):
        n, p, m = 6, 2, 30
        M = rng.normal(size=(n, n))
        H = M @ M.T + 0.1 * np.eye(n)
        A = rng.normal(size=(m, n))
        if trial % 2 == 0:
            H[-1, :] = H[:, -1] = 0.0
            A[:, -1] = -1.0
        g, E, xf = rng.normal(size=n), rng.normal(size=(p, n)), rng.normal(size=n)
        e, b = -E @ xf, -A @ xf - np.abs(rng.normal(size=m)) * (rng.random(m) < 0.7)
        sol = solve(*(jnp.asarray(a) for a in (H, g, E, e, A, b)))
        d, y, z = (np.asarray(a) for a in (sol.d, sol.y, sol.z))
        assert bool(sol.ok)
        ref = minimize(lambda x: 0.5 * x @ H @ x + g @ x, xf, jac=lambda x: H @ x + g, method="SLSQP", options={"ftol": 1e-15, "maxiter": 500},
                       constraints=[{"type": "eq", "fun": lambda x: E @ x + e, "jac": lambda x: E},
                                    {"type": "ineq", "fun": lambda x: -(A @ x + b), "jac": lambda x: -A}])
        assert abs((0.5 * d @ H @ d + g @ d) - ref.fun) <= 1e-9 * (1 + abs(ref.fun))
        tol = 1e-9 * (1 + max(np.max(np.abs(g)), np.max(np.abs(e)), np.max(np.abs(b))))
        assert np.max(np.abs(H @ d + g + E.T @ y + A.T @ z)) < tol
        assert np.max(A @ d + b) < tol and np.max(np.abs(E @ d + e)) < tol and np.min(z) >= 0
        assert np.max(np.abs(z * (A @ d + b))) < tol


def test_cholesky_without_lapack():
    a = np.random.default_rng(1).normal(size=(6, 6))
    spd = a @ a.T + 6 * np.eye(6)
    L, ok = cholesky_small(jnp.asarray(spd))
    assert bool(ok)
    np.testing.assert_allclose(np.asarray(L), np.linalg.cholesky(spd), rtol=1e-12, atol=1e-12)
    _, ok = cholesky_small(jnp.asarray(spd - 20 * np.eye(6)))
    assert not bool(ok)


def test_a_queue_of_starts_on_fewer_lanes_gives_every_starts_answer():
    """Five starts of HS071 on two lanes (each lane takes the next start when its own ends):
    every start's answer, in the starts' order, as the starts solved side by side."""
    evaluate, _ = second_order(hs071, 1)
    starts = jnp.array([[1.0, 5.0, 5.0, 1.0], [2.0, 2.0, 2.0, 2.0], [4.5, 1.5, 3.0, 1.2], [1.2, 4.0, 4.2, 1.1], [3.0, 3.0, 3.0, 3.0]])
    st, _ = jax.jit(jax.vmap(lambda x0: sqp(evaluate, x0, jnp.zeros(1), jnp.zeros(9))))(starts)
    sq, _ = jax.jit(lambda x0: queue(evaluate, x0, jnp.zeros(1), jnp.zeros(9), 2))(starts)
    assert np.all(np.asarray(sq.status) == Status.CONVERGED)
    np.testing.assert_array_equal(np.asarray(sq.k), np.asarray(st.k))
    np.testing.assert_allclose(np.asarray(sq.x), np.asarray(st.x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sq.x), np.broadcast_to(HS071_X, (5, 4)), atol=1e-8)
