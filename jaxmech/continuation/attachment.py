"""A walked stroke attached to its inputs and parameters by the implicit function theorem.

``continuation.walk`` finds a stroke's roots and their input derivatives as values only;
``attach`` makes them functions of ``(us, p)`` again (``implicit.implicit_positions``,
``implicit.implicit_input_derivatives``, per point by ``roots``), inside the stroke program.
Under an eager autodiff (``jax.grad``, ``jvp``, ``jacfwd`` outside any ``jit``) the stroke's
values are a concrete stroke's (the same programs), and ``eager_attach`` takes the
Jacobians of ``roots`` from one program more, so the autodiff traces only their contraction
with its tangents: one implicit rule, whichever way the stroke is differentiated.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanism.branches import branch_names, flipped_mask, has_branch
from ..solver.implicit import implicit_input_derivatives, implicit_positions
from ..solver.linalg import where
from ..mechanism.mechanism import Mechanism
from ..solver.solution import Solution
from ..solver.status import Status
from .stages import PointResults
from ..solver.xla import jit

__all__ = ["Walked", "attach", "eager_attach", "EAGER_JACOBIAN_MAX"]

#: The most numbers ``eager_attach``'s stored Jacobians may hold (128 MiB in float64).
EAGER_JACOBIAN_MAX = 1 << 24


class Walked(NamedTuple):
    """What a stroke's walks found, before the implicit rule attaches it to ``(u, p)``: the
    merged `points` (``PointResults``, ``(D, nb, ...)``), which of them have finite inputs
    (`valid (D, nb)`) and the requested branch signs (`b0`, ``(D[, n_branches])``)."""

    points: PointResults
    valid: jax.Array
    b0: jax.Array

    @property
    def converged(self):
        """``(D, nb)``: the points with finite inputs solved on the requested branch."""
        return self.valid & (self.points.status == Status.CONVERGED)


def _one_point(mech, q_s, ok, e1, e2, u, p1):
    """One point's roots attached to its input ``u`` and its design's ``p1``: ``q`` and, with
    the walk's ``e1 = dq/du``, ``e2 = d2q/du2`` (None without), their attached values too
    (a tuple of one or three)."""
    q = implicit_positions(mech, q_s, ok, u, p1)
    if e1 is None:
        return (q,)
    return (q,) + implicit_input_derivatives(mech, e1, e2, q_s, ok, u, p1)


def _per_point(fn, q_star, ok, d1, d2, us, p):
    """``fn(q_s, ok, e1, e2, u, p)`` mapped over designs and points: ``q_star``, ``ok``, ``d1``,
    ``d2`` with ``(D, nb)`` in front (``d1``, ``d2`` None without, NaN where not ``ok``), the
    inputs ``us`` shared ``(nb, dof)`` or ``(D, nb, dof)`` (non-finite ones as 0), ``p`` per
    design."""
    if d1 is not None:
        d1 = where(ok[..., None, None], d1, jnp.nan)
        d2 = where(ok[..., None, None, None], d2, jnp.nan)
    ax = None if us.ndim == 2 else 0
    inner = (0, 0) + ((None, None) if d1 is None else (0, 0))
    return jax.vmap(jax.vmap(fn, inner + (0, None)), inner + (ax, 0))(q_star, ok, d1, d2, where(jnp.isfinite(us), us, 0.0), p)


def roots(mech: Mechanism, q_star, ok, d1, d2, us, p):
    """The walk's roots ``q_star (D, nb, m)`` (NaN where not ``ok``) and derivatives ``d1``,
    ``d2`` (None without) attached to ``(us, p)`` by the implicit function theorem:
    ``(q, d1, d2)``, NaN where not ``ok``."""
    out = _per_point(lambda *a: _one_point(mech, *a), q_star, ok, d1, d2, us, p)
    return (out[0], None, None) if d1 is None else out


def attach(mech: Mechanism, walked: Walked, us, p):
    """``(Solution, d1, d2)``: statuses of non-finite inputs, branch flips, NaN where not
    ``CONVERGED``, and the roots (and derivatives, None without) attached to ``(us, p)``
    (the stroke as given: ``(nb, dof)`` shared or ``(D, nb, dof)``; ``p`` leaves ``(D,)``)
    by the implicit function theorem (``roots``)."""
    pts = walked.points
    status = where(walked.valid, pts.status, Status.NONFINITE).astype(jnp.int32)
    flipped = jax.vmap(jax.vmap(flipped_mask, (None, 0)))(walked.b0, pts.branch) if has_branch(mech) else jnp.zeros(status.shape, jnp.int32)
    flipped = where(status == Status.BRANCH, flipped, 0)
    ok = status == Status.CONVERGED
    q, d1, d2 = roots(mech, where(ok[..., None], pts.q, jnp.nan), ok, pts.d1, pts.d2, us, p)
    sol = Solution(q=q, status=status, steps=pts.steps, residual=pts.residual, cond=pts.cond, branch=pts.branch,
                   flipped=flipped, coords=mech.coords, branches=branch_names(mech))
    return sol, d1, d2


@functools.partial(jit, static_argnums=(0,))
def _roots_program(mech, q_star, ok, d1, d2, us, p):
    """``roots`` as a program: what an eager autodiff traces where the Jacobians would be too
    large to hold (``eager_attach``)."""
    return roots(mech, q_star, ok, d1, d2, us, p)


@functools.partial(jit, static_argnums=(0,))
def _attach_jacobians(mech, q_star, ok, d1, d2, us, p):
    """Per point of every design, the Jacobians of what ``roots`` gives (``q``, and ``dq/du``,
    ``d2q/du2`` where the walk has them) with respect to the point's input ``u`` and its
    design's parameters ``p``: a tuple over those outputs of ``(J_u (D, nb, *out, dof),
    {name: J_p (D, nb, *out)})``, by forward mode through the implicit rules (zero where a
    point failed).  What an eager derivative of a stroke contracts its tangents with."""

    def one(q_s, ok_, e1, e2, u, p1):
        jac = jax.jacfwd(lambda u_, p_: _one_point(mech, q_s, ok_, e1, e2, u_, p_), argnums=(0, 1))(u, p1)
        return tuple(jax.tree_util.tree_map(lambda x: where(ok_, x, 0.0), j) for j in jac)

    return _per_point(one, q_star, ok, d1, d2, us, p)


def _contract(jac, ok, t_u, t_p):
    """``J_u t_u + sum_k J_p[k] t_p[k]`` for one output's ``jac = (J_u, J_p)`` of
    ``_attach_jacobians``, zero where not ``ok (D, nb)``; ``t_u (D, nb, dof)``, ``t_p``
    leaves ``(D,)``.  The select makes the transpose zero there too: a failed point's
    cotangent (NaN through a user's mask of its NaN value) never reaches the parameters."""
    j_u, j_p = jac
    extra = j_u.ndim - 3
    t = jnp.sum(j_u * t_u.reshape(t_u.shape[:2] + (1,) * extra + t_u.shape[2:]), axis=-1)
    for k, j in j_p.items():
        t = t + j * t_p[k].reshape(t_p[k].shape + (1,) * (j.ndim - 1))
    return jnp.where(ok.reshape(ok.shape + (1,) * extra), t, 0.0)


@functools.partial(jax.jit, static_argnums=(0,))
def _tangents(single: bool, jac, ok, us, t_us, t_p):
    """The tangents of ``attach``'s ``(q[, dq/du, d2q/du2])`` (``_contract`` per output), as
    one program: an eager autodiff compiles it (and its transpose) once instead of every
    product and sum on its own."""
    d = ok.shape[0]
    t_u = jnp.broadcast_to(jnp.where(jnp.isfinite(us), t_us, 0.0), (d,) + us.shape[-2:])
    out = [_contract(j, ok, t_u, t_p) for j in jac]
    return [t[0] for t in out] if single else out


def _zero_tangent(x):
    dtype = jnp.result_type(x)
    if jnp.issubdtype(dtype, jnp.inexact):
        return jnp.zeros(jnp.shape(x), dtype)
    return np.zeros(jnp.shape(x), jax.dtypes.float0)


def eager_attach(mech, single: bool, values, us, p):
    """A concrete stroke's ``values`` (``(Solution, d1, d2)``, as the concrete call returns
    them) attached to a ``(us, p)`` that an eager autodiff traces (``jax.grad``, ``jvp``,
    ``jacfwd`` outside any ``jit``): the values are returned as they are, and their tangents
    are the implicit rule's Jacobians (one program, ``_attach_jacobians``) contracted with
    the autodiff's tangents, a few products and sums.  Where those Jacobians would be large
    (more than ``EAGER_JACOBIAN_MAX`` numbers: many designs, points and parameters), the
    autodiff traces ``roots`` itself instead (``_roots_program``), as inside a ``jit``."""
    def lead(x):  # (D, nb, ...) in front: a single design's values get its axis back
        return None if x is None else np.asarray(x)[None] if single else np.asarray(x)

    sol, d1, d2 = values
    ok = lead(sol.status) == Status.CONVERGED
    q_star, e1, e2 = lead(sol.q), lead(d1), lead(d2)
    d, nb, m = q_star.shape
    dof = us.shape[-1]
    per_point = m * (1 + dof + dof * dof if d1 is not None else 1)
    drop = (lambda x: None if x is None else x[0]) if single else (lambda x: x)  # noqa: E731

    def with_roots(new):
        q, n1, n2 = (drop(x) for x in new)
        return dataclasses.replace(sol, q=q), n1, n2

    if d * nb * per_point * (dof + len(p)) > EAGER_JACOBIAN_MAX:
        return with_roots(_roots_program(mech, q_star, ok, e1, e2, us, p))

    @jax.custom_jvp
    def attached(us_, p_):
        return values

    @attached.defjvp
    def attached_jvp(primals, tangents):
        us_, p_ = primals  # concrete in an eager autodiff: the stored program serves them
        t_us, t_p = tangents
        jac = _attach_jacobians(mech, q_star, ok, e1, e2, us_, p_)
        t_out = _tangents(single, jac, ok, us_, t_us, t_p)
        t_sol = dataclasses.replace(jax.tree_util.tree_map(_zero_tangent, sol), q=t_out[0])
        return values, (t_sol, *(t_out[1:] if d1 is not None else (None, None)))

    return attached(us, p)
