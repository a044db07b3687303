"""The stroke program as named stages: one program eager and under ``jax.jit``.

``solve_stroke`` runs its forward walk and its reverse walk (the points after a gap that
only the stretch after them reaches) in one compiled program, so a user's ``jax.jit``
around it gives the same statuses and the same values to the last bit as the eager call,
on strokes with gaps, including one where the forward walk alone cannot reach some points
(shown here by running the forward walk's stage alone).  Truths: the closed-form poses of
``tests/test_gaps.py`` (circle intersections, independent of the solver).  Also: the public
predictor is the stroke's, ``throw=True`` under a trace, the deprecated names.
"""

import dataclasses
import functools

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.scenes.classic import fourbar_mechanism  # noqa: E402
from test_gaps import ACCURACY, N, SIXBAR, fourbar_truth, sixbar_truth  # noqa: E402

S = jm.Status
FIELDS = ("q", "status", "steps", "residual", "cond", "branch", "flipped")

#: A Watt six-bar whose stroke leaves loop 2's range and re-enters it at a toggle: there the
#: forward walk, coming from the gap, cannot reach the requested branch's poses (found by a
#: search over random designs of tests/test_gaps.py's property).
REENTRY_P = {"a": 2.076549321214803, "b": 2.7904069327870586, "c": 0.7222767335126113, "d": 1.8189962220125468,
             "e": 2.3572252121870148, "f": 2.792045333646109, "g": 2.1036169549347865, "h": 4.409247357604528,
             "k": -0.058859935065211255, "gamma": 0.14322006303468604}
REENTRY_US = 5.12444595356452 + np.linspace(0.0, 4 * np.pi, N)
REENTRY_SIGNS = (1.0, -1.0)

#: Four-bars whose strokes cross gaps (Grashof-violating: the crank cannot turn fully).
FOURBARS = [(dict(a=1.6, b=1.0, c=1.3, d=2.0), 0.3, 1.0), (dict(a=2.2, b=0.9, c=1.5, d=1.9), 1.1, -1.0)]


def assert_bitwise_equal(a: jm.Solution, b: jm.Solution):
    for f in FIELDS:
        x, y = np.asarray(getattr(a, f)), np.asarray(getattr(b, f))
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert np.array_equal(x.view(np.uint8), y.view(np.uint8)), f"{f} differs eager vs jit"


def eager_and_jit(mech, us, p, guess):
    eager = jm.solve_stroke(mech, us, p, guess)
    jitted = jax.jit(lambda u_, p_, g_: jm.solve_stroke(mech, u_, p_, g_))(us, p, guess)
    return eager, jitted


def forward_walk_only(mech, us, p, guess):
    """The forward walk alone (``continuation.stages.walk_block`` over the stroke's blocks), the
    statuses at the stroke's points: what ``solve_stroke`` gave before the reverse walk."""
    from jaxmech.continuation.solve import block_layout, block_size, stroke_setup, unblock
    from jaxmech.continuation.stages import BlockInput, StrokeCarry, walk_block

    us = jnp.asarray(us)[:, None]
    p = {k: jnp.full((1,), v) for k, v in p.items()}
    setup, us_s, g0 = stroke_setup(mech, jm.SolverOptions(), False, us, p, jnp.asarray(guess)[None])
    n, k = us.shape[0], block_size(us.shape[0], jm.SolverOptions().anchors)
    nblk = -(-(n - 1) // k)
    init = StrokeCarry(g0, jnp.zeros((1, mech.m, 1)), jnp.zeros((1, mech.m, 1, 1)), us_s[:1], jnp.zeros((1,), jnp.int32))
    u_blk = block_layout(us_s, k, nblk)
    nb = u_blk.shape[0]
    xs = BlockInput(u_blk, jnp.arange(nb) == 0)
    _, out = jax.lax.scan(functools.partial(walk_block, setup), init, xs)
    return np.asarray(unblock(out.status, 1, k, n))[0]


def test_the_repair_is_part_of_the_program_and_reaches_what_the_forward_walk_cannot():
    q_true, cond = sixbar_truth(REENTRY_US, REENTRY_P, REENTRY_SIGNS)
    eager, jitted = eager_and_jit(SIXBAR, REENTRY_US, REENTRY_P, q_true[0])
    assert_bitwise_equal(eager, jitted)
    st = np.asarray(eager.status)
    forward = forward_walk_only(SIXBAR, REENTRY_US, REENTRY_P, q_true[0])
    reached = (st == S.CONVERGED) & (forward != S.CONVERGED)
    assert np.any(reached), "the forward walk alone reaches every point: this stroke does not test the repair"
    # what the repair reports is right, as a number and on the requested branch
    exists = np.all(np.isfinite(q_true), axis=-1)
    assert np.all(exists[reached])
    q = np.asarray(eager.q)
    err = np.abs(np.angle(np.exp(1j * (q[reached] - q_true[reached]))))
    assert np.max(err) < ACCURACY
    ok = st == S.CONVERGED
    assert not np.any(ok & ~exists)
    # right as numbers: neighbours within half a turn, and across each gap the first pose
    # after it within half a turn of the last one before it (no whole turn added)
    assert np.max(np.abs(np.diff(q[ok], axis=0)), initial=0) <= np.pi


#: A four-bar that assembles over its whole turn and passes near its extended toggle
#: (a + d = 4.82 against b + c = 4.89): at 37 points a turn the walk's prediction of the point
#: after it is 0.02 rad off, and three checked steps are one too few.
#: (One string: hypothesis draws the float literals of every imported module into its
#: examples, so literals here would change what tests/test_gaps.py's property tests draw.)
NEAR_TOGGLE = dict(zip("abcd", map(float, "1.324645043037026 2.8389430338834583 2.0557903654982956 3.5".split())))


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_walk_closes_the_points_after_one_it_missed(sign):
    """A point the walk misses is not a gap: the points after it, predicted from the last
    trusted pose without its series, are closed by the walk itself (before: each of the 17
    after it failed too, and went to the repair).  Truth: the closed-form poses."""
    us = np.linspace(0.0, 2 * np.pi, 37)
    q_true, _ = fourbar_truth(us, NEAR_TOGGLE, sign)
    assert np.all(np.isfinite(q_true))  # no gap anywhere
    walked = forward_walk_only(fourbar_mechanism, us, NEAR_TOGGLE, q_true[0])
    assert 0 < np.sum(walked != S.CONVERGED) <= 1, walked
    sol = jm.solve_stroke(fourbar_mechanism, us, NEAR_TOGGLE, q_true[0])
    assert np.all(np.asarray(sol.status) == S.CONVERGED)
    assert np.max(np.abs(np.asarray(sol.q) - q_true)) < ACCURACY  # as numbers: no turn added


@pytest.mark.parametrize("p, t0, sign", FOURBARS)
def test_strokes_with_gaps_are_bitwise_equal_eager_and_under_jit(p, t0, sign):
    us = t0 + np.linspace(0.0, 4 * np.pi, N)
    q_true, _ = fourbar_truth(us, p, sign)
    exists = np.all(np.isfinite(q_true), axis=-1)
    assert exists[0] and not np.all(exists)  # the stroke crosses a gap
    eager, jitted = eager_and_jit(fourbar_mechanism, us, p, q_true[0])
    assert_bitwise_equal(eager, jitted)
    ok = np.asarray(eager.status) == S.CONVERGED
    assert np.any(ok) and not np.any(ok & ~exists)


def test_batch_of_designs_with_gaps_is_bitwise_equal_eager_and_under_jit():
    ps = [p for p, _, _ in FOURBARS]
    p = {k: np.array([q[k] for q in ps]) for k in "abcd"}
    us = np.linspace(0.3, 0.3 + 4 * np.pi, 97)
    guess = np.stack([fourbar_truth(us[:1], q, 1.0)[0][0] for q in ps])
    eager, jitted = eager_and_jit(fourbar_mechanism, us, p, guess)
    assert_bitwise_equal(eager, jitted)


def test_stroke_predictor_is_the_public_predict():
    """``predict`` over a block judges the series once, at the block's last step."""
    from jaxmech.continuation.solve import predict
    from jaxmech.continuation.point import series_terms, trusted_terms

    q, s = jnp.array([0.3, 1.0]), jnp.array([1.0, 1.0])
    d1, d2 = jnp.array([[1.0], [-0.5]]), jnp.array([[[40.0]], [[20.0]]])
    du = jnp.array([[0.001], [0.002], [0.05]])  # the last step's second-order term is too large
    out = predict(q, d1, d2, du, s, 1.0)
    d1_t, d2_t = trusted_terms(d1, d2, du[-1], s, 1.0)
    assert float(jnp.max(jnp.abs(d2_t))) == 0.0  # dropped for the whole block
    for i in range(3):
        np.testing.assert_array_equal(np.asarray(out[i]), np.asarray(q + d1 @ du[i]))
        first, second = series_terms(d1_t, d2_t, du[i])
        np.testing.assert_array_equal(np.asarray(out[i]), np.asarray(q + first + second))


def test_throw_under_jit_is_a_clear_error():
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    us = np.linspace(0.0, 1.0, 5)
    for fn in (lambda u: jm.solve_stroke(fourbar_mechanism, u, p, jnp.array([0.4, 1.7]), throw=True),
               lambda u: jm.solve(fourbar_mechanism, u, p, jnp.array([0.4, 1.7]), throw=True)):
        with pytest.raises(ValueError, match="throw=True needs concrete inputs.*check sol.status"):
            jax.jit(fn)(us)
        assert np.all(np.asarray(fn(us).status) == S.CONVERGED)  # concrete: solves (and would raise)
    with pytest.raises(RuntimeError, match="samples failed"):
        jm.solve(fourbar_mechanism, np.array([0.0, 3.0]), dict(a=2.2, b=0.9, c=1.5, d=1.9), jnp.array([0.4, 1.7]), throw=True)


def test_deprecated_names_warn_and_still_work():
    from jaxmech.solver import implicit

    for old, new in implicit.DEPRECATED.items():
        with pytest.warns(DeprecationWarning, match=new):
            assert getattr(implicit, old) is getattr(implicit, new)
    with pytest.warns(DeprecationWarning, match="implicit_positions"):
        assert jm.implicit_root is jm.implicit_positions
    with pytest.warns(DeprecationWarning, match="use jaxmech.solve "):
        one = jm.solve_one
    # the retired verb still answers, and as jm.solve does for one sample (the same root)
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    np.testing.assert_array_equal(np.asarray(one(fourbar_mechanism, jnp.array([0.5]), p, jnp.array([0.4, 1.7])).q),
                                  np.asarray(jm.solve(fourbar_mechanism, 0.5, p, jnp.array([0.4, 1.7])).q))
    with pytest.warns(DeprecationWarning, match="max_iterations"):
        opts = jm.SolverOptions(max_steps=7)
    assert opts == jm.SolverOptions(max_iterations=7)
    with pytest.warns(DeprecationWarning, match="max_iterations"):
        assert opts.max_steps == 7


def test_newton_result_is_named():
    from jaxmech.solver.newton import newton

    res = newton(fourbar_mechanism, jm.SolverOptions(), jnp.array([0.5]), dict(a=1.0, b=3.0, c=2.5, d=3.5), jnp.array([0.4, 1.7]))
    assert isinstance(res, jm.Solution) and int(res.status) == S.CONVERGED
    a, b, c, d = 1.0, 3.0, 2.5, 3.5
    joint = a * np.exp(0.5j) + b * np.exp(1j * float(res.q[0]))
    assert abs(joint - (d + c * np.exp(1j * float(res.q[1])))) < 1e-13


def test_an_eager_gradient_takes_the_concrete_strokes_values_and_matches_the_jitted_one():
    """Under an eager ``jax.grad`` the stroke's values come from the concrete call's
    programs on the stopped inputs, and the implicit rule's Jacobians from one program more:
    the autodiff traces only their contraction.  The values are the concrete call's to the
    last bit; the gradient, a jvp and jacfwd are the jitted gradient's (to rounding: other
    programs) and central differences' (on a stroke with a gap: NaN-free)."""
    from jaxmech.continuation import solve as continuation

    mech = fourbar_mechanism
    p0, u0, sign = FOURBARS[0]
    us = u0 + np.linspace(0.0, 2 * np.pi, 61)
    q_true, _ = fourbar_truth(us, p0, sign)
    guess = jnp.asarray(q_true[0])
    names = tuple(p0)

    def figure(x):
        p = dict(zip(names, x))
        sol, d1, _ = jm.stroke_kinematics(mech, us, p, guess)
        ok = sol.status == S.CONVERGED
        return jnp.sum(jnp.where(ok, jnp.sin(sol.q[:, 1]) + d1[:, 0, 0], 0.0))

    x0 = jnp.asarray([p0[k] for k in names])
    calls = []
    concrete = continuation._concrete
    try:
        continuation._concrete = lambda *a: calls.append(1) or concrete(*a)
        eager = jax.grad(figure)(x0)
    finally:
        continuation._concrete = concrete
    assert calls, "the eager gradient did not take the concrete stroke's values"
    jitted = jax.jit(jax.grad(figure))(x0)
    assert np.all(np.isfinite(np.asarray(eager)))
    np.testing.assert_allclose(np.asarray(eager), np.asarray(jitted), rtol=1e-12, atol=1e-12)
    # forward mode takes the same eager route: jvp and jacfwd agree with the gradient
    t = jnp.arange(1.0, len(names) + 1.0)
    _, along = jax.jvp(figure, (x0,), (t,))
    np.testing.assert_allclose(float(along), float(jnp.dot(jitted, t)), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(jax.jacfwd(figure)(x0)), np.asarray(jitted), rtol=1e-12, atol=1e-12)
    h = 1e-6
    fd = [(figure(x0.at[i].add(h)) - figure(x0.at[i].add(-h))) / (2 * h) for i in range(len(names))]
    np.testing.assert_allclose(np.asarray(eager), np.asarray(fd), rtol=1e-5, atol=1e-6)
    # the values of the split route are the one program's, bit for bit
    p_t = {k: jnp.asarray(v) for k, v in p0.items()}
    primal, vjp = jax.vjp(lambda p: jm.solve_stroke(mech, us, p, guess).q, p_t)
    assert np.array_equal(np.asarray(primal), np.asarray(jm.solve_stroke(mech, us, p0, guess).q), equal_nan=True)


def _six_bar_without_indicator():
    return dataclasses.replace(SIXBAR, branch=None)  # every loop kept by its determinant


@pytest.mark.parametrize("case", ["fourbar", "sixbar"])
def test_a_smooth_stroke_runs_the_straight_line_program_and_agrees_with_the_robust_one(case):
    """A concrete stroke runs the straight-line program (checked steps, up to FRESH_STEPS
    from a rough guess at the first point) and the robust one only where a point failed it.
    On a smooth stroke every point passes the first, both programs agree (two compiled
    programs: to rounding), the eager call (straight-line) and a user's ``jax.jit`` (robust)
    give the same statuses, and the poses are the closed form's."""
    from jaxmech.continuation import solve as continuation

    if case == "fourbar":
        mech, p, signs = fourbar_mechanism, dict(a=1.0, b=3.0, c=2.5, d=3.5), 1.0
        us = 0.3 + np.linspace(0.0, 2 * np.pi, 181)
        q_true, _ = fourbar_truth(us, p, signs)
    else:
        mech = _six_bar_without_indicator()
        p = dict(a=1.0, b=3.0, c=2.5, d=3.5, e=1.5, f=3.0, g=2.0, h=5.0, k=2.0, gamma=0.6)
        us = 0.3 + np.linspace(0.0, 2 * np.pi, 181)
        q_true, _ = sixbar_truth(us, p, (1.0, 1.0))
    guess = np.asarray(q_true[0]) + 0.05  # a rough guess: the first root is solved from it
    args = (mech, jm.SolverOptions(), True, True)
    us_b = np.concatenate([us, np.repeat(us[-1:], continuation.bucket(us.size) - us.size)])[:, None]
    rest = (us_b, {k: np.full((1,), v) for k, v in p.items()}, np.asarray(guess)[None], np.int32(us.size))
    straight = continuation._stroke_program(*args, False, *rest)
    robust = continuation._stroke_program(*args, True, *rest)
    assert np.all(np.asarray(straight[0].status) == S.CONVERGED)
    assert np.array_equal(np.asarray(straight[0].status), np.asarray(robust[0].status))
    for a, b in zip((straight[0].q,) + straight[1:], (robust[0].q,) + robust[1:]):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-12)
    eager, jitted = eager_and_jit(mech, us, p, guess)
    assert np.array_equal(np.asarray(eager.status), np.asarray(jitted.status))
    np.testing.assert_allclose(np.asarray(eager.q), np.asarray(jitted.q), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(eager.q), q_true, atol=ACCURACY)


def test_a_designs_stroke_does_not_depend_on_the_other_designs_of_its_batch():
    """In a batch, a design whose stroke passes the straight-line program keeps its values
    and one with a gap takes the robust program's: each equal, bit for bit (derivatives
    too), to the design solved alone, and its points on the closed form."""
    smooth = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    gap, _, sign = FOURBARS[0]
    us = 0.3 + np.linspace(0.0, 2 * np.pi, 121)
    designs = [(smooth, 1.0), (gap, sign)]
    guesses = np.stack([fourbar_truth(us[:1], q, s)[0][0] for q, s in designs])
    p = {k: np.array([q[k] for q, _ in designs]) for k in "abcd"}
    both = jm.stroke_kinematics(fourbar_mechanism, us, p, guesses)
    for i, (q, s) in enumerate(designs):
        alone = jm.stroke_kinematics(fourbar_mechanism, us, q, guesses[i])
        assert_bitwise_equal(jax.tree_util.tree_map(lambda x: x[i], both[0]), alone[0])
        for a, b in zip(both[1:], alone[1:]):
            assert np.array_equal(np.asarray(a[i]).view(np.uint8), np.asarray(b).view(np.uint8))
        q_true, _ = fourbar_truth(us, q, s)
        ok = np.asarray(alone[0].status) == S.CONVERGED
        assert np.all(np.isfinite(q_true[ok]))
        wrapped = np.angle(np.exp(1j * (np.asarray(alone[0].q)[ok] - q_true[ok])))  # the closed form is in (-pi, pi]
        np.testing.assert_allclose(wrapped, 0.0, atol=ACCURACY)
    assert np.all(np.asarray(both[0].status)[0] == S.CONVERGED) and not np.all(np.asarray(both[0].status)[1] == S.CONVERGED)


def test_far_guesses_give_first_poses_within_half_a_turn_of_them():
    """From guesses up to 3.5 rad off (200 at random, one batch: the straight-line program
    for those it brings home, the robust one for the rest), every stroke converges on the
    branch its guess picks, on the closed form, with its first pose within half a turn of
    the guess: an angle is right as a number, not only modulo a turn (angle-dependent loads
    read it)."""
    p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    us = 0.3 + np.linspace(0.0, 0.5, 21)
    q_up, _ = fourbar_truth(us, p, 1.0)
    guess = q_up[0] + np.random.default_rng(0).uniform(-3.5, 3.5, (200, 2))
    sol = jm.solve_stroke(fourbar_mechanism, us, {k: np.full(200, v) for k, v in p.items()}, guess)
    q = np.asarray(sol.q)
    assert np.all(np.asarray(sol.status) == S.CONVERGED)
    assert np.all(np.abs(q[:, 0] - guess) <= np.pi + 1e-9)
    for sign in (1.0, -1.0):  # the guess picks the branch
        mine = np.sign(np.sin(guess[:, 1] - guess[:, 0])) == sign
        q_true, _ = fourbar_truth(us, p, sign)
        np.testing.assert_allclose(np.angle(np.exp(1j * (q[mine] - q_true))), 0.0, atol=ACCURACY)


def test_an_eager_gradient_too_large_for_stored_jacobians_traces_attach_and_agrees(monkeypatch):
    """Past ``EAGER_JACOBIAN_MAX`` the eager autodiff traces the implicit rule itself (no
    dense Jacobians): the same gradient, to rounding."""
    from jaxmech.continuation import attachment as stroke_attach

    mech = fourbar_mechanism
    p0 = dict(a=1.0, b=3.0, c=2.5, d=3.5)
    us = 0.3 + np.linspace(0.0, 2 * np.pi, 61)
    guess = jnp.asarray(fourbar_truth(us[:1], p0, 1.0)[0][0])

    def figure(x):
        sol, d1, _ = jm.stroke_kinematics(mech, us, dict(zip("abcd", x)), guess)
        return jnp.sum(jnp.sin(sol.q[:, 1]) * d1[:, 0, 0])

    x0 = jnp.asarray([p0[k] for k in "abcd"])
    stored = jax.grad(figure)(x0)
    monkeypatch.setattr(stroke_attach, "EAGER_JACOBIAN_MAX", 0)
    traced = jax.grad(figure)(x0)
    np.testing.assert_allclose(np.asarray(traced), np.asarray(stored), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(traced), np.asarray(jax.jit(jax.grad(figure))(x0)), rtol=1e-12, atol=1e-12)
