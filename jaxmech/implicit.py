"""Implicit derivatives of a converged root: the implicit function theorem as custom JVPs.

Derivatives never go through the Newton iterations.  The converged root ``q*`` is
attached to ``(u, p)`` by a custom JVP that implements the implicit function theorem:
differentiating ``Phi(q*(u, p), u, p) = 0`` gives

    Phi_q dq + Phi_u du + Phi_p dp = 0   =>   dq = -Phi_q^{-1} (Phi_u du + Phi_p dp).

The rule is written in JAX primitives evaluated at the attached (differentiable) root,
so forward mode, reverse mode (by transposition of the linear solve) and every higher
order follow.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ._linalg import solve_blocks, where
from .mechanism import Mechanism
from .structure import blocks

__all__ = ["implicit_root", "root_derivatives", "attach_derivatives"]


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def implicit_root(mech: Mechanism, q_star, ok, u, p):
    """Attach a converged root ``q*`` to ``(u, p)`` for differentiation (identity on values).

    Tangent: ``dq = -Phi_q^{-1} (Phi_u du + Phi_p dp)`` (implicit function theorem).  Where
    ``ok`` is False the tangent is exactly zero and every intermediate is finite, so a
    failed sample never puts NaN into a batch gradient.
    """
    return q_star


@implicit_root.defjvp
def _implicit_root_jvp(mech, primals, tangents):
    q_star, ok, u, p = primals
    _, _, du, dp = tangents
    q = implicit_root(mech, q_star, ok, u, p)  # differentiable again: second order follows
    # Evaluate the rule at a safe point where the sample failed (its NaNs would leak through
    # 0 * NaN in the transposed, reverse-mode, computation).
    q_s = where(ok, q, jnp.zeros_like(q))
    u_s = where(ok, u, jnp.zeros_like(u))
    p_s = jax.tree_util.tree_map(lambda x: where(ok, x, jnp.ones_like(x)), p)
    du = where(ok, du, jnp.zeros_like(du))
    dp = jax.tree_util.tree_map(lambda x: where(ok, x, jnp.zeros_like(x)), dp)
    _, rhs = jax.jvp(lambda u_, p_: mech.residual(q_s, u_, p_), (u_s, p_s), (du, dp))
    jac = jax.jacfwd(mech.residual)(q_s, u_s, p_s)
    jac = where(ok, jac, jnp.eye(mech.m, dtype=jac.dtype))
    dq = -solve_blocks(jac, rhs, blocks(mech))
    return q, where(ok, dq, jnp.zeros_like(dq))


def root_derivatives(mech: Mechanism, q, u, p, ok):
    """``dq/du (m, dof)`` and ``d2q/du2 (m, dof, dof)`` at a root ``q`` (finite) of one sample.

    Differentiating ``Phi(q(u), u) = 0`` once and twice along the inputs:

        Phi_q q' = -Phi_u,        Phi_q q''[j, k] = -D2 Phi[x_j, x_k],  x_j = (q'_j, e_j),

    so one Jacobian, one factorisation and one second directional derivative per input
    pair serve both orders.  The second derivative is taken with the primal point ``(q, u)``
    itself (not ``q + 0 x``), so under jit it shares its sines and cosines with the
    solver's last Jacobian.  Where ``ok`` is False the Jacobian is replaced by the identity
    and the results are zero: finite in both directions of differentiation.
    """
    m, dof = mech.m, mech.dof
    jq = jax.jacfwd(mech.residual, 0)(q, u, p)
    jq = where(ok, jq, jnp.eye(m, dtype=jq.dtype))
    ju = jax.jacfwd(mech.residual, 1)(q, u, p)
    d1 = -solve_blocks(jq, ju, blocks(mech))
    res = lambda q_, u_: mech.residual(q_, u_, p)  # noqa: E731
    eye = jnp.eye(dof, dtype=d1.dtype)

    def second(j, k):
        inner = lambda q_, u_: jax.jvp(res, (q_, u_), (d1[:, k], eye[k]))[1]  # noqa: E731
        return jax.jvp(inner, (q, u), (d1[:, j], eye[j]))[1]

    hess = jnp.stack([jnp.stack([second(j, k) for k in range(dof)], axis=-1) for j in range(dof)], axis=-2)
    d2 = -solve_blocks(jq, hess.reshape(m, dof * dof), blocks(mech)).reshape(m, dof, dof)
    zero_if = lambda x: where(ok, x, jnp.zeros_like(x))  # noqa: E731
    return zero_if(d1), zero_if(d2)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def attach_derivatives(mech: Mechanism, d1, d2, q_star, ok, u, p):
    """``(d1, d2)`` (``dq/du`` and ``d2q/du2`` computed without gradients at the root
    ``q_star``), made differentiable in ``u`` and ``p`` like ``root_derivatives`` of the
    attached root: its tangent is ``root_derivatives``'s, taken through ``implicit_root``.
    Values pass unchanged; nothing is traced for the tangent unless one is asked for."""
    return d1, d2


@attach_derivatives.defjvp
def _attach_derivatives_jvp(mech, primals, tangents):
    _, _, q_star, ok, u, p = primals
    _, _, _, _, du, dp = tangents
    q_s = where(ok, q_star, jnp.zeros_like(q_star))

    def fn(u_, p_):
        e1, e2 = root_derivatives(mech, implicit_root(mech, q_s, ok, u_, p_), u_, p_, ok)
        return where(ok, e1, jnp.nan), where(ok, e2, jnp.nan)

    (e1, e2), (t1, t2) = jax.jvp(fn, (u, p), (du, dp))
    return (e1, e2), (where(ok, t1, 0.0), where(ok, t2, 0.0))
