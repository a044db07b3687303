"""Implicit derivatives of a converged root: the implicit function theorem as one custom JVP.

Derivatives never go through the Newton iterations.  One name per idea:

- ``implicit_solution(residual, x*, ok, args)``: any converged root attached to its
  arguments (the one implicit-function rule); statics (the equilibrium inputs) and forward
  dynamics (the Runge-Kutta stages) use it with their own residual;
- ``implicit_positions(mech, q*, ok, u, p)``: it for a mechanism's loop closure (the
  positions ``q*`` attached to ``(u, p)``);
- ``input_derivatives(mech, q, u, p, ok)``: ``dq/du`` and ``d2q/du2`` at a root (values;
  ``kinematics.input_derivatives`` is its public face, with shape checks);
- ``implicit_input_derivatives(mech, d1, d2, q*, ok, u, p)``: such values, computed without
  gradients, attached to ``(u, p)`` (a stroke computes them inside its walk).

The former names ``implicit_root``, ``root_derivatives`` and ``attach_derivatives`` still
work, with a ``DeprecationWarning``.  For the positions, differentiating
``Phi(q*(u, p), u, p) = 0`` gives

    Phi_q dq + Phi_u du + Phi_p dp = 0   =>   dq = -Phi_q^{-1} (Phi_u du + Phi_p dp).

The rule is written in JAX primitives evaluated at the attached (differentiable) root,
so forward mode, reverse mode (by transposition of the linear solve) and every higher
order follow.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp

from .linalg import solve_blocks, solve_small, where
from ..mechanism.mechanism import Mechanism
from ..mechanism.structure import blocks

__all__ = ["implicit_solution", "implicit_positions", "input_derivatives", "implicit_input_derivatives"]

#: Deprecated names -> the names that replaced them (module ``__getattr__`` below).
DEPRECATED = {"implicit_root": "implicit_positions", "root_derivatives": "input_derivatives", "attach_derivatives": "implicit_input_derivatives"}


def __getattr__(name):
    if name in DEPRECATED:
        new = DEPRECATED[name]
        warnings.warn(f"jaxmech.solver.implicit.{name} is deprecated: use jaxmech.solver.implicit.{new}", DeprecationWarning, stacklevel=2)
        return globals()[new]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _safe(ok, tree, fill):
    """``tree`` where ``ok``, else ``fill`` (``zeros_like``/``ones_like``), for its floating
    leaves; other leaves (flags, counts) pass unchanged."""
    def one(x):
        x = jnp.asarray(x)
        return where(ok, x, fill(x)) if jnp.issubdtype(x.dtype, jnp.inexact) else x
    return jax.tree_util.tree_map(one, tree)


def _safe_tangent(ok, tree):
    """Tangents zeroed where not ``ok`` (``float0`` tangents of integer leaves unchanged)."""
    def one(x):
        return x if x.dtype == jax.dtypes.float0 else where(ok, x, jnp.zeros_like(x))
    return jax.tree_util.tree_map(one, tree)


def implicit_solution(residual: Callable, x_star, ok, args, structure=None, *, checkpoint: bool = False):
    """Attach a root ``x*`` of ``residual(x, args) = 0`` to ``args`` for differentiation
    (the identity on values): the one implicit-function rule of the package.

    Differentiating ``F(x*(a), a) = 0`` gives ``F_x dx + F_a da = 0``, so the tangent is

        dx = -F_x^{-1} F_a da,

    evaluated in JAX primitives at the attached root (itself differentiable again), so
    forward mode, reverse mode (by transposition of the linear solve) and every higher
    order follow, and no derivative goes through the iterations that found ``x*``.

    **Arguments**

    - `residual`: ``fn(x, args) -> F`` with ``F`` of the shape of ``x`` (a static function:
      give a module-level function or a ``functools.partial`` of one, not a closure over
      arrays, which would receive no derivative).
    - `x_star`: the converged root (any shape; the system is its flattening).
    - `ok`: boolean scalar, False where the solve failed: there the tangent is exactly
      zero, and the rule is evaluated at a harmless point (``x = 0``, floating ``args``
      leaves ``= 1``), so a failed sample never puts NaN into a batch gradient (a NaN there
      would leak through ``0 * NaN`` in the transposed, reverse-mode, computation).
    - `args`: a pytree of what ``x*`` depends on; non-floating leaves get no derivative.
    - `structure`: the block-triangular order of ``F_x`` (``structure.blocks``) when one is
      known: one small solve per diagonal block; ``None``: one dense small solve.
    - `checkpoint`: call the rule under ``jax.checkpoint``: needed inside a ``lax.scan``
      that is differentiated twice with reverse mode first (forward dynamics' steps):
      without it jax 0.10.2 gave half the second derivative there (forward or reverse
      over reverse), ``jax.lax.custom_root`` alike (``tests/test_hinge.py``).  Off by
      default: it made the reverse-mode programs of the position solve ~1.5x longer to
      compile (flap_msd's gradient test, 37 s to 58 s).

    **Returns** ``x_star``, with the derivative above.
    """
    if not checkpoint:
        return _attach(residual, x_star, ok, args, structure)
    attach = lambda x_, ok_, a_: _attach(residual, x_, ok_, a_, structure)  # noqa: E731
    return jax.checkpoint(attach, prevent_cse=False)(x_star, ok, args)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 4))
def _attach(residual, x_star, ok, args, structure):
    """``x_star`` attached to ``args`` (``implicit_solution``'s custom JVP)."""
    return x_star


@_attach.defjvp
def _implicit_solution_jvp(residual, structure, primals, tangents):
    x_star, ok, args = primals
    _, _, dargs = tangents
    x = _attach(residual, x_star, ok, args, structure)  # differentiable again: second order follows
    x_s = _safe(ok, x, jnp.zeros_like)
    args_s = _safe(ok, args, jnp.ones_like)
    _, rhs = jax.jvp(lambda a: residual(x_s, a), (args_s,), (_safe_tangent(ok, dargs),))
    k = x.size
    jac = jax.jacfwd(lambda x_: residual(x_, args_s))(x_s).reshape(k, k)
    jac = where(ok, jac, jnp.eye(k, dtype=jac.dtype))
    rhs = rhs.reshape(k)
    dx = -(solve_small(jac, rhs) if structure is None else solve_blocks(jac, rhs, structure))
    return x, where(ok, dx.reshape(x.shape), jnp.zeros_like(x))


def mechanism_residual(mech: Mechanism, q, args):
    """``Phi(q, u, p)`` of ``mech`` with ``args = (u, p)``: the residual ``implicit_positions``
    attaches."""
    u, p = args
    return mech.residual(q, u, p)


def implicit_positions(mech: Mechanism, q_star, ok, u, p):
    """Attach a converged root ``q*`` to ``(u, p)`` for differentiation (identity on values):
    ``implicit_solution`` of the loop-closure residual, solved block by block.

    Tangent: ``dq = -Phi_q^{-1} (Phi_u du + Phi_p dp)`` (implicit function theorem).  Where
    ``ok`` is False the tangent is exactly zero and every intermediate is finite.
    """
    return implicit_solution(functools.partial(mechanism_residual, mech), q_star, ok, (u, p), blocks(mech))


def input_derivatives(mech: Mechanism, q, u, p, ok=None):
    """``dq/du (m, dof)`` and ``d2q/du2 (m, dof, dof)`` at a root ``q`` of one sample (rad or
    m per unit input).

    Differentiating ``Phi(q(u), u) = 0`` once and twice along the inputs:

        Phi_q q' = -Phi_u,        Phi_q q''[j, k] = -D2 Phi[x_j, x_k],  x_j = (q'_j, e_j),

    so one Jacobian, one factorisation and one second directional derivative per input
    pair serve both orders.  The second derivative is taken with the primal point ``(q, u)``
    itself (not ``q + 0 x``), so under jit it shares its sines and cosines with the
    solver's last Jacobian.  Where ``ok`` is False (by default: where ``q`` is not finite)
    the Jacobian is replaced by the identity and the results are zero: finite in both
    directions of differentiation.  ``q`` attached to ``(u, p)`` (``implicit_positions``)
    makes the results differentiable again.
    """
    if ok is None:
        ok = jnp.all(jnp.isfinite(q))
        q = where(ok, q, jnp.zeros_like(q))
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
def implicit_input_derivatives(mech: Mechanism, d1, d2, q_star, ok, u, p):
    """``(d1, d2)`` (``dq/du`` and ``d2q/du2`` computed without gradients at the root
    ``q_star``), made differentiable in ``u`` and ``p`` like ``input_derivatives`` of the
    attached root: its tangent is ``input_derivatives``'s, taken through ``implicit_positions``.
    Values pass unchanged; nothing is traced for the tangent unless one is asked for."""
    return d1, d2


@implicit_input_derivatives.defjvp
def _implicit_input_derivatives_jvp(mech, primals, tangents):
    _, _, q_star, ok, u, p = primals
    _, _, _, _, du, dp = tangents
    q_s = where(ok, q_star, jnp.zeros_like(q_star))

    def fn(u_, p_):
        e1, e2 = input_derivatives(mech, implicit_positions(mech, q_s, ok, u_, p_), u_, p_, ok)
        return where(ok, e1, jnp.nan), where(ok, e2, jnp.nan)

    (e1, e2), (t1, t2) = jax.jvp(fn, (u, p), (du, dp))
    return (e1, e2), (where(ok, t1, 0.0), where(ok, t2, 0.0))
