"""A walked stroke attached to its inputs and parameters by the implicit function theorem.

``continuation.walk`` finds a stroke's roots and their input derivatives as values only;
``attach`` makes them functions of ``(us, p)`` again (``implicit.implicit_positions``,
``implicit.implicit_input_derivatives``), inside the stroke program.  Under an eager
autodiff (``jax.grad``, ``jvp``, ``jacfwd`` outside any ``jit``) the walk's values are
concrete, and ``eager_attach`` takes the Jacobians of that attachment from a stored program
as well, so the autodiff traces only their contraction with its tangents.
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


def attach(mech: Mechanism, walked: Walked, us, p):
    """``(Solution, d1, d2)``: statuses of non-finite inputs, branch flips, NaN where not
    ``CONVERGED``, and the roots (and derivatives, None without) attached to ``(us, p)``
    (the stroke as given: ``(nb, dof)`` shared or ``(D, nb, dof)``; ``p`` leaves ``(D,)``)
    by the implicit function theorem."""
    pts = walked.points
    u_out = where(jnp.isfinite(us), us, 0.0)
    status = where(walked.valid, pts.status, Status.NONFINITE).astype(jnp.int32)
    flipped = jax.vmap(jax.vmap(flipped_mask, (None, 0)))(walked.b0, pts.branch) if has_branch(mech) else jnp.zeros(status.shape, jnp.int32)
    flipped = where(status == Status.BRANCH, flipped, 0)
    ok = status == Status.CONVERGED
    q_star = where(ok[..., None], pts.q, jnp.nan)
    ax = None if us.ndim == 2 else 0
    q = jax.vmap(jax.vmap(lambda q_, ok_, u_, p_: implicit_positions(mech, q_, ok_, u_, p_), (0, 0, 0, None)), (0, 0, ax, 0))(q_star, ok, u_out, p)
    d1, d2 = pts.d1, pts.d2
    if d1 is not None:
        d1 = where(ok[..., None, None], d1, jnp.nan)
        d2 = where(ok[..., None, None, None], d2, jnp.nan)
        one = lambda *a: implicit_input_derivatives(mech, *a)  # noqa: E731
        d1, d2 = jax.vmap(jax.vmap(one, (0, 0, 0, 0, 0, None)), (0, 0, 0, 0, ax, 0))(d1, d2, q_star, ok, u_out, p)
    sol = Solution(q=q, status=status, steps=pts.steps, residual=pts.residual, cond=pts.cond, branch=pts.branch,
                   flipped=flipped, coords=mech.coords, branches=branch_names(mech))
    return sol, d1, d2


@functools.partial(jit, static_argnums=(0, 1))
def _attach_program(mech, single, walked: Walked, us, p):
    res = attach(mech, walked, us, p)
    return jax.tree_util.tree_map(lambda x: x[0], res) if single else res


@functools.partial(jit, static_argnums=(0,))
def _attach_jacobians(mech, walked: Walked, us, p):
    """Per point of every design, the Jacobians of what ``attach`` gives (``q``, and ``dq/du``,
    ``d2q/du2`` where the walk has them) with respect to the point's input ``u`` and its
    design's parameters ``p``: a tuple over those outputs of ``(J_u (D, nb, *out, dof),
    {name: J_p (D, nb, *out)})``, by forward mode through ``attach``'s implicit rules (zero
    where a point failed).  What an eager derivative of a stroke contracts its tangents with."""
    pts = walked.points
    ok = walked.converged
    q_star = where(ok[..., None], pts.q, jnp.nan)
    u_out = where(jnp.isfinite(us), us, 0.0)
    derivs = pts.d1 is not None
    d1 = pts.d1 if derivs else jnp.zeros(q_star.shape + (us.shape[-1],), q_star.dtype)
    d2 = pts.d2 if derivs else jnp.zeros(d1.shape + (us.shape[-1],), q_star.dtype)

    def one(q_s, ok_, e1, e2, u, p1):
        def outputs(u_, p_):
            q = implicit_positions(mech, q_s, ok_, u_, p_)
            if not derivs:
                return (q,)
            return (q,) + implicit_input_derivatives(mech, where(ok_, e1, jnp.nan), where(ok_, e2, jnp.nan), q_s, ok_, u_, p_)

        jac = jax.jacfwd(outputs, argnums=(0, 1))(u, p1)
        return tuple(jax.tree_util.tree_map(lambda x: where(ok_, x, 0.0), j) for j in jac)

    ax = None if us.ndim == 2 else 0
    return jax.vmap(jax.vmap(one, (0, 0, 0, 0, 0, None)), (0, 0, 0, 0, ax, 0))(q_star, ok, d1, d2, u_out, p)


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


def eager_attach(mech, single: bool, walked: Walked, us, p):
    """``attach`` of a concrete walk to a ``(us, p)`` an eager autodiff traces (``jax.grad``,
    ``jvp``, ``jacfwd`` outside any ``jit``): values and Jacobians come from stored programs
    (a new process loads them), and the autodiff traces only their contraction with the
    tangents, a few products and sums.  Where those Jacobians would be large (more than
    ``EAGER_JACOBIAN_MAX`` numbers: many designs, points and parameters), the autodiff
    traces ``attach`` itself instead, as inside a ``jit``."""
    d, nb, m = walked.points.q.shape
    dof = us.shape[-1]
    per_point = m * (1 + dof + dof * dof if walked.points.d1 is not None else 1)
    if d * nb * per_point * (dof + len(p)) > EAGER_JACOBIAN_MAX:
        return _attach_program(mech, single, walked, us, p)

    @jax.custom_jvp
    def attached(us_, p_):
        return _attach_program(mech, single, walked, us_, p_)

    @attached.defjvp
    def attached_jvp(primals, tangents):
        us_, p_ = primals  # concrete in an eager autodiff: the stored programs serve them
        t_us, t_p = tangents
        out = _attach_program(mech, single, walked, us_, p_)
        jac = _attach_jacobians(mech, walked, us_, p_)
        ok = np.asarray(walked.converged)
        t_out = _tangents(single, jac, ok, us_, t_us, t_p)
        sol, d1, d2 = out
        t_sol = dataclasses.replace(jax.tree_util.tree_map(_zero_tangent, sol), q=t_out[0])
        return out, (t_sol, *(t_out[1:] if d1 is not None else (None, None)))

    return attached(us, p)
