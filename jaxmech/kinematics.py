"""Drive laws and kinematics (velocities, accelerations) by autodiff of the implicit root.

With ``q = q*(u, p)`` the solved positions and a drive law ``u(t)``, the time
derivatives are nested forward-mode derivatives of ``t -> q*(u(t), p)``:

    q_dot  = q' u_dot,      q_ddot = q' u_ddot + q''[u_dot, u_dot],

with ``q' = dq/du`` and ``q'' = d2q/du2`` given by the implicit function theorem
(``implicit.implicit_root``).  Nothing is differentiated through Newton iterations.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp

from .mechanism import Mechanism
from .continuation import stroke
from .stored import cached_call
from .implicit import implicit_root, root_derivatives
from .options import SolverOptions
from .xla import jit

__all__ = [
    "ConstantSpeed",
    "Ramp",
    "SmoothStart",
    "Motion",
    "input_derivatives",
    "time_derivatives",
    "motion",
    "stroke_kinematics",
    "sample_kinematics",
    "chain_rule",
]


# --------------------------------------------------------------------------- drive laws
@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ConstantSpeed:
    """``u(t) = u0 + w t`` (u0 in rad or m, w in rad/s or m/s)."""

    u0: jax.Array
    w: jax.Array

    def __call__(self, t):
        return self.u0 + self.w * t


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Ramp:
    """``u = u0`` before ``t0``, then ``u0 + w (t - t0)``: a velocity step at ``t0``, as a
    multibody code's ramp drive (its acceleration is an impulse that the smooth law avoids)."""

    u0: jax.Array
    w: jax.Array
    t0: jax.Array = 0.0

    def __call__(self, t):
        return self.u0 + self.w * jnp.maximum(t - self.t0, 0.0)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SmoothStart:
    """The flap report's smooth start: ``u = u0 + w ((t - t0) + (exp(-k (t - t0)) - 1) / k)``.

    Zero speed at ``t0``, speed ``w (1 - exp(-k (t - t0)))`` tending to ``w``; ``u = u0``
    before ``t0``.  ``k`` (1/s) sets how fast the nominal speed is reached.
    """

    u0: jax.Array
    w: jax.Array
    k: jax.Array
    t0: jax.Array = 0.0

    def __call__(self, t):
        tau = jnp.maximum(t - self.t0, 0.0)
        return self.u0 + self.w * (tau + jnp.expm1(-self.k * tau) / self.k)


# --------------------------------------------------------------------------- derivatives
def _root_fn(mech: Mechanism, sol_q, ok, p):
    """``u -> q*(u, p)`` around a solved sample (values fixed, derivatives implicit)."""
    return lambda u: implicit_root(mech, sol_q, ok, u, p)


def input_derivatives(mech: Mechanism, q, u, p):
    """``dq/du`` and ``d2q/du2`` at one solved sample.

    Differentiating ``Phi(q(u), u) = 0`` once and twice along the inputs:

        Phi_q q' = -Phi_u,        Phi_q q''[j, k] = -D2 Phi[x_j, x_k],  x_j = (q'_j, e_j),

    so one Jacobian, one factorisation and one second directional derivative per input
    pair serve both orders.  ``q`` is the solver's root, itself attached to ``(u, p)`` by the
    implicit function theorem, so these are differentiable in ``u`` and ``p`` again.

    Shapes ``(m, dof)`` and ``(m, dof, dof)``; units rad (or m) per unit input.  Samples
    with NaN positions give zeros (mask them by status).
    """
    ok = jnp.all(jnp.isfinite(q))
    return root_derivatives(mech, jnp.where(ok, q, jnp.zeros_like(q)), u, p, ok)


def time_derivatives(fn: Callable, t):
    """``(x, x_dot, x_ddot)`` of any ``fn(t)`` by nested forward mode (one sample)."""

    def first(t_):
        return jax.jvp(fn, (t_,), (jnp.ones_like(t_),))

    (x, xd), (_, xdd) = jax.jvp(first, (t,), (jnp.ones_like(t),))
    return x, xd, xdd


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Motion:
    """Kinematics along a drive (a pytree; leading axis = time samples).

    - `t` (s), `u`, `u_dot`, `u_ddot`: the drive, ``(N, dof)``.
    - `q`, `q_dot`, `q_ddot`: coordinates and their time derivatives, ``(N, m)``.
    - `dq_du`, `d2q_du2`: per-unit-input derivatives, ``(N, m, dof)``, ``(N, m, dof, dof)``.
    - `points`: ``{name: (pos, vel, acc)}`` complex ``x + i y`` in m, m/s, m/s^2.
    - `status`: ``(N,)`` ``Status`` codes; failed samples are NaN in every field.
    """

    t: jax.Array
    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    q: jax.Array
    q_dot: jax.Array
    q_ddot: jax.Array
    dq_du: jax.Array
    d2q_du2: jax.Array
    points: dict
    status: jax.Array
    coords: tuple = dataclasses.field(metadata=dict(static=True), default=())
    inputs: tuple = dataclasses.field(metadata=dict(static=True), default=())

    def __getitem__(self, name: str):
        """Coordinate or input by name (positions)."""
        if name in self.coords:
            return self.q[..., self.coords.index(name)]
        if name in self.inputs:
            return self.u[..., self.inputs.index(name)]
        raise KeyError(f"unknown name {name!r}; coordinates {self.coords}, inputs {self.inputs}")


def chain_rule(d1, d2, u_dot, u_ddot):
    """Coordinate rates of one sample from its per-unit-input derivatives:
    ``q_dot = q' u_dot``, ``q_ddot = q' u_ddot + q''[u_dot, u_dot]`` (``d1 (m, dof)``,
    ``d2 (m, dof, dof)``).  The sums over the few inputs are written out: a ``dot``'s
    rounding under ``vmap`` depends on the batch size."""
    qd = jnp.sum(d1 * u_dot, axis=-1)
    qdd = jnp.sum(d1 * u_ddot, axis=-1) + jnp.sum(d2 * u_dot[:, None] * u_dot[None, :], axis=(-2, -1))
    return qd, qdd


def sample_kinematics(mech: Mechanism, point_names: Sequence[str], drive: Callable, p, t, q, d1, d2):
    """Kinematics at one solved sample from its per-unit-input derivatives ``d1 = dq/du``,
    ``d2 = d2q/du2`` (as ``stroke_kinematics`` gives them): ``(u, u_dot, u_ddot, q_dot,
    q_ddot, points)`` with ``points = {name: (pos, vel, acc)}``.  Finite wherever ``q``,
    ``d1`` and ``d2`` are (give placeholders at failed samples and mask afterwards): the one
    evaluation that ``motion``, sweeps and design share.
    """
    u, ud, udd = time_derivatives(lambda t_: jnp.reshape(drive(t_), (mech.dof,)), t)
    qd, qdd = chain_rule(d1, d2, ud, udd)
    # Points need no further implicit derivatives: along the exact second-order path
    # (q + qd s + qdd s^2/2, u + ud s + udd s^2/2) their first two s-derivatives at s = 0
    # are the true velocity and acceleration.
    pts = {}
    for name in point_names:

        def along(s_, name=name):
            return mech.point(name, q + qd * s_ + 0.5 * qdd * s_**2, u + ud * s_ + 0.5 * udd * s_**2, p)

        pts[name] = time_derivatives(along, jnp.zeros_like(t))
    return u, ud, udd, qd, qdd, pts


def _one_sample(mech: Mechanism, point_names: Sequence[str], drive: Callable, p, t, q, d1, d2):
    """``sample_kinematics`` with NaN wherever the sample failed (NaN positions)."""
    ok = jnp.all(jnp.isfinite(q))
    qs = jnp.where(ok, q, 0.0)
    d1 = jnp.where(ok, d1, 0.0)
    d2 = jnp.where(ok, d2, 0.0)
    u, ud, udd, qd, qdd, pts = sample_kinematics(mech, point_names, drive, p, t, qs, d1, d2)
    nan = lambda x: jnp.where(ok, x, jnp.nan)  # noqa: E731
    return (u, ud, udd, q, nan(qd), nan(qdd), nan(d1), nan(d2), jax.tree_util.tree_map(nan, pts))


@functools.partial(jit, static_argnums=(0, 1, 2))
def _motion_eval_leaves(mech, point_names, drive_def, drive_leaves, p, t, q, d1, d2):
    drive = jax.tree_util.tree_unflatten(drive_def, drive_leaves)
    return jax.vmap(lambda t_, q_, a_, b_: _one_sample(mech, point_names, drive, p, t_, q_, a_, b_))(t, q, d1, d2)


def _motion_eval(mech, point_names, drive, p, t, q, d1, d2):
    # A drive that is a pytree of arrays is traced (one compile for every speed); a plain
    # function is static (it is hashable), so it recompiles only when the function changes.
    leaves, treedef = jax.tree_util.tree_flatten(drive)
    if all(isinstance(x, (jax.Array, float, int)) or hasattr(x, "dtype") for x in leaves) and leaves:
        leaves = [jnp.asarray(x, t.dtype) for x in leaves]
        return cached_call(_motion_eval_leaves, (mech, point_names, treedef), (leaves, p, t, q, d1, d2))
    return _motion_eval_static(mech, point_names, drive, p, t, q, d1, d2)


@functools.partial(jit, static_argnums=(0, 1, 2))
def _motion_eval_static(mech, point_names, drive, p, t, q, d1, d2):
    return jax.vmap(lambda t_, q_, a_, b_: _one_sample(mech, point_names, drive, p, t_, q_, a_, b_))(t, q, d1, d2)


def motion(
    mech: Mechanism,
    drive: Callable,
    t,
    p: Mapping,
    guess,
    *,
    points: Sequence[str] | None = None,
    options: SolverOptions = SolverOptions(),
) -> Motion:
    """Positions, velocities and accelerations along a drive law ``u(t)`` (one design).

    **Arguments**

    - `drive`: any differentiable ``u(t)`` (a pytree such as ``SmoothStart`` or a plain
      function); scalar for one input or ``(dof,)``.
    - `t`: ``(N,)`` times (s), in order: positions are solved by continuation along them.
    - `p`: parameters; `guess`: coordinates at ``t[0]`` (picks the branch).
    - `points`: names of ``mech.points`` to differentiate too (default: all).

    **Returns** a ``Motion``.
    """
    t = jnp.asarray(t)
    if t.ndim != 1:
        raise ValueError(f"{mech.name}: t must be a 1-D array of times, got shape {t.shape}")
    point_names = tuple(mech.points) if points is None else tuple(points)
    for n in point_names:
        if n not in mech.points:
            raise ValueError(f"{mech.name}: unknown point {n!r}; defined points: {list(mech.points)}")
    us = jax.vmap(drive)(t)
    # one compiled pass gives positions and dq/du, d2q/du2; the drive's chain rule follows
    sol, e1, e2 = stroke(mech, us, p, guess, options, derivs=True)
    pj = {k: jnp.asarray(v, sol.q.dtype) for k, v in p.items()}
    u, ud, udd, q, qd, qdd, d1, d2, pts = _motion_eval(mech, point_names, drive, pj, t.astype(sol.q.dtype), sol.q, e1, e2)
    return Motion(
        t=t, u=u, u_dot=ud, u_ddot=udd, q=q, q_dot=qd, q_ddot=qdd, dq_du=d1, d2q_du2=d2,
        points=pts, status=sol.status, coords=mech.coords, inputs=mech.inputs,
    )


def stroke_kinematics(mech: Mechanism, us, p: Mapping, guess, *, options: SolverOptions = SolverOptions()):
    """Positions and per-unit-input derivatives over a stroke ``us``, for one design or a
    batch of designs (``p`` leaves of shape ``(D,)``), in one compiled pass.

    **Returns** ``(solution, dq_du (..., N, m, dof), d2q_du2 (..., N, m, dof, dof))``; NaN
    where the status is not ``CONVERGED``.  The derivatives are those of ``input_derivatives``
    (differentiable again in ``u`` and ``p``), computed together with the solve.
    """
    return stroke(mech, us, p, guess, options, derivs=True)
