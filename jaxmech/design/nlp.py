"""What the constrained optimiser of the design layer works on: a nonlinear program's
evaluation with exact second derivatives, its KKT residual, and a Cholesky
factorisation written in JAX.

The problem, in scaled variables ``x``::

    min f(x)   s.t.   h(x) = 0  (p equalities),   g(x) <= 0  (m inequalities, box rows included)

``second_order`` turns a function ``problem(x) -> (f, h, g, ok)`` into
``evaluate(x, y, z) -> Evaluation``: values, the constraints' Jacobian and the Hessian of the
Lagrangian ``f + y.h + z.g`` (forward over reverse mode, through whatever implicit rules
``problem`` uses); ``design.stroke_problem`` gives the same for a problem over a stroke by a
second-order adjoint; ``design.sqp`` solves either.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["Evaluation", "RowDerivatives", "second_order", "weighted_derivatives", "cholesky_small", "kkt_error"]


class Evaluation(NamedTuple):
    """The problem and its derivatives at one point (``second_order``'s ``evaluate``): the
    objective `f`, the constraints `c` (``h`` then ``g``), ``grad f``, the constraints'
    Jacobian `jac` ``(p + m, n)``, the Hessian `hess` of the Lagrangian, and `ok` (finite
    and evaluable)."""

    f: jax.Array
    c: jax.Array
    grad: jax.Array
    jac: jax.Array
    hess: jax.Array
    ok: jax.Array


def second_order(problem: Callable, p: int):
    """``evaluate(x, y, z) -> Evaluation(f, c, grad f, J_c, W, ok)`` from ``problem(x) -> (f, h, g, ok)``
    (``h (p,)``, ``g (m,)``): values, the constraints' Jacobian and the Hessian ``W`` of the
    Lagrangian ``f + y.h + z.g``, by one linearisation of ``x -> (values, grad L)`` (forward
    over reverse mode) with the ``n`` unit tangents at once."""

    def values(x):
        f, h, g, ok = problem(x)
        return jnp.concatenate([jnp.reshape(f, (1,)), h, g]), ok

    def evaluate(x, y, z):
        v, jac, hess, ok = weighted_derivatives(values, x, jnp.concatenate([jnp.ones((1,), x.dtype), y, z]))
        return Evaluation(v[0], v[1:], jac[0], jac[1:], hess, ok)

    return evaluate, values


class RowDerivatives(NamedTuple):
    """Rows of a problem at one point with their derivatives: `values` ``(k,)``, `jac`
    ``(k, n)``, `hess` ``(n, n)`` the Hessian of ``w . values`` for the weights ``w`` asked
    for (the Lagrange multipliers), and `ok` (evaluable, everything finite)."""

    values: jax.Array
    jac: jax.Array
    hess: jax.Array
    ok: jax.Array


def weighted_derivatives(values: Callable, x, w) -> RowDerivatives:
    """The ``RowDerivatives`` of ``values(x) -> (v (k,), ok)`` with weights ``w (k,)``, by
    one linearisation of ``x -> (v, grad (w . v))`` (forward over reverse mode) with the
    ``n`` unit tangents at once."""

    def both(x_):
        v, ok = values(x_)
        return v, jax.grad(lambda x2: jnp.dot(w, values(x2)[0]))(x_), ok

    (v, _, ok), lin = jax.linearize(both, x)
    tan_v, tan_g, _ = jax.vmap(lin)(jnp.eye(x.shape[0], dtype=x.dtype))
    jac, hess = tan_v.T, 0.5 * (tan_g + tan_g.T)
    ok = ok & jnp.all(jnp.isfinite(v)) & jnp.all(jnp.isfinite(jac)) & jnp.all(jnp.isfinite(hess))
    return RowDerivatives(v, jac, hess, ok)


def cholesky_small(a):
    """``(L, ok)``: the Cholesky factor of a small symmetric matrix, a column per step of a
    ``fori_loop`` (compact to compile; no LAPACK call, see ``stored.calls_lapack``); ``ok``
    False where a pivot is not positive (``L`` is then not to be used)."""
    n = a.shape[0]
    rows = jnp.arange(n)

    def column(j, carry):
        L, ok = carry
        lj = L[j]  # row j: its entries left of j are final, the rest zero
        d = a[j, j] - lj @ lj
        ok = ok & (d > 0)
        ljj = jnp.sqrt(jnp.where(d > 0, d, 1.0))
        col = (a[:, j] - L @ lj) / ljj
        col = jnp.where(rows > j, col, jnp.where(rows == j, ljj, 0.0))
        return L.at[:, j].set(col), ok

    return jax.lax.fori_loop(0, n, column, (jnp.zeros_like(a), jnp.asarray(True)))


def kkt_error(grad, jac, y, z, s, c, p, mu, s_max):
    """IPOPT's scaled optimality error ``E_mu`` (``mu = 0``: of the problem itself)."""
    m = z.shape[0]
    h, g = c[:p], c[p:]
    r_d = grad + jac.T @ jnp.concatenate([y, z])
    s_d = jnp.maximum(s_max, (jnp.sum(jnp.abs(y)) + jnp.sum(jnp.abs(z))) / max(p + m, 1)) / s_max
    s_c = jnp.maximum(s_max, jnp.sum(jnp.abs(z)) / max(m, 1)) / s_max
    primal = jnp.maximum(jnp.max(jnp.abs(h), initial=0.0), jnp.max(jnp.abs(g + s), initial=0.0))
    comp = jnp.max(jnp.abs(s * z - mu), initial=0.0) / s_c
    return jnp.maximum(jnp.maximum(jnp.max(jnp.abs(r_d)) / s_d, primal), comp)


def __getattr__(name):
    """The result codes' retired names (deprecated: ``jaxmech.Status``, ``status.RETIRED``)."""
    from ..solver.status import retired

    return retired(__name__, name)
