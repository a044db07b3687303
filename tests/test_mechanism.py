"""Declaring a mechanism: which parameters are lengths must be said, a mass never enters
the length scale behind the tolerances, and a negative angle is a valid parameter."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402


def _tilted_fourbar(**kw):
    """A four-bar whose ground link is tilted by the angle ``alpha`` and which carries a
    mass ``m`` (kg) that no constraint uses."""
    return jm.Mechanism(
        name="tilted", coords=("theta3", "theta4"), inputs=("theta2",), params=("a", "b", "c", "d", "alpha", "m"),
        constraints=lambda q, u, p: [p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4)
                                     - p.d * jm.cis(p.alpha)], **kw)  # fmt: skip


P = dict(a=0.1, b=0.3, c=0.25, d=0.35, alpha=-0.3, m=50.0)


def test_lengths_must_be_declared_when_there_are_parameters():
    with pytest.raises(ValueError, match=r"tilted: say which parameters are lengths: lengths=\(.*\['a', 'b', 'c', 'd', 'alpha', 'm'\]"):
        _tilted_fourbar()
    # none of the parameters a length: an explicit empty declaration
    assert jm.Mechanism(coords=(), inputs=("x",), params=("k",), lengths=()).lengths == ()
    # no parameters: nothing to declare
    assert jm.Mechanism(coords=(), inputs=("x",), params=()).lengths == ()


def test_mass_and_angle_stay_out_of_the_length_scale_and_a_negative_angle_is_valid():
    mech = _tilted_fourbar(lengths=("a", "b", "c", "d"))
    # the largest length (d = 0.35 m), not the mass (50 kg) nor |alpha|
    assert float(mech.length_scale(P)) == P["d"]
    mech.check_params(P)  # alpha = -0.3 rad is accepted
    with pytest.raises(ValueError, match=r"tilted: length 'a' must be positive, got -0\.1; give a positive length in metres"):
        mech.check_params({**P, "a": -0.1})
    with pytest.raises(ValueError, match=r"tilted: parameter 'alpha' must be finite"):
        mech.check_params({**P, "alpha": np.inf})
