"""Statics: the equilibrium inputs of a force-driven ``Model``, ``tau(u) = tau_applied``.

``tau(u)`` is the quasi-static generalized force (``virtual_power.generalized_forces`` with
``inertia=False``).  One input: safeguarded Newton inside a sign-change bracket; several:
Newton clipped to a box.  The root is attached to the parameters by an implicit-function
custom JVP, so ``u*`` is differentiable (forward and reverse mode) in every parameter.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.linalg import solve_small
from ..actuators import Spec, resolve, spec_names
from ..solver.implicit import implicit_positions, implicit_solution
from ..solver.inputs import as_coords, as_inputs
from ..solver.options import SolverOptions
from ..solver.positions import solve_one
from ..solver.status import Status
from .closure import close_loop
from .model import Model, prepare_params
from .virtual_power import generalized_forces
from ..solver.xla import jit

__all__ = ["Equilibrium", "equilibrium"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Equilibrium:
    """Static equilibrium (a pytree; leading axes = designs).

    - `u`: equilibrium inputs ``(..., dof)``, differentiable in every parameter (implicit
      function theorem); NaN where the status is not ``OK``.
    - `q`: coordinates there ``(..., m)``.
    - `stiffness`: ``d(tau - tau_applied)/du`` at the equilibrium ``(..., dof, dof)``
      (N m/rad or N/m); positive (definite) means stable.
    - `status`: ``Status`` per design; `steps`: Newton iterations.
    """

    u: jax.Array
    q: jax.Array
    stiffness: jax.Array
    status: jax.Array
    steps: jax.Array

    @property
    def stable(self):
        """True where the stiffness is positive definite."""
        if self.stiffness.shape[-1] == 1:
            return self.stiffness[..., 0, 0] > 0
        return jnp.all(jnp.linalg.eigvalsh(0.5 * (self.stiffness + jnp.swapaxes(self.stiffness, -1, -2))) > 0, axis=-1)


def static_residual(model: Model, applied, u, args):
    """``R(u, p) = tau_quasi_static(u, p) - tau_applied(p)`` with ``q = q*(u, p)`` implicit;
    ``args = (q_star, ok, p, t)``: the positions solved at ``u`` (the implicit rule of the
    positions ignores the tangent of ``q_star``), whether they converged, the parameters
    and the time (s)."""
    q_star, ok, p, t = args
    q = implicit_positions(model.mechanism, q_star, ok, u, p)
    tau, _ = generalized_forces(model, q, u, jnp.zeros_like(u), jnp.zeros_like(u), p, t, inertia=False)
    return tau - jnp.broadcast_to(jnp.asarray(resolve(applied, p), tau.dtype), tau.shape)


class SearchContext(NamedTuple):
    """What every iteration of one equilibrium search shares: the model, the applied force
    spec, the options, the budget, the range ``[lo, hi]`` and start `u0` ``(dof,)``, the
    parameters `ps` and time `ts` without gradient, and the tolerances (`eps` of the dtype,
    `xtol` on the step)."""

    model: Model
    applied: Spec
    options: SolverOptions
    max_steps: int
    lo: jax.Array
    hi: jax.Array
    u0: jax.Array
    ps: Mapping
    ts: jax.Array
    eps: float
    xtol: float


class Search(NamedTuple):
    """The search's loop state: iteration `k`, the iterate `u` with its coordinates `q`,
    residual `r` and Jacobian `j`, the bracket ``[a, b]`` (one input), the last `step`,
    whether the positions converged (`ok`), `done`, the residual at ``lo`` and whether the
    range holds a root (`has_root`)."""

    k: jax.Array
    u: jax.Array
    q: jax.Array
    r: jax.Array
    j: jax.Array
    a: jax.Array
    b: jax.Array
    step: jax.Array
    ok: jax.Array
    done: jax.Array
    r_lo: jax.Array
    has_root: jax.Array


class EquilibriumOne(NamedTuple):
    """One design's equilibrium (``equilibrium_one``): inputs `u`, coordinates `q`, the
    `stiffness` ``dR/du``, the ``Status`` `status` and the Newton `steps`."""

    u: jax.Array
    q: jax.Array
    stiffness: jax.Array
    status: jax.Array
    steps: jax.Array


class PointEvaluation(NamedTuple):
    """The search's evaluation at one input (``evaluate_point``): coordinates `q`, static
    residual `r` (N m or N), its Jacobian `j` ``dR/du`` and `ok` (the positions converged)."""

    q: jax.Array
    r: jax.Array
    j: jax.Array
    ok: jax.Array


def evaluate_point(cx: SearchContext, u, qg) -> PointEvaluation:
    """The positions solved at the inputs `u` from `qg`, the static residual and its
    Jacobian (one forward-mode tangent for one input)."""
    mech = cx.model.mechanism
    sol = solve_one(mech, u, cx.ps, qg, cx.options)
    ok = sol.status == Status.CONVERGED
    f = lambda u_: static_residual(cx.model, cx.applied, u_, (sol.q, ok, cx.ps, cx.ts))  # noqa: E731
    r, j = jax.jvp(f, (u,), (jnp.ones_like(u),)) if mech.dof == 1 else (f(u), None)
    j = j[:, None] if mech.dof == 1 else jax.jacfwd(f)(u)
    return PointEvaluation(sol.q, r, j, ok)


def search_step(cx: SearchContext, st: Search) -> Search:
    """One iteration: a Newton step (safeguarded in the bracket for one input, clipped to
    the box otherwise) evaluated.  One copy of the (costly to compile) residual: iteration 0
    evaluates the start and both ends of the range as a batch of three; later iterations
    evaluate their one new point."""
    k, u, q, r, j, a, b, step, ok, done, r_lo, has_root = st
    lo, hi, u0 = cx.lo, cx.hi, cx.u0
    bracket = cx.model.mechanism.dof == 1
    first = k == 0
    newton = u - solve_small(j, r)
    if bracket:
        # Safeguarded Newton (rtsafe): keep a sign-change bracket, bisect when Newton leaves it.
        inside = jnp.all(jnp.isfinite(newton)) & (newton[0] > a[0]) & (newton[0] < b[0])
        cand = jnp.where(inside, newton, 0.5 * (a + b))
    else:
        cand = jnp.clip(jnp.where(jnp.all(jnp.isfinite(newton)), newton, u), lo, hi)
    un = jnp.where(first, u0, cand)
    pts = jnp.where(first, jnp.stack([u0, lo, hi]), jnp.stack([un, un, un]))
    qs, rs, js, oks = jax.vmap(functools.partial(evaluate_point, cx), in_axes=(0, None))(pts, q)
    qn, rn, jn, okn = qs[0], rs[0], js[0], oks[0]
    if bracket:
        change = jnp.sign(rs[1, 0]) != jnp.sign(rs[2, 0])
        root0 = (oks[1] & oks[2] & change) | (rs[1, 0] == 0) | (rs[2, 0] == 0)
        has_root = jnp.where(first, root0, has_root)
        r_lo = jnp.where(first, rs[1], r_lo)
        same = jnp.sign(rn[0]) == jnp.sign(r_lo[0])
        a = jnp.where(first, lo, jnp.where(same, un, a))
        b = jnp.where(first, hi, jnp.where(same, b, un))
    step = jnp.where(first, jnp.inf, jnp.max(jnp.abs(un - u)))
    scale = 1.0 + jnp.max(jnp.abs(un))
    done = (step <= cx.xtol * scale) | jnp.all(rn == 0) | ~okn | ~jnp.all(jnp.isfinite(rn)) | ~has_root
    if bracket:
        done = done | (b[0] - a[0] <= cx.eps * scale)
    return Search(k + 1, un, qn, rn, jn, a, b, step, okn, done, r_lo, has_root)


def search_status(cx: SearchContext, st: Search):
    """``(u, status)`` after the search: one more (cheap) Newton step, which takes the
    error from ``~step^2`` to round-off, kept inside the bracket; the ``Status``
    (no root in the range or Newton out of the box, positions failed, converged or not)."""
    k, u, q, r, j, a, b, step, ok, done, r_lo, has_root = st
    bracket = cx.model.mechanism.dof == 1
    last = u - solve_small(j, r)
    scale = 1.0 + jnp.max(jnp.abs(u))
    conv = ok & jnp.all(jnp.isfinite(r)) & ((step <= cx.xtol * scale) | jnp.all(r == 0))
    if bracket:
        conv = conv | (ok & (b[0] - a[0] <= cx.eps * scale))
        last = jnp.where((last[0] >= a[0]) & (last[0] <= b[0]), last, u)
    else:
        in_box = jnp.all((u > cx.lo) & (u < cx.hi))
    u = jnp.where(conv & jnp.all(jnp.isfinite(last)), last, u)
    status = jnp.where(
        ~has_root, Status.NO_EQUILIBRIUM,
        jnp.where(~ok, Status.POSITION, jnp.where(conv, Status.CONVERGED, Status.NOT_CONVERGED)))
    if not bracket:
        status = jnp.where((status == Status.NOT_CONVERGED) & ~in_box, Status.NO_EQUILIBRIUM, status)
    return u, status


def equilibrium_one(model: Model, applied, options: SolverOptions, max_steps: int, lo, hi, u0, guess, p, t) -> EquilibriumOne:
    """One design's equilibrium (vmapped by ``equilibrium``): the search (``search_step``
    until done or out of budget), its status (``search_status``), then ``u*`` and the
    coordinates attached to ``(p, t)`` by the implicit rule."""
    mech = model.mechanism
    stop = jax.lax.stop_gradient
    ps, ts = jax.tree_util.tree_map(stop, p), stop(t)
    dtype = guess.dtype
    eps = float(jnp.finfo(dtype).eps)
    xtol = eps ** 0.75  # Newton is quadratic: one more step after this leaves ~eps
    cx = SearchContext(model, applied, options, max_steps, lo, hi, u0, ps, ts, eps, xtol)
    zero_r = jnp.zeros((mech.dof,), dtype)
    init = Search(0, u0, guess, zero_r, jnp.eye(mech.dof, dtype=dtype), lo, hi, jnp.asarray(jnp.inf, dtype),
                  jnp.asarray(False), jnp.asarray(False), zero_r, jnp.asarray(True))
    st = jax.lax.while_loop(lambda s: (~s.done) & (s.k < max_steps + 1), functools.partial(search_step, cx), init)
    k = st.k - 1  # iteration 0 only evaluated the start and the ends
    u, status = search_status(cx, st)
    q, j = st.q, st.j
    good = status == Status.CONVERGED
    u_star = jnp.where(good, stop(u), jnp.nan)
    # u* attached to (p, t) by the implicit rule on R(u*(p, t), p, t) = 0: du = -R_u^{-1} R_p dp.
    u_eq = implicit_solution(functools.partial(static_residual, model, applied), u_star, good,
                             (jnp.where(good, q, jnp.nan), good, p, t))
    # Close the loop at the final input (a few Newton steps from the last iterate's q, which is
    # within one quadratically small step) and attach it to (u_eq, p).
    q_eq, q_ok = close_loop(mech, u_eq, p, jnp.where(good, q, guess), 3, options)
    good = good & q_ok
    status = jnp.where((status == Status.CONVERGED) & ~q_ok, Status.POSITION, status)
    # The stiffness is the last iterate's Jacobian (one Newton step away: a diagnostic).
    return EquilibriumOne(u_eq, q_eq, jnp.where(good, j, jnp.nan), status.astype(jnp.int32), k)


@functools.partial(jit, static_argnums=(0, 1, 2, 3))
def _equilibrium_batch(model, applied, options, max_steps, lo, hi, u0, guess, p, t):
    return jax.vmap(lambda *a: equilibrium_one(model, applied, options, max_steps, *a))(lo, hi, u0, guess, p, t)


def equilibrium(model: Model, p: Mapping, bounds, guess, *, u0=None, applied: Spec = 0.0, t=0.0,
                options: SolverOptions = SolverOptions(), max_steps: int = 60) -> Equilibrium:
    """Static equilibrium of a force-driven scene: ``tau(u) = tau_applied`` for the inputs.

    ``tau(u)`` is the quasi-static generalized force the loads and gravity need at the input
    (``generalized_forces(..., inertia=False)``); a free hinge has ``tau_applied = 0``.  One
    input: safeguarded Newton inside the sign-change bracket ``bounds`` (always converges when
    the range holds a sign change).  Several inputs: Newton clipped to the box ``bounds``.

    **Arguments**

    - `p`: parameters (arrays broadcast: a batch of designs).
    - `bounds`: ``(lo, hi)`` input range, each ``(dof,)`` or scalar for one input.
    - `guess`: coordinates ``(m,)`` near the solution (picks the branch over the range).
    - `u0`: starting input (default the middle of the range).
    - `applied`: spec of the generalized force an actuator applies at the input (N m or N).
    - `t`: time for time-dependent loads (s).

    **Returns** an ``Equilibrium``; ``status`` ``NO_EQUILIBRIUM`` when the residual keeps one
    sign over the range (one input) or Newton leaves the box (several).  ``u`` and ``q`` are
    differentiable in ``p`` (implicit function theorem, forward and reverse mode).
    """
    mech = model.mechanism
    lo, hi = (as_inputs(mech, jnp.asarray(b), "bounds") for b in bounds)
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(lo, hi, guess, float)
    pj = prepare_params(model, p, dtype, spec_names(applied))
    u0 = 0.5 * (lo + hi) if u0 is None else as_inputs(mech, jnp.asarray(u0), "u0")
    t = jnp.asarray(t, dtype)
    shape = np.broadcast_shapes(lo.shape[:-1], hi.shape[:-1], u0.shape[:-1], guess.shape[:-1], t.shape,
                                *[v.shape for v in pj.values()])
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    out = _equilibrium_batch(model, applied, options, int(max_steps), flat(lo.astype(dtype), 1), flat(hi.astype(dtype), 1),
                             flat(u0.astype(dtype), 1), flat(guess.astype(dtype), 1), {k: flat(v, 0) for k, v in pj.items()},
                             flat(t, 0))
    u, q, stiff, status, steps = (x.reshape(shape + x.shape[1:]) for x in out)
    return Equilibrium(u=u, q=q, stiffness=stiff, status=status, steps=steps)

