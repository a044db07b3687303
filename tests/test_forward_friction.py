"""Forward dynamics with joint friction (``Linkage(friction=...).forward_dynamics``) against an
independent model written here in numpy and integrated by ``scipy.integrate.solve_ivp``
(Radau): a bar pendulum falling from rest under gravity with Coulomb friction and viscous
damping at its pivot, ``J_G alpha = (O - G) x F + M_f`` with the pin force
``F = m (a_G - g)`` and the friction moment ``M_f = -mu r |F| tanh(w / (width W)) - c w``:
``|F|`` depends on ``alpha``, so every evaluation of the acceleration solves that scalar
equation (``brentq`` to round-off).  And: the offset slider-crank of
``test_joint_friction`` (friction at its three pins and in its guide) falling from rest under
gravity, its per-body Newton-Euler equations solved at every evaluation for the joints'
forces and the crank's acceleration together (the crank's torque zero), against the same
run; the mechanical energy decreases at every step of a run swinging back and forth
(friction only dissipates); the derivative of the final angle in the friction coefficient
against central differences; a pendulum whose pin friction admits no acceleration at all
(the numpy balance keeps one sign) stopping with ``Status.FRICTION``; the speed scale
asked for.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

import jaxmech as jm  # noqa: E402
import test_joint_friction as SC  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402

L, MASS, G = 0.3, 1.0, 9.81  # the bar O-A (m), its mass (kg), gravity (m/s^2)
MU, RPIN, CV = 0.3, 0.02, 0.01  # friction coefficient, pin radius (m), viscous damping (N m s/rad) at O
WIDTH, W = 0.1, 10.0  # the sign's band width W = 1 rad/s: a step of 2.5 ms resolves it
C, JG = L / 2, MASS * L * L / 12  # centre of mass on the bar, inertia about it

LK = jm.Linkage(points={"O": (0, 0), "A": (L, 0)}, links={"arm": "O A"}, ground="O", driver="arm", mass={"arm": MASS},
                gravity=G, friction={"all": {"mu": MU, "radius": RPIN, "damping": CV}, "width": WIDTH})


# --------------------------------------------------------------------------- numpy model
def residual(al, th, om, mu=MU, rpin=RPIN):
    """The bar's moment balance about its centre at angular acceleration `al` (rad/s^2), angle
    `th` and rate `om`, with the pin force ``F(alpha) = m (a_G(alpha) - g)`` and friction."""
    f = MASS * C * np.exp(1j * th) * (1j * al - om * om) + 1j * MASS * G  # the ground's force on the bar at O (N)
    friction = -mu * rpin * np.abs(f) * np.tanh(om / (WIDTH * W)) - CV * om
    return JG * al - np.imag(np.conj(-C * np.exp(1j * th)) * f) - friction


def acceleration(th, om):
    """The bar's angular acceleration (rad/s^2): the root of ``residual``."""
    free = -MASS * G * C * np.cos(th) / (JG + MASS * C * C)
    return brentq(residual, free - 1e3, free + 1e3, args=(th, om), xtol=1e-14, rtol=4 * np.finfo(float).eps, maxiter=500)


def reference(t_end):
    sol = solve_ivp(lambda t, y: [y[1], acceleration(*y)], (0.0, t_end), [0.0, 0.0], method="Radau", rtol=1e-12, atol=1e-12)
    assert sol.success
    return sol.y[:, -1]


def energy(th, om):
    """Kinetic plus potential energy of the bar (J)."""
    return 0.5 * (JG + MASS * C * C) * om**2 + MASS * G * C * np.sin(th)


# --------------------------------------------------------------------------- the tests
def test_pendulum_with_pin_friction_against_scipy_radau():
    want = reference(1.0)
    tr = LK.forward_dynamics(h=1.0 / 400, steps=400, friction_speed=W)
    assert int(tr.status) == jm.Status.CONVERGED, tr.message()
    got = np.array([float(tr.u[-1, 0]), float(tr.u_dot[-1, 0])])
    # observed 1.0e-12 rad, 1.5e-11 rad/s; without friction the bar would be at -0.085 rad, 2.9 rad/s
    assert np.all(np.abs(got - want) <= 1e-8), got - want
    # the run's accelerations are the numpy model's at the run's own states
    u, ud, udd = (np.asarray(x)[:, 0] for x in (tr.u, tr.u_dot, tr.u_ddot))
    np.testing.assert_allclose(udd[::40], [acceleration(a, b) for a, b in zip(u[::40], ud[::40])], rtol=0, atol=1e-10)


def slider_crank_acceleration(th, om, width, scale):
    """The crank's angular acceleration of ``test_joint_friction``'s slider-crank released (no
    torque on the crank): its nine body equations with the friction loads, in the joints'
    forces and the acceleration, by Newton's method from the frictionless solution."""
    sg = {k: np.tanh(v / (width * scale[k])) for k, v in SC.speeds(SC.motion_at(th, om, 0.0)).items()}
    m0, r0 = SC.linear_system(SC.motion_at(th, om, 0.0))
    _, r1 = SC.linear_system(SC.motion_at(th, om, 1.0))  # the equations are affine in the acceleration
    A = np.column_stack([m0[:, :8], r0 - r1])  # unknowns: F_O, F_A, F_B, N, the guide's moment, alpha
    friction = lambda z: SC.friction_loads(np.append(z[:8], 0.0), sg)  # noqa: E731
    z = np.linalg.solve(A, r0)
    jac = A + np.stack([(friction(z + e) - friction(z - e)) / 2e-7 for e in 1e-7 * np.eye(9)], axis=1)
    for _ in range(60):
        r = A @ z + friction(z) - r0
        if np.max(np.abs(r)) <= 1e-14 * np.max(np.abs(r0)):
            return z[8]
        z = z - np.linalg.solve(jac, r)
    raise AssertionError("the numpy friction Newton did not converge")


def test_slider_crank_with_friction_everywhere_against_scipy_radau(monkeypatch):
    monkeypatch.setattr(SC, "LOAD", 0j)  # gravity alone: the load on the block would fling it
    width, scale = 0.1, {"O": 10.0, "A": 10.0, "B": 10.0, "guide": 1.0}  # rad/s at the pins, m/s in the guide
    # to 0.18 s: beyond, the forces at O and A pass near zero and |F|'s kink costs both integrators accuracy
    t_end = 0.18
    want = solve_ivp(lambda t, y: [y[1], slider_crank_acceleration(*y, width, scale)], (0.0, t_end), [SC.TH0, 0.0],
                     method="Radau", rtol=1e-12, atol=1e-12).y[:, -1]
    lk = SC.linkage(friction={**SC.FRICTION, "width": width})
    tr = lk.forward_dynamics(h=t_end / 100, steps=100, friction_speed={"O": 10.0, "A": 10.0, "B": 10.0, "block_B": 1.0})
    assert int(tr.status) == jm.Status.CONVERGED, tr.message()
    got = np.array([float(tr.u[-1, 0]), float(tr.u_dot[-1, 0])])
    assert np.all(np.abs(got - want) <= 1e-10), got - want  # observed 9e-13 rad, 9e-12 rad/s
    assert want[0] < SC.TH0 - 0.35 and want[1] < -5.0  # it falls (rad, rad/s)


def test_friction_dissipates_energy_at_every_step():
    tr = LK.forward_dynamics(h=1.0 / 400, steps=800, friction_speed=W)
    assert int(tr.status) == jm.Status.CONVERGED, tr.message()
    u, ud = np.asarray(tr.u[:, 0]), np.asarray(tr.u_dot[:, 0])
    assert np.count_nonzero(np.diff(np.sign(ud[1:]))) >= 3  # it swings back and forth (observed 4 reversals)
    e = energy(u, ud)
    assert np.all(np.diff(e) < 0), np.max(np.diff(e))  # observed at most -8e-8 J per step
    assert e[0] - e[-1] > 1.0  # J: of 1.16 J lost in 2 s


def test_final_angle_is_differentiable_in_the_friction_coefficient():
    def final(mu):
        return LK.forward_dynamics(h=1.0 / 200, steps=100, p={"mu_O": mu}, friction_speed=W).u[-1, 0]

    g = float(jax.grad(final)(jnp.asarray(MU)))
    e = 1e-4  # central differences, error O(e^2)
    fd = (float(final(MU + e)) - float(final(MU - e))) / (2 * e)
    assert abs(fd) > 0.1 and abs(g - fd) <= 1e-7 * abs(fd), (g, fd)  # observed 5e-10 relative


def test_a_pendulum_jammed_by_friction_stops_with_its_status():
    # a pin of radius 0.5 m with mu = 1: friction grows with |alpha| faster than inertia does,
    # and no acceleration balances the bar (the numpy residual keeps one sign: Painleve's paradox)
    al = np.linspace(-1e5, 1e5, 200001)
    assert np.all(residual(al, 0.0, 5.0, 1.0, 0.5) > 0)
    tr = LK.forward_dynamics(h=1e-3, steps=5, u0=0.0, u_dot0=5.0, p={"mu_O": 1.0, "rpin_O": 0.5}, friction_speed=W)
    assert int(tr.status) == jm.Status.FRICTION and float(tr.t_stop) == 0.0
    assert "friction jams the linkage" in tr.message() and np.all(np.isnan(np.asarray(tr.u[1:])))


def test_the_speed_scale_is_asked_for():
    with pytest.raises(ValueError, match="friction_speed="):
        LK.forward_dynamics(h=1e-3, steps=2)
    with pytest.raises(ValueError, match="positive"):
        LK.forward_dynamics(h=1e-3, steps=2, friction_speed=0.0)
    with pytest.raises(ValueError, match="carry no friction"):
        LK.forward_dynamics(h=1e-3, steps=2, friction_speed={"O": 1.0, "A": 1.0})
