"""Kinematics and inverse dynamics from samples of (u, u_dot, u_ddot): a reversing input with
no time law, checked against the four-bar's hand kinematics and hand Newton-Euler model; one
parameter dict for kinematics and dynamics; the documented input shapes."""

import functools

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.scenes.classic import fourbar_mechanism  # noqa: E402
from tests.test_dynamics import FB_GUESS, FB_MODEL, FB_P, fb_kinematics, fb_newton_euler  # noqa: E402

TOL = 1e-10  # relative: the hand kinematics and Newton-Euler are exact, both sides in float64

# A rocker drive that reverses twice: u = 0.2 + 1.1 sin(s), with its exact rates.
S = np.linspace(0.0, 2 * np.pi, 50)
U, UD, UDD = 0.2 + 1.1 * np.sin(S), 1.1 * np.cos(S), -1.1 * np.sin(S)


@functools.lru_cache(maxsize=None)
def _motion():
    # the classic four-bar's mechanism (parameters a, b, c, d) with the model's whole dict
    return jm.motion(fourbar_mechanism, jm.Samples(U, UD, UDD), p=FB_P, guess=FB_GUESS)


@functools.lru_cache(maxsize=None)
def _dynamics():
    return jm.inverse_dynamics(FB_MODEL, jm.Samples(U, UD, UDD), p=FB_P, guess=FB_GUESS)


def test_motion_from_reversing_samples_matches_hand_kinematics():
    mo = _motion()
    assert np.all(np.asarray(mo.status) == 0)
    np.testing.assert_array_equal(np.asarray(mo.u[:, 0]), U)
    np.testing.assert_array_equal(np.asarray(mo.u_dot[:, 0]), UD)
    for k in range(len(S)):
        th3, th4, w3, w4, al3, al4 = fb_kinematics(U[k], UD[k], UDD[k], FB_P)
        for got, want in zip((mo.q[k], mo.q_dot[k], mo.q_ddot[k]), ((th3, th4), (w3, w4), (al3, al4))):
            np.testing.assert_allclose(np.asarray(got), want, rtol=TOL, atol=TOL * max(1.0, np.max(np.abs(want))))
        # a named point: the coupler's B = d + c e^{i theta4}, velocity and acceleration by hand
        E4 = np.exp(1j * th4)
        want = (FB_P["d"] + FB_P["c"] * E4, 1j * w4 * FB_P["c"] * E4, FB_P["c"] * E4 * (1j * al4 - w4**2))
        for got, w in zip(mo.points["B"], want):
            assert abs(complex(got[k]) - w) <= TOL * max(1.0, abs(w))


def test_inverse_dynamics_from_samples_matches_newton_euler():
    r = _dynamics()
    assert np.all(np.asarray(r.status) == 0)
    for k in range(0, len(S), 3):
        tau, F34 = fb_newton_euler(U[k], UD[k], UDD[k], FB_P)
        scale = max(abs(tau), abs(F34))
        assert abs(float(r.tau[k, 0]) - tau) <= TOL * scale
        assert abs(complex(r.reaction("loop 1")[k]) - F34) <= TOL * scale
        assert abs(complex(r.reaction(0)[k]) - F34) <= TOL * scale
    # the motion the dynamics carries is the kinematics' own
    np.testing.assert_allclose(np.asarray(r.q_ddot), np.asarray(_motion().q_ddot), rtol=0, atol=1e-12)


def test_reaction_names_are_checked():
    r = _dynamics()
    with pytest.raises(ValueError, match="no joint or loop named 'loop 2'"):
        r.reaction("loop 2")
    with pytest.raises(ValueError, match="there are 1 loops"):
        r.reaction(1)


def test_samples_need_no_t_and_refuse_one():
    with pytest.raises(ValueError, match="carries its own times"):
        jm.motion(fourbar_mechanism, jm.Samples(U, UD, UDD), S, FB_P, FB_GUESS)
    with pytest.raises(ValueError, match="Samples.u_dot of shape"):
        jm.motion(fourbar_mechanism, jm.Samples(U, UD[:3], UDD), p=FB_P, guess=FB_GUESS)
    with pytest.raises(ValueError, match="t .the sample times, s. is required"):
        jm.motion(fourbar_mechanism, jm.ConstantSpeed(0.0, 1.0), p=FB_P, guess=FB_GUESS)


def test_statics_is_inverse_dynamics_at_rest():
    """``statics`` at poses = the quasi-static balance with zero rates (gravity and the
    velocity-independent loads only): the hand Newton-Euler model with w = alpha = 0."""
    u = np.array([0.3, 1.2, 2.5])
    r = jm.statics(FB_MODEL, u, FB_P, np.broadcast_to(np.asarray(FB_GUESS), (3, 2)))
    assert np.all(np.asarray(r.status) == 0)
    for k in range(3):
        tau, _ = fb_newton_euler(u[k], 0.0, 0.0, FB_P)
        assert abs(float(r.tau[k, 0]) - tau) <= TOL * abs(tau)
    np.testing.assert_array_equal(np.asarray(r.u_dot), 0.0)
