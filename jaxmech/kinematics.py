"""Drive laws and kinematics (velocities, accelerations) by autodiff of the implicit root.

With ``q = q*(u, p)`` the solved positions and a drive law ``u(t)``, the time
derivatives are nested forward-mode derivatives of ``t -> q*(u(t), p)``:

    q_dot  = q' u_dot,      q_ddot = q' u_ddot + q''[u_dot, u_dot],

with ``q' = dq/du`` and ``q'' = d2q/du2`` given by the implicit function theorem
(``implicit.input_derivatives``).  Nothing is differentiated through Newton iterations.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .mechanism.mechanism import Mechanism
from .continuation.solve import stroke
from .solver.inputs import as_coords, as_inputs
from .solver import implicit
from .solver.options import SolverOptions
from .solver.solution import Solution
from .solver.xla import jit

__all__ = ["ConstantSpeed", "Ramp", "SmoothStart", "Samples", "drive_rates", "point_kinematics", "check_samples",
           "Motion", "input_derivatives", "one_state", "time_derivatives", "motion", "drive_samples", "split_drive",
           "join_drive", "stroke_kinematics", "StrokeKinematics", "sample_kinematics", "chain_rule"]


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


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Samples:
    """A drive given by its samples instead of a time law: inputs ``u``, their rates
    ``u_dot`` and accelerations ``u_ddot``, ``(N,)`` for one input or ``(N, dof)``, in the
    order the stroke passes them (it may reverse: a rocker drive, a measured input).
    `t` (s, optional): the samples' times, for time-dependent loads (zeros if not given).

    Every function that takes a drive law (``motion``, ``inverse_dynamics``) takes
    ``Samples`` too, with no ``t`` argument: positions are solved by continuation along
    ``u`` and the rates come from the samples themselves, not from a derivative of a law.
    """

    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    t: jax.Array | None = None

    @property
    def times(self):
        """The samples' times (s): `t`, or zeros."""
        return jnp.zeros(jnp.shape(self.u)[:1], jnp.result_type(self.u, float)) if self.t is None else self.t


def check_samples(mech: Mechanism, s: Samples) -> Samples:
    """``Samples`` with its rates broadcast to its inputs' shape ``(N, dof)`` (a scalar rate:
    the same at every sample); ``ValueError`` naming the field whose shape does not fit."""
    xp = jnp if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(s)) else np
    u = xp.asarray(s.u)
    if mech.dof == 1 and u.ndim == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[0] < 1 or u.shape[1] != mech.dof:
        raise ValueError(f"{mech.name}: Samples.u must have shape (N,) or (N, {mech.dof}) with N >= 1, got {xp.shape(s.u)}")
    out = {"u": u}
    for name in ("u_dot", "u_ddot", "t"):
        v = getattr(s, name)
        if v is None:
            out[name] = None
            continue
        v = xp.asarray(v)
        want = u.shape if name != "t" else u.shape[:1]
        if name != "t" and mech.dof == 1 and v.ndim == 1 and v.shape[0] == u.shape[0]:
            v = v[:, None]
        try:
            out[name] = xp.broadcast_to(v, want)
        except ValueError:
            raise ValueError(f"{mech.name}: Samples.{name} of shape {xp.shape(getattr(s, name))} does not fit u of shape {u.shape}") from None
    return Samples(**out)


def drive_rates(drive, t, dof: int):
    """``(u, u_dot, u_ddot)``, each ``(N, dof)``, of a drive at the times ``t (N,)``: a time
    law's by nested forward mode, ``Samples`` as given (traceable)."""
    if isinstance(drive, Samples):
        return tuple(jnp.reshape(jnp.asarray(x), (-1, dof)) for x in (drive.u, drive.u_dot, drive.u_ddot))
    return jax.vmap(lambda t_: time_derivatives(lambda s: jnp.reshape(drive(s), (dof,)), t_))(t)


# --------------------------------------------------------------------------- derivatives
def one_state(mech: Mechanism, q, u, **rates):
    """The arrays of one state for the functions that take one (``input_derivatives``,
    ``generalized_forces``, ``mass_matrix``...): ``q (m,)``, then ``u`` and each of `rates`
    (by argument name) ``(dof,)``; for one input a bare number is its ``(1,)``, and a
    mapping by name is accepted.  ``ValueError`` naming the argument for any other shape, at
    trace time (a batch: ``jax.vmap`` the function)."""
    q_in = q
    q = as_coords(mech, q, "q")
    if q.ndim != 1:
        raise ValueError(f"{mech.name}: q must have shape ({len(mech.coords)},) at one state (vmap the function for a batch), "
                         f"got shape {np.shape(q_in)}")
    out = [q]
    for name, x in (("u", u), *rates.items()):
        x_in = x
        x = as_inputs(mech, x, name)
        if x.ndim != 1:
            raise ValueError(f"{mech.name}: {name} must have shape ({mech.dof},) at one state (vmap the function for a batch), "
                             f"got shape {np.shape(x_in) if not isinstance(x_in, Mapping) else x.shape[:-1]}")
        out.append(x)
    return tuple(out)


def input_derivatives(mech: Mechanism, q, u, p):
    """``dq/du`` ``(m, dof)`` and ``d2q/du2`` ``(m, dof, dof)`` at one solved sample, ``q (m,)``
    and ``u (dof,)`` (a number for one input); units rad (or m) per unit input.

    ``jaxmech.solver.implicit.input_derivatives`` with the sample's shapes checked: one
    Jacobian, one factorisation and one second directional derivative per input pair serve
    both orders (``Phi_q q' = -Phi_u``, ``Phi_q q''[j, k] = -D2 Phi[x_j, x_k]``).  ``q`` is
    the solver's root, itself attached to ``(u, p)`` by the implicit function theorem, so
    these are differentiable in ``u`` and ``p`` again.  Samples with NaN positions give
    zeros (mask them by status).
    """
    q, u = one_state(mech, q, u)
    return implicit.input_derivatives(mech, q, u, p)


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


class SampleKinematics(NamedTuple):
    """Kinematics at one sample (``sample_kinematics``; unpacks like the 6-tuple it
    replaces): the inputs `u` and their rates, the coordinates' rates, and ``points =
    {name: (pos, vel, acc)}`` (complex, m, m/s, m/s^2)."""

    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    q_dot: jax.Array
    q_ddot: jax.Array
    points: dict


class SampleMotion(NamedTuple):
    """One sample's motion from its drive rates (``_one_sample``), NaN where it failed:
    coordinates `q` and their rates, the per-unit-input derivatives `dq_du`, `d2q_du2`, and
    ``points = {name: (pos, vel, acc)}``."""

    q: jax.Array
    q_dot: jax.Array
    q_ddot: jax.Array
    dq_du: jax.Array
    d2q_du2: jax.Array
    points: dict


def sample_kinematics(mech: Mechanism, point_names: Sequence[str], drive: Callable, p, t, q, d1, d2) -> SampleKinematics:
    """Kinematics at one solved sample from its per-unit-input derivatives ``d1 = dq/du``,
    ``d2 = d2q/du2`` (as ``stroke_kinematics`` gives them): a ``SampleKinematics`` ``(u,
    u_dot, u_ddot, q_dot, q_ddot, points)`` with ``points = {name: (pos, vel, acc)}``.  Finite wherever ``q``,
    ``d1`` and ``d2`` are (give placeholders at failed samples and mask afterwards): the one
    evaluation that ``motion``, sweeps and design share.
    """
    u, ud, udd = time_derivatives(lambda t_: jnp.reshape(drive(t_), (mech.dof,)), t)
    qd, qdd = chain_rule(d1, d2, ud, udd)
    return SampleKinematics(u, ud, udd, qd, qdd, point_kinematics(mech, point_names, p, q, qd, qdd, u, ud, udd))


def point_kinematics(mech: Mechanism, point_names: Sequence[str], p, q, qd, qdd, u, ud, udd) -> dict:
    """``{name: (position, velocity, acceleration)}`` (complex ``x + i y``: m, m/s, m/s^2) of
    the named points at one sample whose coordinates' and inputs' rates are known.

    Points need no further implicit derivatives: along the exact second-order path
    ``(q + qd s + qdd s^2/2, u + ud s + udd s^2/2)`` their first two ``s``-derivatives at
    ``s = 0`` are the true velocity and acceleration."""
    pts = {}
    zero = jnp.zeros((), jnp.result_type(q))
    for name in point_names:

        def along(s_, name=name):
            return mech.point(name, q + qd * s_ + 0.5 * qdd * s_**2, u + ud * s_ + 0.5 * udd * s_**2, p)

        pts[name] = time_derivatives(along, zero)
    return pts


def _one_sample(mech: Mechanism, point_names: Sequence[str], p, u, ud, udd, q, d1, d2) -> SampleMotion:
    """One sample's kinematics from its drive rates, NaN wherever the sample failed."""
    ok = jnp.all(jnp.isfinite(q))
    qs = jnp.where(ok, q, 0.0)
    d1 = jnp.where(ok, d1, 0.0)
    d2 = jnp.where(ok, d2, 0.0)
    qd, qdd = chain_rule(d1, d2, ud, udd)
    pts = point_kinematics(mech, point_names, p, qs, qd, qdd, u, ud, udd)
    nan = lambda x: jnp.where(ok, x, jnp.nan)  # noqa: E731
    return SampleMotion(q, nan(qd), nan(qdd), nan(d1), nan(d2), jax.tree_util.tree_map(nan, pts))


def split_drive(drive):
    """``(static part, traced leaves)`` of a drive for a compiled call: a drive that is a
    pytree of arrays (``ConstantSpeed``, ``Samples``) is traced, so one program serves every
    speed; any other function is static (it is hashable), recompiled only when it changes."""
    leaves, treedef = jax.tree_util.tree_flatten(drive)
    if leaves and all(isinstance(x, (jax.Array, float, int)) or hasattr(x, "dtype") for x in leaves):
        return treedef, leaves
    return drive, None


def join_drive(static, leaves):
    """The drive ``split_drive`` split."""
    return static if leaves is None else jax.tree_util.tree_unflatten(static, leaves)


@functools.partial(jit, static_argnums=(0, 1, 2))
def _motion_eval(mech, point_names, drive_static, drive_leaves, p, t, q, d1, d2):
    drive = join_drive(drive_static, drive_leaves)
    u, ud, udd = drive_rates(drive, t, mech.dof)
    out = jax.vmap(lambda *a: _one_sample(mech, point_names, p, *a))(u, ud, udd, q, d1, d2)
    return (u, ud, udd) + tuple(out)


def drive_samples(mech: Mechanism, drive, t):
    """The stroke ``us (N, dof)`` and the times ``t (N,)`` of a drive: a time law at the
    times `t` (required), ``Samples`` at their own (`t` must then be None)."""
    if isinstance(drive, Samples):
        if t is not None:
            raise ValueError(f"{mech.name}: a Samples drive carries its own times (Samples(t=...)); leave t out")
        drive = check_samples(mech, drive)
        return drive, drive.u, jnp.asarray(drive.times)
    if t is None:
        raise ValueError(f"{mech.name}: t (the sample times, s) is required for a drive law; or give the drive as Samples(u, u_dot, u_ddot)")
    t = jnp.asarray(t)
    if t.ndim != 1:
        raise ValueError(f"{mech.name}: t must be a 1-D array of times, got shape {t.shape}")
    return drive, jax.vmap(drive)(t), t


def motion(
    mech: Mechanism,
    drive: Callable,
    t=None,
    p: Mapping | None = None,
    guess=None,
    *,
    points: Sequence[str] | None = None,
    options: SolverOptions = SolverOptions(),
) -> Motion:
    """Positions, velocities and accelerations along a drive (one design).

    **Arguments**

    - `drive`: any differentiable ``u(t)`` (a pytree such as ``SmoothStart`` or a plain
      function), scalar for one input or ``(dof,)``; or ``Samples(u, u_dot, u_ddot)`` of
      the inputs and their rates (then no `t`: a measured or reversing input, no time law).
    - `t`: ``(N,)`` times (s), in order: positions are solved by continuation along them.
    - `p`: parameters (a model's whole dict is accepted: names the mechanism does not use
      are ignored); `guess`: coordinates at the first sample (picks the branch).
    - `points`: names of ``mech.points`` to differentiate too (default: all).

    **Returns** a ``Motion``: coordinates and every named point's position, velocity and
    acceleration (``motion.points[name]``).
    """
    if p is None or guess is None:
        raise ValueError(f"{mech.name}: motion needs the parameters p= and a guess= at the first sample")
    point_names = tuple(mech.points) if points is None else tuple(points)
    for n in point_names:
        if n not in mech.points:
            raise ValueError(f"{mech.name}: unknown point {n!r}; defined points: {list(mech.points)}")
    drive, us, t = drive_samples(mech, drive, t)
    # one compiled pass gives positions and dq/du, d2q/du2; the drive's chain rule follows
    sol, e1, e2 = stroke(mech, us, p, guess, options, derivs=True)
    dtype = sol.q.dtype
    pj = {k: jnp.asarray(p[k], dtype) for k in mech.params}
    static, leaves = split_drive(drive)
    if leaves is not None:
        leaves = [jnp.asarray(x, dtype) for x in leaves]
    out = _motion_eval(mech, point_names, static, leaves, pj, t.astype(dtype), sol.q, e1, e2)
    u, ud, udd, q, qd, qdd, d1, d2, pts = out
    return Motion(
        t=t, u=u, u_dot=ud, u_ddot=udd, q=q, q_dot=qd, q_ddot=qdd, dq_du=d1, d2q_du2=d2,
        points=pts, status=sol.status, coords=mech.coords, inputs=mech.inputs,
    )


class StrokeKinematics(NamedTuple):
    """``stroke_kinematics``'s result (a named tuple: ``sol, d1, d2 = ...`` still unpacks it).

    - `solution`: the stroke's ``Solution`` (positions, per-point statuses), ``(..., N)``.
    - `dq_du`: ``(..., N, m, dof)`` first derivatives of the coordinates with respect to the
      inputs (rad or length per unit input), NaN where the status is not ``CONVERGED``.
    - `d2q_du2`: ``(..., N, m, dof, dof)`` second derivatives, NaN likewise.
    """

    solution: Solution
    dq_du: jax.Array
    d2q_du2: jax.Array


def stroke_kinematics(mech: Mechanism, us, p: Mapping, guess, *, options: SolverOptions = SolverOptions()) -> StrokeKinematics:
    """Positions and per-unit-input derivatives over a stroke ``us``, for one design or a
    batch of designs (``p`` leaves of shape ``(D,)``), in one compiled pass.

    **Returns** a ``StrokeKinematics`` ``(solution, dq_du (..., N, m, dof), d2q_du2 (..., N,
    m, dof, dof))``; NaN where the status is not ``CONVERGED``.  The derivatives are those of
    ``input_derivatives`` (differentiable again in ``u`` and ``p``), computed together with
    the solve.
    """
    return StrokeKinematics(*stroke(mech, us, p, guess, options, derivs=True))
