"""A design problem over a stroke, with its Lagrangian's exact Hessian by a second-order adjoint.

Most linkage design questions are functions of the motion at the samples of a stroke:
the peak drive torque, a transmission angle at every sample, the travel between the first
and the last sample.  ``StrokeProblem`` states one as that: a mechanism, the stroke's
inputs and their rates, a map from the design variables to the mechanism's parameters, a
guess per sample (which picks the assembly mode), and ``rows(p, motion) -> Stated``.

Per sample the motion is ``Y = (q, q', q'')`` (positions and their first and second
derivatives along the inputs), the root of

    G(Y, x) = ( Phi(q),   Phi_q q'_j + Phi_{u_j},   Phi_q q''_jk + D2 Phi[(q'_j, e_j), (q'_k, e_k)] ) = 0,

block lower triangular in ``Y`` with ``Phi_q`` on its diagonal.  So, for a weighted sum of
the rows ``r(x, Y) = w . rows`` (the Lagrangian), with ``V_j = (e_j, Y_x e_j)``:

- the tangents ``Y_x = -G_Y^-1 G_x`` by forward substitution (three solves with ``Phi_q``);
- the adjoint ``lambda``, ``G_Y' lambda = -r_Y``, by back substitution;
- ``d2 r / dx2 = V' (Hessian of r + lambda . G in (x, Y)) V``: ``n`` Hessian-vector
  products of an explicit function (the residual's derivatives to fourth order), with
  ``lambda`` held constant: the second-order adjoint.

Nothing is differentiated through a Newton iteration or through a linear solve: the
position solve runs on values only, and every factor of ``Phi_q`` is applied as a matrix.
This is the implicit rule to second order written out, and it compiles several times
smaller than nesting automatic differentiation through the solver's implicit rule (the
flap_msd statement: see ``benchmarks/design.py``).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation.solve import walk
from ..solver.implicit import input_derivatives
from ..kinematics import Motion, chain_rule
from ..solver.linalg import inv_small, where
from ..mechanism.mechanism import Mechanism
from ..solver.newton import newton
from ..solver.options import SolverOptions
from ..solver.status import Status
from ..mechanism.structure import blocks
from .constrained import Stated, stated_rows
from .nlp import RowDerivatives

__all__ = ["StrokeProblem", "stroke_evaluator", "stroke_state", "stroke_sizes"]


@dataclasses.dataclass(frozen=True, eq=False)
class StrokeProblem:
    """A design problem over a stroke (module docstring).

    - `mechanism`: the ``Mechanism``.
    - `names`: the design variables, in order.
    - `params`: ``({name: scalar}) -> {param: scalar}``, every parameter of `mechanism`
      (and of `rows`) from the design variables (traceable; a plain ``{**base, **x}``
      for lengths taken as they are).
    - `us`: ``(N, dof)`` the stroke's inputs; `u_dot`, `u_ddot`: ``(N, dof)`` their rates
      (the motion's time derivatives follow by the chain rule).
    - `guess`: ``(p, u (dof,)) -> q (m,)``: each sample's Newton guess; it picks the
      assembly mode (a closed form with the branch signs, or the drawing).
    - `rows`: ``(p, Motion) -> Stated``: the requirements on the motion (``Motion`` fields
      ``u``, ``u_dot``, ``u_ddot``, ``q``, ``q_dot``, ``q_ddot``, ``dq_du``, ``d2q_du2``,
      ``(N, ...)``; ``points`` empty).  Any field of ``Stated`` may be empty; ``ok`` is
      overwritten by the solves' convergence.
    - `options`: the position solves' ``SolverOptions``.
    - `t`: ``(N,)`` the samples' times in s (what time-dependent loads of `rows` read;
      default zeros).
    - `continuation`: False (default): each sample is solved on its own from `guess`;
      True: `guess` is called at the first sample only and the stroke is followed from
      there by continuation (the straight-line walk of ``solve_stroke``, on the requested
      branch), for strokes too long for one guess per sample (a crank's whole turn).  A
      trial design whose walk leaves a sample unsolved (a gap) does not assemble: the
      optimiser shortens its step (the gap handling of sweeps is not needed here).

    Compared by identity: one object, one compiled program.
    """

    mechanism: Mechanism
    names: tuple
    params: Callable
    us: np.ndarray
    u_dot: np.ndarray
    u_ddot: np.ndarray
    guess: Callable
    rows: Callable
    options: SolverOptions = SolverOptions()
    t: np.ndarray | None = None
    continuation: bool = False

    def __post_init__(self):
        dof = self.mechanism.dof
        for name in ("us", "u_dot", "u_ddot"):
            a = np.asarray(getattr(self, name), float)
            if a.ndim == 1 and dof == 1:
                a = a[:, None]
            if a.ndim != 2 or a.shape[1] != dof:
                raise ValueError(f"StrokeProblem: {name} must have shape (N, {dof}), got {np.shape(getattr(self, name))}")
            object.__setattr__(self, name, a)
        n = self.us.shape[0]
        if self.u_dot.shape[0] != n or self.u_ddot.shape[0] != n:
            raise ValueError(f"StrokeProblem: us, u_dot and u_ddot must have the same number of samples, got "
                             f"{self.us.shape[0]}, {self.u_dot.shape[0]}, {self.u_ddot.shape[0]}")
        object.__setattr__(self, "names", tuple(self.names))
        t = np.zeros(n) if self.t is None else np.asarray(self.t, float)
        if t.shape != (n,):
            raise ValueError(f"StrokeProblem: t must have shape ({n},) (one time per sample), got {np.shape(self.t)}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "continuation", bool(self.continuation))

    @functools.cached_property
    def program_key(self) -> str | None:
        """A fingerprint of what a compiled program of this problem depends on (the
        mechanism's, the names, the stroke, the options and the traced programs of
        `params`, `guess` and `rows`), equal for identical problems in any process; None
        when the mechanism has none or a function does not trace (then nothing is stored)."""
        mech_key = self.mechanism.program_key
        if mech_key is None:
            return None
        dtype = jnp.zeros(()).dtype
        digest = hashlib.sha256(repr((mech_key, self.names, repr(self.options), str(dtype), self.continuation)).encode())
        for a in (self.us, self.u_dot, self.u_ddot, self.t):
            digest.update(repr(a.shape).encode() + np.ascontiguousarray(a).tobytes())
        x = {k: jax.ShapeDtypeStruct((), dtype) for k in self.names}
        try:
            p = jax.eval_shape(self.params, x)
            n, m, dof = self.us.shape[0], self.mechanism.m, self.mechanism.dof
            y = _Motion(*(jax.ShapeDtypeStruct(s, dtype) for s in ((n, m), (n, m, dof), (n, m, dof, dof))))
            traced = (jax.make_jaxpr(self.params)(x), jax.make_jaxpr(self.guess)(p, jax.ShapeDtypeStruct((dof,), dtype)),
                      jax.make_jaxpr(lambda p_, y_: self.rows(p_, _motion(self, y_, dtype)))(p, y))
        except Exception:  # noqa: BLE001 - a function that does not trace: no key (its error shows when solved)
            return None
        for closed in traced:
            digest.update(str(closed.jaxpr).encode())
            for c in closed.consts:
                c = np.asarray(c)
                digest.update(repr((c.shape, str(c.dtype))).encode() + c.tobytes())
        return digest.hexdigest()


class _Motion(NamedTuple):
    q: jax.Array  # (N, m)
    d1: jax.Array  # (N, m, dof)
    d2: jax.Array  # (N, m, dof, dof)


def _second(mech: Mechanism, q, d1, d2, u, p):
    """``G_3``: ``Phi_q q''_jk + D2 Phi[(q'_j, e_j), (q'_k, e_k)]`` ``(m, dof, dof)``."""
    dof = u.shape[0]
    eye = jnp.eye(dof, dtype=q.dtype)
    res = lambda q_, u_: mech.residual(q_, u_, p)  # noqa: E731

    def one(j, k):
        inner = lambda q_, u_: jax.jvp(res, (q_, u_), (d1[:, k], eye[k]))[1]  # noqa: E731
        curv = jax.jvp(inner, (q, u), (d1[:, j], eye[j]))[1]
        return curv + jax.jvp(lambda q_: res(q_, u), (q,), (d2[:, j, k],))[1]

    return jnp.stack([jnp.stack([one(j, k) for k in range(dof)], axis=-1) for j in range(dof)], axis=-2)


def _first(mech: Mechanism, q, d1, u, p):
    """``G_2``: ``Phi_q q'_j + Phi_{u_j}`` ``(m, dof)``."""
    dof = u.shape[0]
    eye = jnp.eye(dof, dtype=q.dtype)
    res = lambda q_, u_: mech.residual(q_, u_, p)  # noqa: E731
    return jnp.stack([jax.jvp(res, (q, u), (d1[:, j], eye[j]))[1] for j in range(dof)], axis=-1)


def _closure(mech: Mechanism, y: _Motion, u, p):
    """``G(Y) = (Phi, G_2, G_3)`` of one sample."""
    return _Motion(mech.residual(y.q, u, p), _first(mech, y.q, y.d1, u, p), _second(mech, y.q, y.d1, y.d2, u, p))


def _positions(problem: StrokeProblem, p, us):
    """Values only: every sample's root ``q (N, m)`` and ``ok (N,)``, each sample from its
    own guess, or (``continuation``) by the walk from the first sample's."""
    mech = problem.mechanism
    stop = jax.lax.stop_gradient
    p, us = jax.tree_util.tree_map(stop, (p, us))
    if problem.continuation:
        g = problem.guess(p, us[0])
        walked = walk(mech, problem.options, False, us, {k: jnp.reshape(v, (1,)) for k, v in p.items()}, g[None], us.shape[0],
                      robust=False)
        return walked.points.q[0], walked.converged[0] & jnp.all(jnp.isfinite(g))

    def one(u):
        g = problem.guess(p, u)
        finite = jnp.all(jnp.isfinite(g))
        res = newton(mech, problem.options, u, p, where(finite, g, jnp.zeros_like(g)))
        return res.q, finite & (res.status == Status.CONVERGED)

    return jax.vmap(one)(us)


def _sample_motion(problem: StrokeProblem, p, u, q, ok):
    """Values only: one sample's motion from its root (placeholders where not ``ok``):
    ``(_Motion, Phi_q^-1)``."""
    mech = problem.mechanism
    p, u, q = jax.tree_util.tree_map(jax.lax.stop_gradient, (p, u, q))
    q = where(ok, q, jnp.zeros_like(q))
    d1, d2 = input_derivatives(mech, q, u, p, ok)
    jq = jax.jacfwd(mech.residual)(q, u, p)
    jinv = inv_small(where(ok, jq, jnp.eye(mech.m, dtype=jq.dtype)), blocks(mech))
    return _Motion(q, d1, d2), jinv


def _solve_stroke(problem: StrokeProblem, p, us):
    """Every sample's ``(_Motion, Phi_q^-1, ok)``, ``(N, ...)`` in front."""
    q, ok = _positions(problem, p, us)
    y, jinv = jax.vmap(lambda u_, q_, ok_: _sample_motion(problem, p, u_, q_, ok_))(us, q, ok)
    return y, jinv, ok


def _apply(a, r):
    """``-a r`` over the leading axis of ``r`` (``(m, ...)``): ``a`` is ``Phi_q^-1`` or its transpose."""
    return -jnp.tensordot(a, r, axes=1)


def _tangent(problem: StrokeProblem, y: _Motion, jinv, u, p, dp) -> _Motion:
    """``Y_x`` along one design direction (its parameters' tangent ``dp``): forward
    substitution through the three blocks of ``G_Y``."""
    mech = problem.mechanism
    # block 1: Phi_q dq = -Phi_p dp
    dq = _apply(jinv, jax.jvp(lambda p_: mech.residual(y.q, u, p_), (p,), (dp,))[1])
    # block 2: Phi_q dq' = -(G_2)_(q, p) (dq, dp)
    dd1 = _apply(jinv, jax.jvp(lambda q_, p_: _first(mech, q_, y.d1, u, p_), (y.q, p), (dq, dp))[1])
    # block 3: Phi_q dq'' = -(G_3)_(q, q', p) (dq, dq', dp)
    dd2 = _apply(jinv, jax.jvp(lambda q_, d1_, p_: _second(mech, q_, d1_, y.d2, u, p_), (y.q, y.d1, p), (dq, dd1, dp))[1])
    return _Motion(dq, dd1, dd2)


def _adjoint(problem: StrokeProblem, y: _Motion, jinv, u, p, r_y: _Motion) -> _Motion:
    """``lambda`` with ``G_Y' lambda = -r_Y`` for one sample: back substitution."""
    mech = problem.mechanism
    lam3 = _apply(jinv.T, r_y.d2)
    _, vjp3 = jax.vjp(lambda q_, d1_: _second(mech, q_, d1_, y.d2, u, p), y.q, y.d1)
    g3_q, g3_d1 = vjp3(lam3)
    lam2 = _apply(jinv.T, r_y.d1 + g3_d1)
    _, vjp2 = jax.vjp(lambda q_: _first(mech, q_, y.d1, u, p), y.q)
    (g2_q,) = vjp2(lam2)
    lam1 = _apply(jinv.T, r_y.q + g2_q + g3_q)
    return _Motion(lam1, lam2, lam3)


def _motion(problem: StrokeProblem, y: _Motion, dtype) -> Motion:
    us, ud, udd = (jnp.asarray(a, dtype) for a in (problem.us, problem.u_dot, problem.u_ddot))
    qd, qdd = jax.vmap(chain_rule)(y.d1, y.d2, ud, udd)
    n = us.shape[0]
    return Motion(t=jnp.asarray(problem.t, dtype), u=us, u_dot=ud, u_ddot=udd, q=y.q, q_dot=qd, q_ddot=qdd, dq_du=y.d1, d2q_du2=y.d2,
                  points={}, status=jnp.zeros((n,), jnp.int32), coords=problem.mechanism.coords, inputs=problem.mechanism.inputs)


def _rows(problem: StrokeProblem, x, y: _Motion):
    """The stacked rows ``(peak, eq, le)`` of the design ``x (n,)`` on the motion ``y``."""
    p = problem.params(dict(zip(problem.names, x)))
    s = problem.rows(p, _motion(problem, y, x.dtype))
    return jnp.concatenate(stated_rows(s, x.dtype))


def stroke_sizes(problem: StrokeProblem, dtype=None) -> tuple:
    """``(peak, eq, le)``: how many rows of each kind the problem states."""
    dtype = dtype or jnp.result_type(float)
    n, m, dof = problem.us.shape[0], problem.mechanism.m, problem.mechanism.dof
    y = _Motion(jax.ShapeDtypeStruct((n, m), dtype), jax.ShapeDtypeStruct((n, m, dof), dtype), jax.ShapeDtypeStruct((n, m, dof, dof), dtype))

    def parts(x, y_):
        p = problem.params(dict(zip(problem.names, x)))
        s = problem.rows(p, _motion(problem, y_, dtype))
        return stated_rows(s, dtype)

    out = jax.eval_shape(parts, jax.ShapeDtypeStruct((len(problem.names),), dtype), y)
    return tuple(int(a.shape[0]) for a in out)


def stroke_evaluator(problem: StrokeProblem):
    """``evaluate(x (n,), w (k,)) -> RowDerivatives``: the rows at the design `x`, their
    Jacobian, and the Hessian of ``w . rows`` (``w``: one weight per row, e.g. the
    Lagrange multipliers), exact (module docstring).  Traceable and vmappable."""
    mech = problem.mechanism

    def evaluate(x, w):
        dtype = x.dtype
        n = x.shape[0]
        us = jnp.asarray(problem.us, dtype)
        params = lambda x_: problem.params(dict(zip(problem.names, x_)))  # noqa: E731
        p = params(x)
        y, jinv, ok_i = _solve_stroke(problem, p, us)
        # design tangents: dp for each direction, then Y_x sample by sample
        eye = jnp.eye(n, dtype=dtype)
        dps = jax.vmap(lambda e: jax.jvp(params, (x,), (e,))[1])(eye)
        dy = jax.vmap(lambda dp: jax.vmap(lambda y_, j_, u_: _tangent(problem, y_, j_, u_, p, dp))(y, jinv, us))(dps)
        # values and Jacobian of the rows: forward mode along V_j = (e_j, Y_x e_j)
        rows = lambda x_, y_: _rows(problem, x_, y_)  # noqa: E731
        values = rows(x, y)
        jac = jax.vmap(lambda e, d: jax.jvp(rows, (x, y), (e, d))[1])(eye, dy).T
        # the adjoint of r = w . rows, then the Hessian of r + lambda . G along the V_j
        r = lambda x_, y_: jnp.dot(w, rows(x_, y_))  # noqa: E731
        r_y = jax.grad(r, argnums=1)(x, y)
        lam = jax.vmap(lambda y_, j_, u_, ry: _adjoint(problem, y_, j_, u_, p, ry))(y, jinv, us, r_y)

        def lagrangian(x_, y_):
            p_ = params(x_)
            g = jax.vmap(lambda yy, u_: _closure(mech, yy, u_, p_))(y_, us)
            return r(x_, y_) + sum(jnp.sum(a * b) for a, b in zip(jax.tree_util.tree_leaves(lam), jax.tree_util.tree_leaves(g)))

        grad_l = jax.grad(lagrangian, argnums=(0, 1))
        hv = jax.vmap(lambda e, d: jax.jvp(grad_l, (x, y), (e, d))[1])(eye, dy)  # ((n, n), _Motion (n, ...))
        hess = hv[0] + sum(jnp.einsum("j...,l...->lj", a, b) for a, b in zip(jax.tree_util.tree_leaves(hv[1]), jax.tree_util.tree_leaves(dy)))
        hess = 0.5 * (hess + hess.T)
        ok = jnp.all(ok_i) & jnp.all(jnp.isfinite(values)) & jnp.all(jnp.isfinite(jac)) & jnp.all(jnp.isfinite(hess))
        return RowDerivatives(values, jac, hess, ok)

    return evaluate


def stroke_state(problem: StrokeProblem) -> Callable:
    """The same problem as a ``state(x) -> Stated`` for ``design.constrained.minimize`` and the
    generic evaluators (positions attached by the implicit rule; values as ``stroke_evaluator``)."""
    from ..solver.implicit import implicit_positions
    mech = problem.mechanism

    def state(xd):
        x = jnp.stack([jnp.asarray(xd[k]) for k in problem.names])
        p = problem.params(dict(zip(problem.names, x)))
        us = jnp.asarray(problem.us, x.dtype)
        y0, _, ok_i = _solve_stroke(problem, p, us)

        def attach(q, ok, u):
            q = implicit_positions(mech, q, ok, u, p)
            return q, *input_derivatives(mech, q, u, p, ok)

        q, d1, d2 = jax.vmap(attach)(y0.q, ok_i, us)
        s = problem.rows(p, _motion(problem, _Motion(q, d1, d2), x.dtype))
        return Stated(peak=s.peak, eq=s.eq, le=s.le, ok=jnp.all(ok_i))

    return state
