"""Inverse dynamics: the driving forces and constraint reactions of a ``Model`` at a batch of
independent states (``inverse_dynamics_at``) or along a drive law (``inverse_dynamics``),
by virtual power (``virtual_power.generalized_forces``) at positions solved by the engine."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation import stroke
from ..kinematics import chain_rule, time_derivatives
from ..inputs import as_coords, as_inputs
from ..options import SolverOptions
from ..positions import solve_one
from .model import Model, mechanism_params, prepare_params
from .virtual_power import generalized_forces
from ..xla import jit

__all__ = ["InverseDynamics", "inverse_dynamics", "inverse_dynamics_at", "inverse_dynamics_batch"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class InverseDynamics:
    """Inverse-dynamics result (a pytree; leading axes = samples).

    - `t` (s), `u`, `u_dot`, `u_ddot` ``(..., dof)``, `q` ``(..., m)``.
    - `tau`: driving force/torque on each input ``(..., dof)`` (N or N m).
    - `reactions`: constraint multipliers ``(..., m)`` (N for loops in metres; sign in the
      module docstring); `reaction(i)` pairs loop ``i``'s two rows as ``x + i y``.
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

    def reaction(self, row: int):
        """Multipliers of rows ``row`` and ``row + 1`` (a complex loop) as ``Fx + i Fy`` (N)."""
        return jax.lax.complex(self.reactions[..., row], self.reactions[..., row + 1])


def _id_one(model, quasi_static, u, ud, udd, p, t, guess, options):
    sol = solve_one(model.mechanism, u, p, guess, options)
    tau, lam = generalized_forces(model, sol.q, u, ud, udd, p, t, inertia=not quasi_static)
    return sol.q, tau, lam, sol.status


@functools.partial(jit, static_argnums=(0, 1, 2))
def inverse_dynamics_batch(model, quasi_static, options, u, ud, udd, p, t, guess):
    """The compiled kernel of ``inverse_dynamics_at`` on a flat batch (jit; `model`,
    `quasi_static` and `options` static): `u`, `ud`, `udd` ``(n, dof)``, `p` leaves ``(n,)``,
    `t` ``(n,)``, `guess` ``(n, m)``, no checks.  Returns ``(q, tau, lam, status)``."""
    return jax.vmap(lambda *a: _id_one(model, quasi_static, *a, options))(u, ud, udd, p, t, guess)


def inverse_dynamics_at(model: Model, u, u_dot, u_ddot, p: Mapping, guess, *, t=0.0, quasi_static: bool = False,
                        options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Driving forces and reactions at a batch of independent states (jit, vmapped).

    **Arguments**: `u`, `u_dot`, `u_ddot`: ``(..., dof)`` (or the bare batch for one input);
    `p`: parameters (arrays broadcast against the batch); `guess`: ``(..., m)`` coordinates
    near each solution (it picks the branch); `t`: time(s) for time-dependent loads;
    `quasi_static`: leave inertia out.

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
    shape = np.broadcast_shapes(u.shape[:-1], ud.shape[:-1], udd.shape[:-1], guess.shape[:-1], t.shape,
                                *[v.shape for v in p.values()])
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    args = [flat(x.astype(dtype), 1) for x in (u, ud, udd)]
    pf = {k: flat(v, 0) for k, v in p.items()}
    q, tau, lam, status = inverse_dynamics_batch(model, bool(quasi_static), options, *args, pf, flat(t, 0), flat(guess.astype(dtype), 1))
    r = lambda x: x.reshape(shape + x.shape[1:])  # noqa: E731
    return InverseDynamics(t=jnp.broadcast_to(t, shape), u=r(args[0]), u_dot=r(args[1]), u_ddot=r(args[2]), q=r(q),
                           tau=r(tau), reactions=r(lam), status=r(status))


def _id_drive_one(model, quasi_static, drive, p, t_, q_, d1, d2):
    u, ud, udd = time_derivatives(lambda s: jnp.reshape(drive(s), (model.mechanism.dof,)), t_)
    qd, qdd = chain_rule(d1, d2, ud, udd)
    tau, lam = generalized_forces(model, q_, u, ud, udd, p, t_, inertia=not quasi_static, q_dot=qd, q_ddot=qdd)
    return u, ud, udd, tau, lam


@functools.partial(jit, static_argnums=(0, 1, 2))
def _id_drive_leaves(model, quasi_static, drive_def, drive_leaves, p, t, q, d1, d2):
    drive = jax.tree_util.tree_unflatten(drive_def, drive_leaves)
    return jax.vmap(lambda *a: _id_drive_one(model, quasi_static, drive, p, *a))(t, q, d1, d2)


@functools.partial(jit, static_argnums=(0, 1, 2))
def _id_drive_static(model, quasi_static, drive, p, t, q, d1, d2):
    return jax.vmap(lambda *a: _id_drive_one(model, quasi_static, drive, p, *a))(t, q, d1, d2)


def inverse_dynamics(model: Model, drive, t, p: Mapping, guess, *, quasi_static: bool = False,
                     options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Driving force/torque and reactions along a drive law ``u(t)`` (one design).

    **Arguments**

    - `drive`: ``u(t)``, a pytree drive law (``ConstantSpeed``, ``SmoothStart``...) or any
      differentiable function, scalar for one input or ``(dof,)``.
    - `t`: ``(N,)`` times (s) in order; positions are solved by continuation along them.
    - `p`: parameters; `guess`: coordinates at ``t[0]`` (picks the branch).
    - `quasi_static`: leave inertia out.

    **Returns** an ``InverseDynamics`` with leading axis ``N``; NaN where the position
    status is not ``CONVERGED``.

    Power balance (a check the tests make): ``tau . u_dot = dT/dt - Pi_loads``.
    """
    t = jnp.asarray(t)
    if t.ndim != 1:
        raise ValueError(f"t must be a 1-D array of times, got shape {t.shape}")
    us = jax.vmap(drive)(t)
    model.check_params(p)
    # positions, dq/du and d2q/du2 in one compiled pass; the drive's chain rule gives the rates
    sol, d1, d2 = stroke(model.mechanism, us, mechanism_params(model, p), guess, options, derivs=True)
    dtype = sol.q.dtype
    pj = prepare_params(model, p, dtype)
    tt = t.astype(dtype)
    leaves, treedef = jax.tree_util.tree_flatten(drive)
    # A pytree drive is traced (one compile for every speed); a plain function is static.
    if leaves and all(hasattr(x, "dtype") or isinstance(x, (int, float)) for x in leaves):
        res = _id_drive_leaves(model, bool(quasi_static), treedef, [jnp.asarray(x, dtype) for x in leaves], pj, tt, sol.q, d1, d2)
    else:
        res = _id_drive_static(model, bool(quasi_static), drive, pj, tt, sol.q, d1, d2)
    u, ud, udd, tau, lam = res
    return InverseDynamics(t=t, u=u, u_dot=ud, u_ddot=udd, q=sol.q, tau=tau, reactions=lam, status=sol.status)

