"""Forward dynamics of a linkage driven by a DC motor, with a spring and a damper, against an
independent model written here in numpy and integrated by ``scipy.integrate.solve_ivp``
(Radau): a centred slider-crank, its constraint eliminated on the crank angle (closed-form
slider position and rod angle and their first two derivatives by hand), the mass matrix
``M(theta)`` by virtual work, ``M theta'' + M'(theta) theta'^2 / 2 = Q``.

And what a run holds and how it ends: a new duration compiles nothing new and repeats the
shorter run's states exactly; the trajectory's accelerations against central differences of
its velocities; the effort along the run equal to the motor's torque ``K i``; the reactions
equal to inverse dynamics at the same state; an oversized step's message naming the step and
``close_iters``, a toggle's naming the toggle.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import jaxmech as jm  # noqa: E402
from helpers import fourbar_closed  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402
from test_dynamics import FB_FREE, FB_GUESS, FB_MODEL  # noqa: E402

R, L = 0.10, 0.35  # crank and rod (m)
MASS = {"crank": 1.0, "rod": 2.0, "block_B": 1.5}  # kg; bars uniform (centre at the middle, m L^2 / 12)
G = 9.81
S, DA = 0.30 + 0.25j, -0.10 + 0.20j  # spring anchor (to the block), damper anchor (to the crank pin), m
K, L0, F0, C = 800.0, 0.20, 10.0, 3.0  # N/m, m, N, N s/m
RA, KM, LA, V = 2.0, 0.5, 0.02, 6.0  # ohm, N m/A, H, V
MOTOR = jm.DCMotor("R_a", "K_m", inductance="L_a", voltage="V")
P_MOTOR = {"R_a": RA, "K_m": KM, "L_a": LA, "V": V}
TH0 = 0.3  # drawn crank angle (rad); the run starts there at rest


# --------------------------------------------------------------------------- numpy model
def kinematics(th):
    """The slider-crank's positions and their first two derivatives in the crank angle:
    crank pin A, block B (on the x axis), rod angle phi, as ``(x, x', x'')`` each."""
    s = np.sqrt(L**2 - (R * np.sin(th)) ** 2)
    s1 = -(R**2) * np.sin(2 * th) / (2 * s)
    s2 = (-(R**2) * np.cos(2 * th) - s1**2) / s
    e = np.exp(1j * th)
    A = (R * e, 1j * R * e, -R * e)
    B = (R * np.cos(th) + s, -R * np.sin(th) + s1, -R * np.cos(th) + s2)
    phi = (-np.arcsin(R * np.sin(th) / L), -R * np.cos(th) / s, R * (np.sin(th) * s + np.cos(th) * s1) / s**2)
    return A, B, phi


def dot(a, b):
    return np.real(np.conj(a) * b)


def mass_terms(th):
    """``(M, M')``: the generalized mass and its derivative in the crank angle (kg m^2)."""
    A, B, phi = kinematics(th)
    G2 = tuple(0.5 * x for x in A)
    G3 = tuple(0.5 * (a + b) for a, b in zip(A, B))
    J2, J3 = MASS["crank"] * R**2 / 12, MASS["rod"] * L**2 / 12
    M = MASS["crank"] * abs(G2[1]) ** 2 + J2 + MASS["rod"] * abs(G3[1]) ** 2 + J3 * phi[1] ** 2 + MASS["block_B"] * B[1] ** 2
    dM = 2 * (MASS["crank"] * dot(G2[1], G2[2]) + MASS["rod"] * dot(G3[1], G3[2]) + J3 * phi[1] * phi[2]
              + MASS["block_B"] * B[1] * B[2])
    return M, dM


def applied(th, om, i):
    """The generalized force on the crank (N m): motor ``K i``, gravity, the spring S-B
    (tension ``F0 + K (d - L0)``) and the damper D-A (tension ``C d'``)."""
    A, B, _ = kinematics(th)
    gravity = -G * (MASS["crank"] * 0.5 * A[1].imag + MASS["rod"] * 0.5 * A[1].imag)  # the block moves along x
    d = abs(B[0] - S)
    d1 = dot(B[0] - S, B[1]) / d
    spring = -(F0 + K * (d - L0)) * d1
    e = abs(A[0] - DA)
    e1 = dot(A[0] - DA, A[1]) / e
    damper = -C * e1 * om * e1
    return KM * i + gravity + spring + damper


def numpy_rhs(t, y):
    th, om, i = y
    M, dM = mass_terms(th)
    return [om, (applied(th, om, i) - 0.5 * dM * om**2) / M, (V - RA * i - KM * om) / LA]


def reference(t_end):
    sol = solve_ivp(numpy_rhs, (0.0, t_end), [TH0, 0.0, 0.0], method="Radau", rtol=1e-12, atol=1e-12)
    assert sol.success
    return sol.y[:, -1]


# --------------------------------------------------------------------------- the linkage
def slider_crank():
    A, B, _ = kinematics(TH0)
    pts = {"O": (0, 0), "A": (A[0].real, A[0].imag), "B": (B[0], 0.0), "S": (S.real, S.imag), "D": (DA.real, DA.imag)}
    return jm.Linkage(points=pts, links={"crank": "O A", "rod": "A B"}, ground="O S D", driver="crank",
                      sliders={"B": {"angle": 0.0}}, mass=MASS, gravity=G,
                      springs={"s1": {"between": ["S", "B"], "on": ["ground", "block_B"], "k": K, "free_length": L0, "preload": F0}},
                      dampers={"d1": {"between": "D A", "on": "ground crank", "c": C}})


LK = slider_crank()


def run(steps, h, **kw):
    return LK.forward_dynamics(h=h, steps=steps, p=P_MOTOR, motor=MOTOR, **kw)


def test_linkage_forward_dynamics_with_motor_spring_and_damper_against_scipy_radau():
    want = reference(1.0)
    errors = {}
    for steps in (200, 400):
        tr = run(steps, 1.0 / steps)
        assert int(tr.status) == jm.Status.CONVERGED, tr.message()
        got = np.array([float(tr.u[-1, 0]), float(tr.u_dot[-1, 0]), float(tr.current[-1, 0])])
        errors[steps] = np.abs(got - want)
    assert want[0] - TH0 > 4.0 and want[2] > 1.0  # the motor turns the crank well over (rad), against a real current (A)
    assert np.all(errors[400] <= 1e-8), errors  # rad, rad/s, A at t = 1 s
    # Radau IIA is of order 5: halving the step divides the error by about 2^5 = 32 (observed 4.9)
    order = np.log2(errors[200][0] / errors[400][0])
    assert 4.0 < order < 6.5, order


def _compiles(fn):
    """How many XLA programs ``fn()`` compiled (the backend compile events)."""
    seen = []

    def listener(event, duration, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            seen.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        out = fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    return out, len(seen)


def diff4(x, h):
    """Fourth-order central differences of the rows of `x` (rows 2 to N-2)."""
    return (-x[4:] + 8 * x[3:-1] - 8 * x[1:-3] + x[:-4]) / (12 * h)


def test_trajectory_rates_effort_and_reactions():
    h = 2e-3
    tr = run(300, h)
    u, ud, udd, i = (np.asarray(x)[:, 0] for x in (tr.u, tr.u_dot, tr.u_ddot, tr.current))
    q, qd = np.asarray(tr.q), np.asarray(tr.q_dot)
    # rates against fourth-order central differences of the run's own rows, row for row (a
    # row off would miss by 8% of the peak); the differences' truncation error, largest in the
    # motor current's 10 ms rise, is 5e-5 of the peak acceleration and 5e-6 of the peak q_dot
    assert np.max(np.abs(udd[2:-2] - diff4(ud, h))) <= 2e-4 * np.max(np.abs(udd))
    assert np.max(np.abs(qd[2:-2] - diff4(q, h))) <= 2e-5 * np.max(np.abs(qd))
    # the numpy model's acceleration at the run's own states
    want = np.array([numpy_rhs(0.0, [a, b, c])[1] for a, b, c in zip(u, ud, i)])
    np.testing.assert_allclose(udd, want, rtol=0, atol=1e-10 * np.max(np.abs(want)))
    # along the run the effort is the motor's torque K i, every joint's reaction inverse dynamics' at that state
    p = {**LK.params, **P_MOTOR}
    res = tr.dynamics(LK.model, p)
    np.testing.assert_allclose(np.asarray(res.tau[:, 0]), KM * i, rtol=0, atol=1e-9 * np.max(np.abs(KM * i)))
    qdd = np.asarray(res.q_ddot)
    assert np.max(np.abs(qdd[2:-2] - diff4(qd, h))) <= 2e-4 * np.max(np.abs(qdd))  # observed 4e-5
    k = 137
    one = D.inverse_dynamics_at(LK.model, tr.u[k], tr.u_dot[k], tr.u_ddot[k], LK.params, tr.q[k], t=tr.t[k])
    for joint in LK.joints:
        scale = np.max(np.abs(np.asarray(res.joints[joint])))
        assert abs(complex(res.joints[joint][k]) - complex(one.joints[joint])) <= 1e-12 * scale, joint
    assert np.max(np.abs(np.asarray(res.reactions[k]) - np.asarray(one.reactions))) <= 1e-12 * np.max(np.abs(np.asarray(res.reactions)))


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="R_a"):
        LK.forward_dynamics(h=1e-3, steps=2, p={"V": 1.0, "K_m": 1.0, "L_a": 1.0}, motor=MOTOR)
    with pytest.raises(ValueError, match="k_spring"):
        LK.forward_dynamics(h=1e-3, steps=2, p={**P_MOTOR, "k_spring": 1.0}, motor=MOTOR)
    with pytest.raises(ValueError, match="closeiters"):
        LK.forward_dynamics(h=1e-3, steps=2, p=P_MOTOR, motor=MOTOR, closeiters=3)
    rough = jm.Linkage(points={"O": (0, 0), "A": (0.2, 0)}, links={"arm": "O A"}, ground="O", driver="arm", mass={"arm": 1.0},
                       friction={"all": {"mu": 0.1, "radius": 0.01}})
    with pytest.raises(ValueError, match="friction_speed="):  # joint friction runs with its sign's speed scale
        rough.forward_dynamics(h=1e-3, steps=2, p=P_MOTOR, motor=MOTOR)


def test_a_linkage_run_is_differentiable_in_a_spring_parameter():
    # a motor swinging an arm against a torsion spring and a rotary damper at its pivot (a
    # linkage without a loop: a program compiled in seconds); d(final angle)/d(stiffness)
    arm = jm.Linkage(points={"O": (0, 0), "A": (0.2, 0)}, links={"arm": "O A"}, ground="O", driver="arm", mass={"arm": 1.0},
                     gravity=G, torsion_springs={"t1": {"at": "O", "k": 5.0, "free_angle": 0.0}},
                     rotary_dampers={"r1": {"at": "O", "c": 0.05}})
    motor = jm.DCMotor("R_a", "K_m", voltage="V")

    def final(k):
        return arm.forward_dynamics(h=5e-3, steps=60, p={"kt_t1": k, "R_a": 2.0, "K_m": 0.1, "V": 6.0}, motor=motor).u[-1, 0]

    g = float(jax.grad(final)(jnp.asarray(5.0)))
    e = 1e-4  # N m/rad; central differences, error O(e^2)
    fd = (float(final(5.0 + e)) - float(final(5.0 - e))) / (2 * e)
    assert abs(fd) > 1e-3 and abs(g - fd) <= 1e-7 * abs(fd), (g, fd)


# --------------------------------------------------------------------------- durations and stops
# the hand-built four-bar of test_dynamics (its forward-dynamics program compiles in seconds)
def fourbar(steps, h=5e-3, **kw):
    return D.forward_dynamics(FB_MODEL, FB_FREE, 0.0, 6.0, FB_GUESS, h=h, steps=steps, **kw)


def test_a_new_duration_compiles_nothing_and_repeats_the_shorter_run():
    x = jnp.ones(5)
    assert _compiles(lambda: jax.jit(lambda v: 2.0 * v + 1.0)(x))[1] == 1  # the counter sees a compile
    short, _ = _compiles(lambda: fourbar(300))
    long, n = _compiles(lambda: fourbar(1000))
    assert n == 0
    assert int(short.status) == int(long.status) == jm.Status.CONVERGED
    for field in ("t", "u", "u_dot", "q", "q_dot", "u_ddot"):
        np.testing.assert_array_equal(np.asarray(getattr(long, field))[:301], np.asarray(getattr(short, field)), err_msg=field)
    assert long.u.shape == (1001, 1) and long.newton.shape == (1000,)
    # the documented call that adds the effort and the reactions compiles nothing new either
    short_dyn = short.dynamics(FB_MODEL, FB_FREE)
    long_dyn, n = _compiles(lambda: long.dynamics(FB_MODEL, FB_FREE))
    assert n == 0
    np.testing.assert_array_equal(np.asarray(long_dyn.tau)[:301], np.asarray(short_dyn.tau))


def test_an_oversized_step_names_the_step_and_close_iters():
    # one Newton step per stage cannot close the loop across a 20 ms step of a fast crank, at
    # a well-conditioned pose: the budget, not a toggle
    tr = fourbar(50, 2e-2, close_iters=1)
    assert int(tr.status) == jm.Status.POSITION
    msg = tr.message()
    assert "h=0.02 s" in msg and "close_iters=1" in msg and "smaller h" in msg, msg
    assert "toggle" not in msg and float(tr.cond) < 1e3
    assert int(fourbar(50, 2e-2).status) == jm.Status.CONVERGED  # five Newton steps close it


def test_a_toggle_is_named_as_such():
    # a triple rocker (test_dynamics): the crank runs into the toggle where coupler and rocker align
    tr = D.forward_dynamics(FB_MODEL, {**FB_FREE, "a": 2.4, "g": 0.0}, 0.0, 6.0, jnp.array(fourbar_closed(0.0, 2.4, 3.0, 2.5, 3.5)),
                            h=5e-3, steps=300)
    assert int(tr.status) == jm.Status.POSITION
    msg = tr.message()
    assert "toggle" in msg and "close_iters" not in msg, msg
