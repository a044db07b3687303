"""Virtual power: driving generalized forces and constraint multipliers, the mass matrix and
the energies of a ``Model`` at one solved state.

With ``x = (q, u)`` treated as independent and the loop closure ``Phi(q, u, p) = 0``
enforced by multipliers ``lambda``:

    applied    Q = sum F . dr_P/dx + M dphi/dx - dV/dx - T dL/dx
    inertia    I = sum m a_G . dr_G/dx + J alpha dphi/dx
    balance    I - Q + Phi_x^T lambda = tau e_u .

We never form a Jacobian of the poses: ``I - Q`` is the gradient (one reverse pass) of the
scalar virtual-work function ``W(x) = sum m a_G . r_G(x) + J alpha phi(x) - F . r_P(x) -
M phi(x) + V(x) + T L(x)`` with the accelerations and loads frozen at the actual state.
The ``q`` rows give ``lambda = -Phi_q^{-T} (I - Q)_q``, the ``u`` rows
``tau = (I - Q)_u + Phi_u^T lambda``.  Accelerations come from the implicit kinematics
(nested ``jax.jvp`` through ``implicit.implicit_positions``), never from Newton iterates.

**Reactions.**  ``-Phi_x^T lambda`` is the generalized constraint force.  For a complex loop
written ``path_1 - path_2 = 0`` (the two ways to reach the closing joint), the pair
``(lambda_re, lambda_im)`` is the force (N, ``x + i y``) that the last body of path 1
applies to the last body of path 2 at the closing joint.  A real equation whose gradient
in the point's position has unit length (a pin on a slot ``|P - C| - R = 0``) gives its
normal force in newtons the same way.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.linalg import solve_small
from ..actuators import resolve
from ..kinematics import one_state, time_derivatives
from ..mechanism.mechanism import Vars
from ..solver.implicit import implicit_positions
from .model import Axial, Gravity, Model, Moment, PointForce, Potential, geometry, masses

__all__ = ["generalized_forces", "LoadedState", "loaded_state", "balance", "driving_effort", "mass_matrix", "kinetic_energy", "potential_energy"]


def _dot(a, b):
    """Real dot product of two planar vectors given as complex numbers."""
    return jnp.real(jnp.conj(a) * b)



def _safe(model: Model, q, u, p):
    """Inputs made harmless where the position is not finite (results are masked later)."""
    ok = jnp.all(jnp.isfinite(q))
    return ok, jnp.where(ok, q, jnp.zeros_like(q))


def _path(model: Model, q, ok, u, ud, udd, p, qd=None, qdd=None):
    """``s -> (q(s), u(s))`` along ``u(s) = u + ud s + udd s^2/2``, differentiable via the
    implicit function theorem: its first and second ``s``-derivatives at 0 are the actual
    velocities and accelerations.  With the coordinates' own ``qd`` and ``qdd`` known (a
    stroke's chain rule gives them) the path is ``q + qd s + qdd s^2/2``: the same first
    and second derivatives, without differentiating the implicit root twice again."""
    mech = model.mechanism

    if qd is not None:
        qd = jnp.where(ok, qd, 0.0)
        qdd = jnp.where(ok, qdd, 0.0)

        def path(s):
            return q + qd * s + 0.5 * qdd * s * s, u + ud * s + 0.5 * udd * s * s

        return path

    def path(s):
        us = u + ud * s + 0.5 * udd * s * s
        return implicit_positions(mech, q, ok, us, p), us

    return path


class LoadedState(NamedTuple):
    """One solved state with everything the balance equations need (a record, per sample).

    - `ok`: whether the position is finite; `q`, `u`: coordinates and inputs (``q`` zeroed
      where not ok); `p`: the parameter mapping; `t`: time (s).
    - `poses`, `rates`, `accels`: ``geometry`` ``(r_G, phi, load points, load angles, axial
      lengths)`` and its first and second time derivatives (``accels`` None without inertia).
    - `velocities`: every coordinate's and input's velocity by name (what loads see as ``v``).
    - `forces`, `moments`, `tensions`: the ``PointForce``, ``Moment`` and ``Axial`` loads' values
      at this state, in the model's load order per type; `gravity`: each ``Gravity``'s
      acceleration vector (complex, m/s^2).
    - `masses`, `inertias`: the bodies' ``m`` (kg) and ``J`` (kg m^2).
    """

    ok: jax.Array
    q: jax.Array
    u: jax.Array
    p: dict
    t: jax.Array
    poses: tuple
    rates: tuple
    accels: tuple | None
    velocities: Vars
    forces: list
    moments: list
    tensions: list
    gravity: list
    masses: list
    inertias: list


def loaded_state(model: Model, q, u, u_dot, u_ddot, p, t=0.0, *, inertia: bool = True, q_dot=None, q_ddot=None) -> LoadedState:
    """The ``LoadedState`` at one solved state (arguments as ``generalized_forces``): poses
    and their rates and accelerations along the exact second-order path, and every load's
    value there."""
    mech = model.mechanism
    p = dict(p)
    ok, q = _safe(model, q, u, p)
    dtype = q.dtype
    path = _path(model, q, ok, u, u_dot, u_ddot, p, q_dot, q_ddot)
    pv = Vars(p)
    geo = lambda s: geometry(model, *path(s), p)  # noqa: E731
    zero = jnp.zeros((), dtype)
    if inertia:
        g0, gd, gdd = time_derivatives(geo, zero)
    else:  # quasi-static: no accelerations, so no second derivatives to trace
        g0, gd = jax.jvp(geo, (zero,), (jnp.ones((), dtype),))
        gdd = None
    _, (qd_, ud_) = jax.jvp(path, (zero,), (jnp.ones((), dtype),))
    vel = Vars({**dict(zip(mech.coords, qd_)), **dict(zip(mech.inputs, ud_))}) if mech.m + mech.dof else Vars({})
    qv, uv = mech.vars_q(q), mech.vars_u(u)
    forces, moments, tensions, grav = [], [], [], []
    lengths, rates = g0[4], gd[4]
    k_ax = 0
    for ld in model.loads:
        if isinstance(ld, PointForce):
            forces.append(jnp.asarray(ld.force(qv, uv, pv, vel, t)))
        elif isinstance(ld, Moment):
            moments.append(jnp.asarray(ld.moment(qv, uv, pv, vel, t)))
        elif isinstance(ld, Axial):
            tensions.append(jnp.asarray(ld.law(lengths[k_ax], rates[k_ax], pv, t)))
            k_ax += 1
        elif isinstance(ld, Gravity):
            grav.append(resolve(ld.g, p) * ld.direction)
    m_, J_ = masses(model, p)
    return LoadedState(ok=ok, q=q, u=u, p=p, t=jnp.asarray(t, dtype), poses=g0, rates=gd, accels=gdd, velocities=vel,
                       forces=forces, moments=moments, tensions=tensions, gravity=grav, masses=m_, inertias=J_)


def _work_gradient(model: Model, st: LoadedState):
    """``I - Q`` over ``x = (q, u)`` at a ``LoadedState``: the gradient of the virtual-work
    function ``W(x)`` with the accelerations and loads frozen (module docstring)."""
    mech = model.mechanism
    q, u, p, t = st.q, st.u, st.p, st.t
    dtype = q.dtype
    pv = Vars(p)
    m_, J_ = st.masses, st.inertias
    inertia = st.accels is not None
    a_g, alpha = (st.accels[0], st.accels[1]) if inertia else (None, None)
    potentials = [ld for ld in model.loads if isinstance(ld, Potential)]

    def work(x):
        qx, ux = x[: mech.m], x[mech.m :]
        rg, ph, lp, la, ll = geometry(model, qx, ux, p)
        w = jnp.zeros((), dtype)
        for k in range(len(model.bodies)):
            if inertia:
                w = w + m_[k] * _dot(a_g[k], rg[k]) + J_[k] * alpha[k] * ph[k]
            for gv in st.gravity:
                w = w - m_[k] * _dot(gv, rg[k])
        for F, r in zip(st.forces, lp):
            w = w - _dot(F, r)
        for M, a in zip(st.moments, la):
            w = w - M * a
        for T, L in zip(st.tensions, ll):
            w = w + T * L
        for ld in potentials:
            w = w + ld.energy(mech.vars_q(qx), mech.vars_u(ux), pv, t)
        return w

    return jax.grad(work)(jnp.concatenate([q, u]))


def balance(model: Model, st: LoadedState):
    """Driving generalized forces and constraint multipliers ``(tau (dof,), lam (m,))`` from
    a ``LoadedState`` (see ``generalized_forces``)."""
    mech = model.mechanism
    q, u, p = st.q, st.u, st.p
    g = _work_gradient(model, st)
    jq, ju = jax.jacfwd(mech.residual, (0, 1))(q, u, p)
    jq = jnp.where(st.ok, jq, jnp.eye(mech.m, dtype=q.dtype))
    lam = -solve_small(jq.T, g[: mech.m])
    tau = g[mech.m :] + ju.T @ lam
    nan = lambda x: jnp.where(st.ok, x, jnp.nan)  # noqa: E731
    return nan(tau), nan(lam)


def driving_effort(model: Model, st: LoadedState, dq_du):
    """The drive's generalized force ``tau (dof,)`` (N or N m, *on* each input, as
    ``generalized_forces``) from a ``LoadedState`` and the input derivatives ``dq_du (m,
    dof)`` at the same state: the virtual power along the motion's own tangent,
    ``tau = (I - Q)_u + dq_du' (I - Q)_q``.  Equal to ``balance``'s ``tau`` (since
    ``dq_du = -Phi_q^-1 Phi_u``) without its multipliers or linear solve: the lean path when
    only the effort is asked for (a design problem's second derivatives through it are
    several times cheaper to compile than through the joints' reactions)."""
    g = _work_gradient(model, st)
    m = model.mechanism.m
    tau = g[m:] + jnp.asarray(dq_du).T @ g[:m]
    return jnp.where(st.ok, tau, jnp.nan)


# The four model functions of the public face are jitted (the model static): called eagerly,
# JAX would otherwise run them operation by operation, compiling each (a slider-crank's first
# eager mass_matrix took 86 s, each later one 3.7 s); inside a trace they inline as usual.
@functools.partial(jax.jit, static_argnums=0, static_argnames=("inertia",))
def generalized_forces(model: Model, q, u, u_dot, u_ddot, p, t=0.0, *, inertia: bool = True, q_dot=None, q_ddot=None):
    """Driving generalized forces and constraint multipliers at one solved state.

    **Arguments**

    - `q`: solved coordinates ``(m,)`` (NaN gives NaN results); `u`, `u_dot`, `u_ddot`:
      input position, velocity, acceleration ``(dof,)`` (a number for one input); `p`:
      parameter mapping; `t`: s.  One state (``jax.vmap`` it for a batch): another shape
      raises ``ValueError`` naming the argument.
    - `inertia`: False for the quasi-static balance (inertia left out; velocity-dependent
      loads still see `u_dot`).
    - `q_dot`, `q_ddot`: the coordinates' velocities and accelerations ``(m,)`` when known
      (``motion`` and ``stroke_kinematics`` give them); otherwise they are taken from ``q``
      by the implicit function theorem.  Either way the results are differentiable in
      every parameter.

    **Returns** ``(tau (dof,), lam (m,))``: `tau` the force/torque (N or N m) that the
    drive must apply *on* each input (positive in the input's positive sense) to produce
    the motion; `lam` the multipliers (N for complex loops in metres; see the module
    docstring for the sign).
    """
    q, u, u_dot, u_ddot = one_state(model.mechanism, q, u, u_dot=u_dot, u_ddot=u_ddot)
    st = loaded_state(model, q, u, u_dot, u_ddot, p, t, inertia=inertia, q_dot=q_dot, q_ddot=q_ddot)
    return balance(model, st)


@functools.partial(jax.jit, static_argnums=0)
def mass_matrix(model: Model, q, u, p):
    """Generalized mass matrix in the inputs, ``(dof, dof)`` (kg, kg m, kg m^2):
    ``M = sum m (dr_G/du)^T (dr_G/du) + J (dphi/du)^T (dphi/du)``, with ``dq/du`` implicit."""
    mech = model.mechanism
    q, u = one_state(mech, q, u)
    p = dict(p)
    ok, q = _safe(model, q, u, p)

    def poses(u_):
        qs = implicit_positions(mech, q, ok, u_, p)
        rg, ph, *_ = geometry(model, qs, u_, p)
        return jnp.stack(rg) if rg else jnp.zeros((0,), complex), jnp.stack(ph) if ph else jnp.zeros((0,))

    jr, jp = jax.jacfwd(poses)(u)  # (nb, dof) complex, (nb, dof)
    m_, J_ = masses(model, p)
    M = jnp.zeros((mech.dof, mech.dof), q.dtype)
    for k in range(len(model.bodies)):
        M = M + m_[k] * jnp.real(jnp.conj(jr[k])[:, None] * jr[k][None, :]) + J_[k] * jnp.outer(jp[k], jp[k])
    return jnp.where(ok, M, jnp.nan)


@functools.partial(jax.jit, static_argnums=0)
def kinetic_energy(model: Model, q, u, u_dot, p):
    """``T = sum m |v_G|^2 / 2 + J omega^2 / 2`` (J) at one solved state."""
    mech = model.mechanism
    q, u, u_dot = one_state(mech, q, u, u_dot=u_dot)
    p = dict(p)
    ok, q = _safe(model, q, u, p)
    z = jnp.zeros_like(u_dot)
    path = _path(model, q, ok, u, u_dot, z, p)
    _, (vg, om, *_) = jax.jvp(lambda s: geometry(model, *path(s), p), (jnp.zeros((), q.dtype),), (jnp.ones((), q.dtype),))
    m_, J_ = masses(model, p)
    T = sum(0.5 * m_[k] * jnp.abs(vg[k]) ** 2 + 0.5 * J_[k] * om[k] ** 2 for k in range(len(model.bodies)))
    return jnp.where(ok, jnp.asarray(T, q.dtype), jnp.nan)


@functools.partial(jax.jit, static_argnums=0)
def potential_energy(model: Model, q, u, p, t=0.0):
    """Gravity and ``Potential`` loads' energy (J) at one state (``Axial`` laws excluded:
    a general law has no energy; use ``Potential`` for a spring you want counted)."""
    mech = model.mechanism
    q, u = one_state(mech, q, u)
    rg, *_ = geometry(model, q, u, p)
    m_, _ = masses(model, p)
    V = jnp.zeros((), q.dtype)
    for ld in model.loads:
        if isinstance(ld, Gravity):
            gv = resolve(ld.g, p) * ld.direction
            V = V - sum(m_[k] * _dot(gv, rg[k]) for k in range(len(model.bodies)))
        elif isinstance(ld, Potential):
            V = V + ld.energy(mech.vars_q(q), mech.vars_u(u), Vars(dict(p)), t)
    return V

