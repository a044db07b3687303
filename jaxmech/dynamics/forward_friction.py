"""Joint friction in forward dynamics: the inputs' accelerations of a ``Model`` with Coulomb
friction and viscous damping at its joints (``dynamics.friction``'s laws), at one state.

**The system.**  A joint's friction load ``s_j`` (a pin's moment on its second body, a
guide's force along its direction) does the virtual power ``s_j w_j``, ``w = G u_dot`` the
joints' relative speeds (``G = dw/du_dot``, ``(k, dof)``), so the equations of motion are
``M u_ddot = tau - h + G' s``: with the loads ``s`` known, the accelerations are
``u_ddot(s) = u_ddot_0 + M^-1 G' s`` (``u_ddot_0`` the frictionless ones).  The joints'
reactions are linear in the accelerations and in the friction loads, so along ``u_ddot(s)``
they are ``x(s) = x0 + X s``: ``x0`` the reactions at ``u_ddot_0`` and ``X`` the reactions to
a unit friction load at each joint together with the inertia of the accelerations it
causes (two eliminations: the state's loads with the inertia of ``u_ddot_0``, and the ``k``
unit loads each with the inertia of ``M^-1 G' e_j``).  Friction is then the
same small nonlinear system as in inverse dynamics, ``s = -mu r |F(x0 + X s)| sgn(w) -
c w``, one unknown per joint, solved by ``friction.solve_friction_loads``: Newton's method
from ``s = 0`` (the frictionless solution), attached to the state and the parameters by
the implicit function theorem (derivatives in every parameter, none through the
iterations).  Its status: ``converged`` (False: the accelerations are NaN, and the run
stops with ``Status.FRICTION``).

**The sign** is ``friction.friction_signs``' ``tanh(w / (width W))`` with ``W`` each joint's
speed scale given to the run (a forward run does not know its joints' largest speeds
before it runs them, as a stroke of inverse dynamics does).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.implicit import implicit_positions
from ..solver.linalg import solve_small
from .friction import (JointFriction, friction_joints, friction_norms, friction_signs, friction_terms, joint_speeds,
                       solve_friction_loads, unit_friction_solutions)
from .model import Model, geometry, masses
from .reactions import reaction_system, solve_reaction_system
from .virtual_power import balance, loaded_state

__all__ = ["friction_accelerations"]


class FrictionAccelerations(NamedTuple):
    """``friction_accelerations``' result at one state: the inputs' accelerations `u_ddot`
    ``(dof,)`` with friction (NaN where its Newton did not converge), the friction loads
    `friction` ``(k,)`` (N m at a pin, N in a guide, on the joint's second body) and
    `converged`."""

    u_ddot: jax.Array
    friction: jax.Array
    converged: jax.Array


def _tangents(model: Model, q, ok, u, p):
    """``(dq/du (m, dof), dr_G/du (nb, dof) complex, dphi/du (nb, dof))`` at a closed state."""
    mech = model.mechanism

    def poses(u_):
        qs = implicit_positions(mech, q, ok, u_, p)
        rg, ph, *_ = geometry(model, qs, u_, p)
        return qs, jnp.stack(rg), jnp.stack(ph)

    return jax.jacfwd(poses)(u)


def _inertia(mass, jr, jp, acc):
    """``{row: value}``: the Newton-Euler system's right-hand side (``reactions``: ``m a_G``
    and ``J alpha`` per body) of the input accelerations `acc` ``(dof,)`` or ``(dof, k)``
    alone (``a_G = dr_G/du acc``, ``alpha = dphi/du acc``)."""
    out = {}
    for k, (m, J) in enumerate(zip(*mass)):
        da = jr[k] @ acc
        out.update({3 * k: m * jnp.real(da), 3 * k + 1: m * jnp.imag(da), 3 * k + 2: J * (jp[k] @ acc)})
    return out


def friction_accelerations(model: Model, fr: JointFriction, scale, q, u, ud, p, t, M, tau) -> FrictionAccelerations:
    """The inputs' accelerations with joint friction at the state ``(q, u, u_dot = ud)``
    (module docstring): `scale` ``(k,)`` each joint's speed scale ``W`` (rad/s, m/s), `M`
    the mass matrix ``(dof, dof)``, `tau` ``(dof,)`` the generalized force of the run's
    motor, actuators and load on the inputs, `p` the parameters (friction's with them),
    `t` the time (s)."""
    dtype = q.dtype
    ok = jnp.all(jnp.isfinite(q))
    q = jnp.where(ok, q, 0.0)
    st = loaded_state(model, q, u, ud, jnp.zeros_like(ud), p, t)  # the inputs at rest in acceleration
    hvec, _ = balance(model, st)
    udd0 = solve_small(M, tau - hvec)
    dq, jr, jp = _tangents(model, q, ok, u, p)
    G = jax.jacfwd(lambda v: joint_speeds(model, fr, q, u, p, dq @ v, v))(jnp.zeros_like(ud))  # (k, dof)
    w = G @ ud
    a, d = friction_terms(fr, p, friction_signs(fr, w, jnp.asarray(scale, dtype)), w, dtype)
    dv = solve_small(M, G.T)  # (dof, k): the accelerations a unit friction load at each joint causes
    inertia = functools.partial(_inertia, masses(model, p), jr, jp)
    joints = friction_joints(model, fr)
    sys_, _ = reaction_system(model, st)
    X = unit_friction_solutions(model, sys_, st, joints, inertia(dv))
    # x0: the reactions at udd0 (the state's loads and the inertia of udd0: one more elimination)
    base, start = sys_.rhs, inertia(udd0)
    sys_.rhs = {i: base.get(i, 0.0) + start.get(i, 0.0) for i in set(base) | set(start)}
    x0 = solve_reaction_system(model, sys_, st)
    s, conv, good = solve_friction_loads(friction_norms(model, joints), a, d, x0, X, ok)
    udd = jnp.where(good, udd0 + dv @ s, jnp.nan)
    return FrictionAccelerations(udd, jnp.where(good, s, jnp.nan), conv)
