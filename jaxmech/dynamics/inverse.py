"""Inverse dynamics: the driving forces, the constraint reactions and (for a model with
joints) every joint's reaction, at a batch of independent states (``inverse_dynamics_at``,
``statics``) or along a drive (``inverse_dynamics``), by virtual power
(``virtual_power.balance``) and the per-body Newton-Euler equations
(``reactions.joint_reactions``) at positions solved by the engine."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation import stroke
from ..implicit import input_derivatives
from ..inputs import as_coords, as_inputs, batch_shape
from ..kinematics import chain_rule, drive_rates, drive_samples, join_drive, point_kinematics, split_drive
from ..options import SolverOptions
from ..positions import solve_one
from ..status import Status
from ..xla import jit
from .model import Model, mechanism_params, prepare_params
from .reactions import joint_reactions
from .virtual_power import balance, loaded_state

__all__ = ["InverseDynamics", "inverse_dynamics", "inverse_dynamics_at", "inverse_dynamics_batch", "statics"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class InverseDynamics:
    """Inverse-dynamics result (a pytree; leading axes = samples).

    - `t` (s), `u`, `u_dot`, `u_ddot` ``(..., dof)``; `q`, `q_dot`, `q_ddot` ``(..., m)``.
    - `tau`: driving force/torque on each input ``(..., dof)`` (N or N m), positive in the
      input's positive sense.
    - `reactions`: the loop equations' multipliers ``(..., m)`` (N for loops in metres; see
      ``virtual_power``): ``reaction("loop 2")`` pairs a loop's two rows as ``Fx + i Fy``.
    - `points`: ``{name: (position, velocity, acceleration)}`` of every named point of the
      mechanism (complex ``x + i y``: m, m/s, m/s^2).
    - `joints`: for a model with joints, ``{joint: F}``: the force (N, complex, global) that
      the joint's first body exerts on its second (``dynamics.joints``), from the per-body
      Newton-Euler equations; `joint_moments`: ``{joint: M}`` (N m) of prismatic joints.
    - `status`: position-solve ``Status`` per sample (NaN results where not CONVERGED).
    """

    t: jax.Array
    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    q: jax.Array
    tau: jax.Array
    reactions: jax.Array
    status: jax.Array
    q_dot: jax.Array | None = None
    q_ddot: jax.Array | None = None
    points: dict = dataclasses.field(default_factory=dict)
    joints: dict = dataclasses.field(default_factory=dict)
    joint_moments: dict = dataclasses.field(default_factory=dict)
    loops: tuple = dataclasses.field(metadata=dict(static=True), default=())

    def reaction(self, name):
        """The reaction named `name` (N, complex ``Fx + i Fy``, one per sample):

        - a joint's name (models with joints): the force its first body exerts on its second;
        - a loop's name (``Mechanism.equations``: ``"loop 1"``, or the constraints' mapping
          keys): the multipliers of that loop's two rows as ``Fx + i Fy`` (a real equation's
          one multiplier as a real number); an ``int`` k is the k-th loop (from 0).

        **Raises** ``ValueError`` for a name or index that is neither.
        """
        if isinstance(name, str) and name in self.joints:
            return self.joints[name]
        if isinstance(name, (int, np.integer)) and not isinstance(name, bool):
            if not 0 <= name < len(self.loops):
                raise ValueError(f"reaction({name}): there are {len(self.loops)} loops (0 to {len(self.loops) - 1}): "
                                 f"{[n for n, _ in self.loops]}")
            name = self.loops[name][0]
        for loop, rows in self.loops:
            if loop == name:
                if len(rows) == 2:
                    return jax.lax.complex(self.reactions[..., rows[0]], self.reactions[..., rows[1]])
                return self.reactions[..., rows[0]]
        known = list(self.joints) + [n for n, _ in self.loops]
        raise ValueError(f"no joint or loop named {name!r}; known: {known}")


def _sample(model: Model, quasi_static: bool, names, p, t, u, ud, udd, q, d1, d2):
    """Everything at one sample from its position and per-unit-input derivatives: the rates,
    the points' kinematics, the drive efforts, multipliers and joint reactions."""
    mech = model.mechanism
    ok = jnp.all(jnp.isfinite(q))
    qs = jnp.where(ok, q, 0.0)
    qd, qdd = chain_rule(jnp.where(ok, d1, 0.0), jnp.where(ok, d2, 0.0), ud, udd)
    st = loaded_state(model, q, u, ud, udd, p, t, inertia=not quasi_static, q_dot=qd, q_ddot=qdd)
    tau, lam = balance(model, st)
    nan = lambda x: jnp.where(ok, x, jnp.nan)  # noqa: E731
    pts = point_kinematics(mech, names, p, qs, qd, qdd, u, ud, udd)
    out = dict(tau=tau, reactions=lam, q_dot=nan(qd), q_ddot=nan(qdd), points=jax.tree_util.tree_map(nan, pts), joints={}, joint_moments={})
    if model.joints:
        _, out["joints"], out["joint_moments"] = joint_reactions(model, st)
    return out


def _at_one(model, quasi_static, names, options, u, ud, udd, p, t, guess):
    mech = model.mechanism
    sol = solve_one(mech, u, mechanism_params(model, p), guess, options)
    ok = sol.status == Status.CONVERGED
    d1, d2 = input_derivatives(mech, jnp.where(ok, sol.q, 0.0), u, mechanism_params(model, p), ok)
    return dict(_sample(model, quasi_static, names, p, t, u, ud, udd, sol.q, d1, d2), q=sol.q, status=sol.status)


@functools.partial(jit, static_argnums=(0, 1, 2))
def inverse_dynamics_batch(model, quasi_static, options, u, ud, udd, p, t, guess):
    """The compiled kernel of ``inverse_dynamics_at`` on a flat batch (jit; `model`,
    `quasi_static` and `options` static): `u`, `ud`, `udd` ``(n, dof)``, `p` leaves ``(n,)``,
    `t` ``(n,)``, `guess` ``(n, m)``, no checks.  Returns a dict of the ``InverseDynamics``
    fields (``q``, ``tau``, ``reactions``, ``status``, ``points``, ``joints``...)."""
    names = tuple(model.mechanism.points)
    return jax.vmap(lambda *a: _at_one(model, quasi_static, names, options, *a))(u, ud, udd, p, t, guess)


def _result(mech, t, u, ud, udd, fields) -> InverseDynamics:
    return InverseDynamics(t=t, u=u, u_dot=ud, u_ddot=udd, loops=mech.equations, **fields)


def inverse_dynamics_at(model: Model, u, u_dot, u_ddot, p: Mapping, guess, *, t=0.0, quasi_static: bool = False,
                        options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Driving forces and reactions at a batch of independent states (jit, vmapped).

    **Arguments**: `u`, `u_dot`, `u_ddot`: ``(..., dof)`` (or the bare batch for one input);
    `p`: parameters (arrays broadcast against the batch); `guess`: ``(..., m)`` coordinates
    near each solution (it picks the branch); `t`: time(s) for time-dependent loads;
    `quasi_static`: leave inertia out (``statics`` is this at rest).

    **Returns** an ``InverseDynamics`` with the broadcast batch shape in front.
    """
    mech = model.mechanism
    u = as_inputs(mech, u)
    ud = as_inputs(mech, u_dot, "u_dot")
    udd = as_inputs(mech, u_ddot, "u_ddot")
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(u, ud, udd, guess, float)
    p = prepare_params(model, p, dtype)
    t = jnp.asarray(t, dtype)
    shape = batch_shape(mech, {"u": u.shape[:-1], "u_dot": ud.shape[:-1], "u_ddot": udd.shape[:-1], "guess": guess.shape[:-1],
                               "t": t.shape, **{f"p[{k!r}]": v.shape for k, v in p.items()}})
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    args = [flat(x.astype(dtype), 1) for x in (u, ud, udd)]
    pf = {k: flat(v, 0) for k, v in p.items()}
    out = inverse_dynamics_batch(model, bool(quasi_static), options, *args, pf, flat(t, 0), flat(guess.astype(dtype), 1))
    out = jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), out)
    r = lambda x: x.reshape(shape + x.shape[1:])  # noqa: E731
    return _result(mech, jnp.broadcast_to(t, shape), r(args[0]), r(args[1]), r(args[2]), out)


def statics(model: Model, u, p: Mapping, guess, *, t=0.0, options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Statics at given poses: the holding torque (or force) on each input and every
    reaction, at rest under gravity and the loads (no inertia, zero rates), for a batch of
    inputs ``u (..., dof)``.  What a peer tool calls a static force analysis; for the input
    at which the loads balance with no drive, see ``equilibrium``.

    **Returns** an ``InverseDynamics`` (``tau``: the effort the drive must hold, N m or N;
    ``joints``: every joint's reaction for a model with joints)."""
    zero = jnp.zeros_like(as_inputs(model.mechanism, u))
    return inverse_dynamics_at(model, u, zero, zero, p, guess, t=t, quasi_static=True, options=options)


class AlongDrive(NamedTuple):
    """``_along``'s result: the drive's inputs `u` and their rates ``(N, dof)``, and every
    sample's dynamics `samples` (``_sample``'s mapping, leading axis N)."""

    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    samples: dict


@functools.partial(jit, static_argnums=(0, 1, 2, 3), stored=True)  # a new process loads it (jaxmech.stored)
def _along(model, quasi_static, names, drive_static, drive_leaves, p, t, q, d1, d2):
    drive = join_drive(drive_static, drive_leaves)
    u, ud, udd = drive_rates(drive, t, model.mechanism.dof)
    out = jax.vmap(lambda *a: _sample(model, quasi_static, names, p, *a))(t, u, ud, udd, q, d1, d2)
    return AlongDrive(u, ud, udd, out)


def inverse_dynamics(model: Model, drive, t=None, p: Mapping | None = None, guess=None, *, quasi_static: bool = False,
                     options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Driving force/torque and reactions along a drive (one design).

    **Arguments**

    - `drive`: ``u(t)``, a pytree drive law (``ConstantSpeed``, ``SmoothStart``...) or any
      differentiable function, scalar for one input or ``(dof,)``; or ``Samples(u, u_dot,
      u_ddot)`` (no `t`): the inputs and their rates, in the order the stroke passes them.
    - `t`: ``(N,)`` times (s) in order; positions are solved by continuation along them.
    - `p`: parameters; `guess`: coordinates at the first sample (picks the branch).
    - `quasi_static`: leave inertia out.

    **Returns** an ``InverseDynamics`` with leading axis ``N``; NaN where the position
    status is not ``CONVERGED``.

    Power balance (a check the tests make): ``tau . u_dot = dT/dt - Pi_loads``.
    """
    mech = model.mechanism
    if p is None or guess is None:
        raise ValueError(f"{mech.name}: inverse_dynamics needs the parameters p= and a guess= at the first sample")
    drive, us, t = drive_samples(mech, drive, t)
    model.check_params(p)
    # positions, dq/du and d2q/du2 in one compiled pass; the drive's rates give the rest
    sol, d1, d2 = stroke(mech, us, mechanism_params(model, p), guess, options, derivs=True)
    dtype = sol.q.dtype
    pj = prepare_params(model, p, dtype)
    static, leaves = split_drive(drive)
    if leaves is not None:
        leaves = [jnp.asarray(x, dtype) for x in leaves]
    u, ud, udd, out = _along(model, bool(quasi_static), tuple(mech.points), static, leaves, pj, t.astype(dtype), sol.q, d1, d2)
    return _result(mech, t, u, ud, udd, dict(out, q=sol.q, status=sol.status))
