"""Every public entry point accepts the shapes its docstring documents, and answers any other
shape with a result or a ``ValueError`` that names the argument (never an error from inside a
compiled program).

One table: each row is one entry point called with one form of one argument (a scalar, the
``(dof,)`` array, a batch ``(N,)`` or ``(N, dof)``, a mapping by name, a wrong shape), and
what it must do: give a result (``doc``), give a result or a ``ValueError`` naming the
argument (``any``), or raise that ``ValueError`` (``err``).  A row ``same`` as another form
must give that form's result bit for bit: for one input, ``(1,)`` is the scalar and
``(N, 1)`` the bare batch ``(N,)``.  One four-bar model with masses (one input) and one
five-bar (two inputs) serve every row, so the file compiles each program once or twice.
"""

import jax

jax.config.update("jax_enable_x64", True)

import dataclasses  # noqa: E402
import functools  # noqa: E402
import re  # noqa: E402
from collections.abc import Callable  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.scenes.classic import fourbar_mechanism as FB  # noqa: E402

# --------------------------------------------------------------------------- the models
# Four-bar with a mass on each link, gravity and a damper on the rocker (one input).
FB_MODEL = jm.Model(
    FB,
    bodies=[jm.Body("A", "m2", angle="theta2", inertia="J2"), jm.Body("P", "m3", angle="theta3", inertia="J3"),
            jm.Body("B", "m4", angle="theta4", inertia="J4")],
    loads=[jm.Gravity(), jm.Moment("theta4", lambda q, u, p, v, t: -p.cd * v.theta4)],
    params=("m2", "J2", "m3", "J3", "m4", "J4", "g", "cd"),
)
P = dict(a=1.0, b=3.0, c=2.5, d=3.5, m2=1.0, J2=0.1, m3=2.0, J3=1.5, m4=1.5, J4=0.8, g=9.81, cd=0.6)
U = 1.0  # crank angle (rad); gravity's holding torque changes sign between 1.0 and 1.6
UB = np.array([0.9, 1.0, 1.1])
G = np.array([0.56, 1.75])  # (theta3, theta4) near U, open assembly
T = np.array([0.0, 0.2, 0.4])

# Five-bar: two cranks (theta1 at the origin, theta4 at D = d), coupler point P carries a mass.
FIVE = jm.Mechanism(
    name="fivebar",
    coords=("theta2", "theta3"),
    inputs=("theta1", "theta4"),
    params=("a1", "a2", "a3", "a4", "d"),
    lengths=("a1", "a2", "a3", "a4", "d"),
    constraints=lambda q, u, p: [p.a1 * jm.cis(u.theta1) + p.a2 * jm.cis(q.theta2) - p.d - p.a4 * jm.cis(u.theta4)
                                 - p.a3 * jm.cis(q.theta3)],
    points={"A": lambda q, u, p: p.a1 * jm.cis(u.theta1),
            "P": lambda q, u, p: p.a1 * jm.cis(u.theta1) + p.a2 * jm.cis(q.theta2)},
)
FIVE_MODEL = jm.Model(FIVE, bodies=[jm.Body("A", "m1", angle="theta1", inertia="J1"), jm.Body("P", "m")],
                      loads=[jm.Gravity()], params=("m1", "J1", "m", "g"))
P5 = dict(a1=1.0, a2=2.5, a3=2.5, a4=1.0, d=2.0, m1=0.5, J1=0.05, m=2.0, g=9.81)
U5 = np.array([1.2, 1.9])
U5B = np.array([[1.2, 1.9], [1.25, 1.9], [1.2, 1.95]])
G5 = np.array([1.30, 1.84])


def _q(model, u, p, guess):
    """Solved coordinates at one state (for the one-state functions)."""
    return np.asarray(jm.solve(model.mechanism, u, p, guess, throw=True).q)


Q = _q(FB_MODEL, U, P, G)
Q5 = _q(FIVE_MODEL, U5, P5, G5)
LK = jm.Linkage(
    points={"O2": (0.2, -0.1), "A": (0.55, 0.75), "B": (2.9, 1.7), "O4": (3.3, -0.2)},
    links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B"}, ground="O2 O4", driver="crank",
    mass={"crank": 0.7, "coupler": 2.5, "rocker": 1.6}, gravity=9.81,
)
LK_U = float(LK.input_at_drawing[0]) + np.array([0.0, 0.05, 0.1])


# --------------------------------------------------------------------------- the table
@dataclasses.dataclass(frozen=True)
class Row:
    entry: str  # the entry point
    form: str  # the form of `arg`
    call: Callable  # () -> result
    expect: str  # "doc": a result; "any": a result or ValueError naming `arg`; "err": that ValueError
    arg: str  # the argument the form is about
    same: str | None = None  # the form whose result this one must equal exactly
    names: tuple = ()  # other names the error may give the argument by (a field of it)
    xfail: str | None = None  # a known gap, in a module this file's author could not edit

    @property
    def id(self):
        return f"{self.entry}[{self.form}]"


def _forms(entry, arg, make, forms, **kw):
    """Rows of one entry point: ``forms`` is ``[(form, value, expect, same), ...]`` and
    ``make(value)`` calls the entry point; `kw`: ``names``, ``xfail`` (``{form: reason}``)."""
    xfail = kw.pop("xfail", {})
    return [Row(entry, form, functools.partial(make, value), expect, arg, same, xfail=xfail.get(form), **kw)
            for form, value, expect, same in forms]


# The forms of an input array of the four-bar (one input).
ONE_STATE = [("scalar", U, "doc", None), ("(dof,)", np.array([U]), "doc", "scalar"),
             ("(N,)", UB, "any", None), ("(N, dof)", UB[:, None], "any", "(N,)"), ("(2,) x 2 inputs", np.ones((3, 2)), "err", None)]
BATCH = [("scalar", U, "doc", None), ("(dof,)", np.array([U]), "doc", "scalar"), ("(N,)", UB, "doc", None),
         ("(N, dof)", UB[:, None], "doc", "(N,)"), ("dict", {"theta2": UB}, "doc", "(N,)"),
         ("(N, M) bare", np.full((3, 2), U), "doc", None)]
STROKE = [("scalar", U, "any", None), ("(N,)", UB, "doc", None), ("(N, dof)", UB[:, None], "doc", "(N,)"),
          ("(N, 2)", np.ones((3, 2)), "err", None)]
# The five-bar's inputs (two): the bare scalar is no input vector.
TWO_STATE = [("scalar", 1.2, "err", None), ("(dof,)", U5, "doc", None), ("dict", dict(zip(FIVE.inputs, U5)), "any", "(dof,)"),
             ("(N, dof)", U5B, "any", None), ("(3,)", np.array([1.2, 1.9, 0.0]), "err", None)]
TWO_BATCH = [("scalar", 1.2, "err", None), ("(dof,)", U5, "doc", None), ("dict", dict(zip(FIVE.inputs, U5)), "doc", "(dof,)"),
             ("(N, dof)", U5B, "doc", None), ("(3,)", np.array([1.2, 1.9, 0.0]), "err", None)]


def _drive(u0, w):
    return jm.ConstantSpeed(u0=u0, w=w)


def _samples(shape):
    u = np.array([0.9, 1.0, 0.95])  # reverses
    ud, udd = np.array([0.5, 0.2, -0.5]), np.array([0.0, -1.0, 0.5])
    if shape == "(N, dof)":
        u, ud, udd = u[:, None], ud[:, None], udd[:, None]
    if shape == "scalar rates":
        ud, udd = 0.5, 0.0
    return jm.Samples(u, ud, udd)


DRIVES = [("scalar", _drive(0.9, 0.5), "doc", None), ("(dof,)", _drive(np.array([0.9]), np.array([0.5])), "doc", "scalar"),
          ("Samples (N,)", _samples("(N,)"), "doc", None), ("Samples (N, dof)", _samples("(N, dof)"), "doc", "Samples (N,)"),
          ("Samples scalar rates", _samples("scalar rates"), "doc", None),
          ("Samples (N, 2)", jm.Samples(np.ones((3, 2)), 0.0, 0.0), "err", None)]


def _law_or_samples(fn):
    """``fn(drive, t)`` with ``t`` left out for Samples."""
    return lambda d: fn(d, None if isinstance(d, jm.Samples) else T)


def _forward(model, p, guess, u0, ud0):
    return jm.forward_dynamics(model, p, u0, ud0, guess, h=0.01, steps=2)


# Known gaps, in modules this file's author was not to edit (reported with the change):
# the error is a ValueError, but it names another thing than the argument.
UD, UDD = np.array([0.5]), np.array([0.1])  # documented (dof,) rates for the rows about other arguments

ROWS = [
    *_forms("solve", "u", lambda u: jm.solve(FB, u, P, G), BATCH),
    *_forms("solve", "guess", lambda g: jm.solve(FB, UB, P, g),
            [("(m,)", G, "doc", None), ("(N, m)", np.tile(G, (3, 1)), "doc", None), ("(3,)", np.ones(3), "err", None)]),
    *_forms("solve_stroke", "us", lambda u: jm.solve_stroke(FB, u, P, G), STROKE),
    *_forms("stroke_kinematics", "us", lambda u: jm.stroke_kinematics(FB, u, P, G), STROKE),
    *_forms("motion", "drive", _law_or_samples(lambda d, t: jm.motion(FB, d, t, P, G)), DRIVES, names=("Samples.u",)),
    *_forms("inverse_dynamics", "drive", _law_or_samples(lambda d, t: jm.inverse_dynamics(FB_MODEL, d, t, P, G)), DRIVES,
            names=("Samples.u",)),
    *_forms("inverse_dynamics_at", "u", lambda u: jm.inverse_dynamics_at(FB_MODEL, u, UD, UDD, P, G), BATCH),
    *_forms("inverse_dynamics_at", "u_dot", lambda ud: jm.inverse_dynamics_at(FB_MODEL, UB, ud, UDD, P, G),
            [("scalar", 0.5, "doc", None), ("(dof,)", np.array([0.5]), "doc", "scalar"), ("(N,)", np.full(3, 0.5), "doc", None),
             ("(N, dof)", np.full((3, 1), 0.5), "doc", "(N,)"), ("(N, 2)", np.ones((3, 2)), "err", None)]),
    *_forms("statics", "u", lambda u: jm.statics(FB_MODEL, u, P, G), BATCH),
    *_forms("equilibrium", "bounds", lambda b: jm.equilibrium(FB_MODEL, P, b, G),
            [("scalar", (1.0, 1.6), "doc", None), ("(dof,)", (np.array([1.0]), np.array([1.6])), "doc", "scalar")]),
    *_forms("equilibrium", "u0", lambda u0: jm.equilibrium(FB_MODEL, P, (1.0, 1.6), G, u0=u0),
            [("scalar", 1.3, "doc", None), ("(dof,)", np.array([1.3]), "doc", "scalar")]),
    *_forms("forward_dynamics", "u0", lambda u0: _forward(FB_MODEL, P, G, u0, 0.5),
            [("scalar", U, "doc", None), ("(dof,)", np.array([U]), "doc", "scalar"), ("jnp (dof,)", jnp.array([U]), "doc", "scalar"),
             ("dict", {"theta2": U}, "doc", "scalar"), ("(N,)", UB, "err", None), ("(N, dof)", UB[:, None], "err", None)]),
    *_forms("forward_dynamics", "u_dot0", lambda ud0: _forward(FB_MODEL, P, G, U, ud0),
            [("scalar", 0.5, "doc", None), ("(dof,)", jnp.array([0.5]), "doc", "scalar"), ("(2,)", np.ones(2), "err", None)]),
    *_forms("forward_dynamics", "guess", lambda g: _forward(FB_MODEL, P, g, U, 0.5),
            [("(m,)", G, "doc", None), ("(N, m)", np.tile(G, (3, 1)), "err", None), ("(3,)", np.ones(3), "err", None)]),
    *_forms("generalized_forces", "u", lambda u: jm.generalized_forces(FB_MODEL, Q, u, UD, UDD, P), ONE_STATE),
    *_forms("generalized_forces", "u_dot", lambda ud: jm.generalized_forces(FB_MODEL, Q, np.array([U]), ud, UDD, P),
            [("scalar", 0.5, "any", None), ("(dof,)", UD, "doc", "scalar"), ("(2,)", np.ones(2), "err", None)]),
    *_forms("generalized_forces", "q", lambda q: jm.generalized_forces(FB_MODEL, q, np.array([U]), UD, UDD, P),
            [("(m,)", Q, "doc", None), ("(3,)", np.ones(3), "err", None), ("(N, m)", np.tile(Q, (3, 1)), "err", None)]),
    *_forms("mass_matrix", "u", lambda u: jm.mass_matrix(FB_MODEL, Q, u, P), ONE_STATE),
    *_forms("kinetic_energy", "u", lambda u: jm.kinetic_energy(FB_MODEL, Q, u, UD, P), ONE_STATE),
    *_forms("potential_energy", "u", lambda u: jm.potential_energy(FB_MODEL, Q, u, P), ONE_STATE),
    *_forms("input_derivatives", "u", lambda u: jm.input_derivatives(FB, Q, u, P), ONE_STATE),
    *_forms("Linkage.solve", "us", lambda u: LK.solve(u), [(f, LK_U if f == "(N,)" else LK_U[:, None] if f == "(N, dof)" else v, e, s)
                                                          for f, v, e, s in STROKE]),
    *_forms("Linkage.statics", "u", lambda u: LK.statics(u), [("(N,)", LK_U, "doc", None), ("(N, dof)", LK_U[:, None], "doc", "(N,)"),
                                                              ("(N, 2)", np.ones((3, 2)), "err", None)]),
    *_forms("Linkage.motion", "drive", _law_or_samples(lambda d, t: LK.motion(d, t)),
            [("scalar", _drive(LK_U[0], 0.5), "doc", None), ("(dof,)", _drive(LK_U[:1], np.array([0.5])), "doc", "scalar"),
             ("Samples (N,)", jm.Samples(LK_U, 0.5, 0.0), "doc", None),
             ("Samples (N, dof)", jm.Samples(LK_U[:, None], 0.5, 0.0), "doc", "Samples (N,)")]),
    *_forms("Linkage.inverse_dynamics", "drive", _law_or_samples(lambda d, t: LK.inverse_dynamics(d, t)),
            [("scalar", _drive(LK_U[0], 0.5), "doc", None), ("(dof,)", _drive(LK_U[:1], np.array([0.5])), "doc", "scalar"),
             ("Samples (N, 2)", jm.Samples(np.ones((3, 2)), 0.0, 0.0), "err", None)], names=("Samples.u",)),
    *_forms("time_derivatives", "fn", lambda fn: jm.time_derivatives(fn, 0.1),
            [("scalar", _drive(0.9, 0.5), "doc", None), ("(dof,)", _drive(np.array([0.9]), np.array([0.5])), "doc", None)]),
    # two inputs
    *_forms("solve (2 inputs)", "u", lambda u: jm.solve(FIVE, u, P5, G5), TWO_BATCH),
    *_forms("inverse_dynamics_at (2 inputs)", "u",
            lambda u: jm.inverse_dynamics_at(FIVE_MODEL, u, np.zeros(2), np.zeros(2), P5, G5), TWO_BATCH),
    *_forms("generalized_forces (2 inputs)", "u",
            lambda u: jm.generalized_forces(FIVE_MODEL, Q5, u, np.array([0.3, -0.2]), np.zeros(2), P5), TWO_STATE),
    *_forms("mass_matrix (2 inputs)", "u", lambda u: jm.mass_matrix(FIVE_MODEL, Q5, u, P5), TWO_STATE),
    *_forms("forward_dynamics (2 inputs)", "u0", lambda u0: _forward(FIVE_MODEL, P5, G5, u0, np.zeros(2)),
            [("scalar", 1.2, "err", None), ("(dof,)", U5, "doc", None), ("dict", dict(zip(FIVE.inputs, U5)), "doc", "(dof,)"),
             ("(N, dof)", U5B, "err", None)]),
]
BY_KEY = {(r.entry, r.arg, r.form): r for r in ROWS}
assert len(BY_KEY) == len(ROWS), "two rows with one name"


@functools.cache
def _result(entry, arg, form):
    return BY_KEY[entry, arg, form].call()


def _names(message: str, arg: str) -> bool:
    return re.search(rf"(?<![\w.]){re.escape(arg)}(?!\w)", message) is not None


def _assert_same(a, b, what):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb, f"{what}: results of different structure"
    for x, y in zip(la, lb):
        x, y = np.asarray(x), np.asarray(y)
        assert x.shape == y.shape, f"{what}: shape {x.shape} vs {y.shape}"
        np.testing.assert_array_equal(x, y, err_msg=what)


def _finite_somewhere(out):
    leaves = [np.asarray(x) for x in jax.tree_util.tree_leaves(out) if jnp.issubdtype(np.asarray(x).dtype, jnp.floating)]
    return any(np.isfinite(x).any() for x in leaves)


def _param(row):
    marks = [pytest.mark.xfail(strict=True, reason=row.xfail)] if row.xfail else []
    return pytest.param(row, id=f"{row.entry}-{row.arg}[{row.form}]", marks=marks)


@pytest.mark.parametrize("row", [_param(r) for r in ROWS])
def test_documented_shapes(row):
    what = f"{row.entry}({row.arg}={row.form})"
    named = lambda e: any(_names(str(e), n) for n in (row.arg, *row.names))  # noqa: E731
    if row.expect == "err":
        with pytest.raises(ValueError) as info:
            row.call()
        assert named(info.value), f"{what}: the error does not name {row.arg!r}: {info.value}"
        return
    try:
        out = _result(row.entry, row.arg, row.form)
    except ValueError as e:
        if row.expect == "doc":
            raise AssertionError(f"{what}: a documented shape refused: {e}") from e
        assert named(e), f"{what}: the error does not name {row.arg!r}: {e}"
        return
    assert _finite_somewhere(out), f"{what}: no finite number in the result"
    if row.same is not None:
        try:
            ref = _result(row.entry, row.arg, row.same)
        except ValueError:
            pytest.fail(f"{what} gave a result where {row.same} was refused")
        _assert_same(out, ref, f"{what} vs {row.arg}={row.same}")


def test_forward_dynamics_one_input_array_is_the_scalar_call():
    """The issue's call: ``u0``, ``u_dot0`` as ``jnp.array([x])`` for a one-input model give the
    scalar call's trajectory, bit for bit (the documented ``(dof,)``)."""
    a = _forward(FB_MODEL, P, G, U, 0.5)
    b = _forward(FB_MODEL, P, G, jnp.array([U]), jnp.array([0.5]))
    assert int(a.status) == jm.Status.CONVERGED
    _assert_same(a, b, "forward_dynamics((1,)) vs scalar")


def test_forward_dynamics_checks_before_tracing():
    """A wrong shape is answered eagerly, naming the argument, not from a compiled scan."""
    for kwargs, name in [(dict(u0=np.ones(2)), "u0"), (dict(u_dot0=np.ones((2, 1))), "u_dot0"), (dict(guess=np.ones((2, 2))), "guess")]:
        args = dict(u0=U, u_dot0=0.5, guess=G) | kwargs
        with pytest.raises(ValueError, match=rf"\b{name}\b.*shape"):
            jm.forward_dynamics(FB_MODEL, P, args["u0"], args["u_dot0"], args["guess"], h=0.01, steps=2)


def test_a_one_sample_stroke_is_that_sample_of_a_longer_one():
    """Every public entry point that takes a stroke (``(1,)`` and ``(1, dof)``) or a time
    array (``(1,)``: times are 1-D) accepts one sample, and gives the numbers of that sample
    inside a longer array (to rounding: a one-point stroke is solved from its guess, not
    continued to).  A one-sample time array raised on dcea8c7."""
    us = np.linspace(0.6, 1.4, 5)
    guess = jnp.array([0.4, 1.7])
    full_sol = jm.solve_stroke(FB, us, P, guess)
    drive = jm.ConstantSpeed(0.6, 0.2)
    t = np.linspace(0.0, 4.0, 5)
    full_mo = jm.motion(FB, drive, t, P, guess)
    full_id = jm.inverse_dynamics(FB_MODEL, drive, t, P, guess)
    k = 3
    g = np.asarray(full_sol.q[k])
    for shape in ((1,), (1, 1)):
        one = jm.solve_stroke(FB, us[k : k + 1].reshape(shape), P, g)
        np.testing.assert_allclose(np.asarray(one.q), np.asarray(full_sol.q[k : k + 1]), rtol=0, atol=1e-12)
    tk = t[k : k + 1]
    mo = jm.motion(FB, drive, tk, P, g)
    np.testing.assert_allclose(np.asarray(mo.q_ddot), np.asarray(full_mo.q_ddot[k : k + 1]), rtol=0, atol=1e-10)
    inv = jm.inverse_dynamics(FB_MODEL, drive, tk, P, g)
    np.testing.assert_allclose(np.asarray(inv.tau), np.asarray(full_id.tau[k : k + 1]), rtol=0, atol=1e-10)
