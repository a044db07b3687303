"""A mechanism without dependent coordinates (a hinged flap: its one input is its only
coordinate), and parameters declared on the model and its actuators rather than on the
mechanism.

Closed forms: a flap (point mass ``m`` at ``c`` from the hinge, inertia ``J`` about its
centre of mass, ``J_O = J + m c^2``) held by a torsion spring ``k (theta - theta0)``
against a constant moment ``M0``:

- statics: ``theta* = theta0 + M0 / k``, stiffness ``k``, ``d theta*/dk = -M0 / k^2``;
- released at rest from ``theta = 0``: ``theta(t) = theta* (1 - cos w t)``, ``w = sqrt(k / J_O)``,
  so ``theta_dot = theta* w sin w t`` and ``theta_ddot = theta* w^2 cos w t``.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402

TOL_STATIC = 1e-12  # equilibrium angle (rad): a linear equation, Newton's round-off
TOL_RK = 1e-9  # Radau IIA (order 5) at w h = 0.05 over 1.5 periods: measured 2e-10 (5e-9 at w h = 0.1, ~h^5)
TOL_ID = 1e-9  # inverse-dynamics torque of the free motion (N m; torques are ~1 N m)
RTOL_GRAD = 1e-9  # implicit derivative of the equilibrium against its closed form
RTOL_FD_GRAD = 1e-7  # a run's gradient (reverse mode) against its closed form: measured 3e-9 (integration error)

HINGE = jm.Mechanism(name="hinge", coords=(), inputs=("theta",), params=("c",), lengths=("c",),
                     points={"G": lambda q, u, p: p.c * jm.cis(u.theta)})
MODEL = D.Model(
    HINGE,
    bodies=[D.Body("G", "m", angle="theta", inertia="J", name="flap")],
    loads=[D.Moment("theta", lambda q, u, p, v, t: p.M0 - p.k * (u.theta - p.theta0), name="spring and moment")],
    params=("m", "J", "k", "theta0", "M0"),  # the model's own: no constraint uses them
)
P = dict(c=0.3, m=2.0, J=0.01, k=5.0, theta0=0.1, M0=1.5)
THETA_STAR = P["theta0"] + P["M0"] / P["k"]
W = np.sqrt(P["k"] / (P["J"] + P["m"] * P["c"] ** 2))


def test_kinematics_of_a_mechanism_without_dependent_coordinates():
    t = jnp.linspace(0.0, 1.0, 5)
    mo = jm.motion(HINGE, jm.ConstantSpeed(0.2, 2.0), t, {"c": 0.3}, ())
    assert mo.q.shape == (5, 0) and np.all(np.asarray(mo.status) == jm.Status.CONVERGED)
    th = 0.2 + 2.0 * np.asarray(t)
    pos, vel, acc = (np.asarray(x) for x in mo.points["G"])
    np.testing.assert_allclose(pos, 0.3 * np.exp(1j * th), rtol=0, atol=1e-15)
    np.testing.assert_allclose(vel, 0.3 * 2.0 * 1j * np.exp(1j * th), rtol=0, atol=1e-14)
    np.testing.assert_allclose(acc, -0.3 * 4.0 * np.exp(1j * th), rtol=0, atol=1e-14)


def test_statics_of_a_hinge_against_its_closed_form():
    eq = D.equilibrium(MODEL, P, (-1.0, 2.0), ())
    assert int(eq.status) == jm.Status.CONVERGED and eq.q.shape == (0,)
    assert abs(float(eq.u[0]) - THETA_STAR) <= TOL_STATIC
    assert abs(float(eq.stiffness[0, 0]) - P["k"]) <= TOL_STATIC * P["k"]
    dk = jax.grad(lambda k: D.equilibrium(MODEL, {**P, "k": k}, (-1.0, 2.0), ()).u[0])(P["k"])
    assert abs(float(dk) + P["M0"] / P["k"] ** 2) <= RTOL_GRAD * P["M0"] / P["k"] ** 2


def test_forward_and_inverse_dynamics_of_a_hinge_against_its_closed_form():
    tr = D.forward_dynamics(MODEL, P, 0.0, 0.0, (), h=0.05 / W, steps=190)  # 1.5 periods
    assert int(tr.status) == jm.Status.CONVERGED and tr.q.shape == (191, 0)
    wt = W * np.asarray(tr.t)
    np.testing.assert_allclose(np.asarray(tr.u[:, 0]), THETA_STAR * (1 - np.cos(wt)), rtol=0, atol=TOL_RK)
    np.testing.assert_allclose(np.asarray(tr.u_dot[:, 0]), THETA_STAR * W * np.sin(wt), rtol=0, atol=TOL_RK * W)
    # The acceleration: the closed-form motion, driven, needs no torque at any instant.
    free = lambda t: THETA_STAR * (1 - jnp.cos(W * t))  # noqa: E731
    idn = D.inverse_dynamics(MODEL, free, jnp.linspace(0.0, 3.0, 7), P, ())
    np.testing.assert_allclose(np.asarray(idn.u_ddot[:, 0]), THETA_STAR * W**2 * np.cos(W * np.asarray(idn.t)), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(idn.tau[:, 0]), 0.0, rtol=0, atol=TOL_ID)


def test_motor_parameters_declared_only_on_the_motor():
    """A DC motor's resistance and constant and the voltage live in ``p`` without being
    declared by the mechanism or the model.  Steady state with the spring removed and a
    viscous loss ``cv w``: ``K i = cv w``, ``v = R i + K w``, so ``w = v K / (R cv + K^2)``."""
    model = D.Model(HINGE, bodies=[D.Body("G", "m", angle="theta", inertia="J")],
                    loads=[D.Moment("theta", lambda q, u, p, v, t: -p.cv * v.theta)], params=("m", "J", "cv"))
    p = dict(c=0.3, m=2.0, J=0.01, cv=0.05, R_a=2.0, K_m=0.5, V=3.0)
    tr = D.forward_dynamics(model, p, 0.0, 0.0, (), h=0.05, steps=400, motor=jm.DCMotor("R_a", "K_m"), voltage="V")
    assert int(tr.status) == jm.Status.CONVERGED
    w = p["V"] * p["K_m"] / (p["R_a"] * p["cv"] + p["K_m"] ** 2)
    assert abs(float(tr.u_dot[-1, 0]) - w) <= 1e-8 * w
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['R_b'\]"):
        D.forward_dynamics(model, {**p, "R_b": 1.0}, 0.0, 0.0, (), h=0.05, steps=4, motor=jm.DCMotor("R_a", "K_m"), voltage="V")
    with pytest.raises(ValueError, match=r"missing parameter\(s\) \['K_m'\]"):
        D.forward_dynamics(model, {k: v for k, v in p.items() if k != "K_m"}, 0.0, 0.0, (), h=0.05, steps=4,
                           motor=jm.DCMotor("R_a", "K_m"), voltage="V")


def test_model_parameters_merge_by_name_and_clash_clearly():
    assert MODEL.parameters == ("c", "m", "J", "k", "theta0", "M0")
    # a motor attached to the model declares its parameters; a name the mechanism has is shared
    withm = D.Model(HINGE, params=("k",), actuators=[jm.DCMotor("R_a", "c")])
    assert withm.parameters == ("c", "k", "R_a")
    with pytest.raises(ValueError, match="'c' is declared by both the mechanism 'hinge' and the model"):
        D.Model(HINGE, params=("c", "m"))
    with pytest.raises(ValueError, match="'theta' has the name of a coordinate or input"):
        D.Model(HINGE, actuators=[jm.DCMotor("theta", "K")])
    with pytest.raises(ValueError, match=r"unknown parameter 'mass'.*Model\(params=\.\.\.\)"):
        D.Model(HINGE, bodies=[D.Body("G", "mass")])
    with pytest.raises(ValueError, match=r"parameter 'k' must be finite, got nan"):
        D.equilibrium(MODEL, {**P, "k": np.float64("nan")}, (-1.0, 2.0), ())
    with pytest.raises(ValueError, match="length 'c' must be positive, got -1.0"):
        D.equilibrium(MODEL, {**P, "c": np.float64(-1.0)}, (-1.0, 2.0), ())


def test_forward_dynamics_gradient_in_reverse_mode_against_the_closed_form():
    """``jax.grad`` through a whole run: ``theta(T) = theta* (1 - cos w T)`` with
    ``theta* = theta0 + M0/k`` and ``w = sqrt(k / (J + m c^2))`` differentiated by hand in a
    stiffness, a mass and a length."""
    h, steps = 0.05 / W, 190
    T = h * steps

    def final(x):
        return D.forward_dynamics(MODEL, {**P, **x}, 0.0, 0.0, (), h=h, steps=steps).u[-1, 0]

    g = jax.grad(final)({k: P[k] for k in ("k", "m", "c")})
    k, m, c, J_O = P["k"], P["m"], P["c"], P["J"] + P["m"] * P["c"] ** 2
    swing = THETA_STAR * np.sin(W * T) * T  # d theta(T) / d w
    want = {"k": -P["M0"] / k**2 * (1 - np.cos(W * T)) + swing * W / (2 * k),
            "m": swing * (-W / (2 * J_O)) * c**2,
            "c": swing * (-W / (2 * J_O)) * 2 * m * c}
    for name, value in want.items():
        assert abs(float(g[name]) - value) <= RTOL_FD_GRAD * abs(value), (name, float(g[name]), value)


def test_one_implicit_rule_second_order_through_statics_and_forward_dynamics():
    """``implicit.implicit_solution`` (the rule solve, statics and forward dynamics share)
    against finite differences, second order, forward and reverse mode: the equilibrium
    angle in the stiffness and the moment, and one step's final angle and rate in the
    stiffness (the position solve: test_solve's check_grads)."""
    from jax.test_util import check_grads

    def theta_star(k, M0):
        return D.equilibrium(MODEL, {**P, "k": k, "M0": M0}, (-1.0, 2.0), ()).u[0]

    check_grads(theta_star, (P["k"], P["M0"]), order=2, modes=("fwd", "rev"))

    def final(k):
        tr = D.forward_dynamics(MODEL, {**P, "k": k}, 0.2, 0.0, (), h=0.05 / W, steps=1)
        return jnp.stack([tr.u[-1, 0], tr.u_dot[-1, 0]])

    check_grads(final, (P["k"],), order=2, modes=("fwd", "rev"))


def test_implicit_rule_inside_a_scan_second_order_in_reverse_mode():
    """The rule inside ``lax.scan`` (as forward dynamics' steps use it), reverse over
    reverse and forward over reverse, against the closed form: one implicit Euler step
    of ``x' = -k x`` from ``x = 1`` with ``h = 0.1`` solves ``z = -h k (1 + z)``, so
    ``x1 = 1 / (1 + h k)`` and ``d2 x1/dk2 = 2 h^2 / (1 + h k)^3``.  (Without
    ``checkpoint=True``, jax 0.10.2 gives half of it, as it does for
    ``jax.lax.custom_root``.)"""
    from jaxmech.solver.implicit import implicit_solution

    def euler_stage(z, args):
        x, k = args
        return z + 0.1 * k * (x + z)

    def step(x, k):
        z_star = jax.lax.stop_gradient(-0.1 * k * x / (1 + 0.1 * k))  # the solver's root
        return x + implicit_solution(euler_stage, z_star, jnp.asarray(True), (x, k), checkpoint=True), None

    def x1(k):
        return jax.lax.scan(lambda x, _: step(x, k), jnp.ones(1), None, length=1)[0][0]

    k = 2.0
    exact = 2 * 0.1**2 / (1 + 0.1 * k) ** 3
    for second in (jax.grad(jax.grad(x1)), jax.jacfwd(jax.grad(x1)), jax.grad(jax.jacfwd(x1))):
        assert abs(float(second(k)) - exact) <= 1e-15
