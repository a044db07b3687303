"""Position solve: damped Newton on the loop-closure equations, with implicit derivatives.

Every function here works on one sample; batching is ``jax.vmap`` (the public
``solve``/``solve_stroke`` broadcast for the user).

Derivatives never go through the Newton iterations.  The converged root ``q*`` is
attached to ``(u, p)`` by a custom JVP that implements the implicit function theorem:
differentiating ``Phi(q*(u, p), u, p) = 0`` gives

    Phi_q dq + Phi_u du + Phi_p dp = 0   =>   dq = -Phi_q^{-1} (Phi_u du + Phi_p dp).

The rule is written in JAX primitives evaluated at the attached (differentiable) root,
so forward mode, reverse mode (by transposition of the linear solve) and every higher
order follow.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .mechanism import Mechanism, _unfused
from .status import Status

__all__ = ["SolverOptions", "Solution", "solve", "solve_stroke", "solve_one", "implicit_root"]


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Static solver settings (hashable; part of the compiled function's identity).

    - `max_steps`: Newton/Levenberg-Marquardt iteration budget per sample.
    - `xtol`: converged when the next scaled Newton step is below this (rad, or
      multiples of the design's length scale).  Default ``eps**(2/3)`` of the dtype.
    - `ftol`: converged residual, relative to the design's length scale.  Default
      ``1024 eps``.
    - `cond_max`: a converged sample whose scaled Jacobian condition number exceeds
      this is reported ``SINGULAR``.  Default ``eps**-0.5``.
    - `max_step`: largest scaled step per iteration (rad, or length scales); keeps far-off
      guesses from jumping across assembly branches.
    - `patience`: iterations with less than 10% residual decrease before a sample is
      declared stalled (``INFEASIBLE``).
    - `lean_steps`: plain Newton steps tried first for stroke points, from their anchor's
      second-order predictor; a point is accepted only if the next step is below
      ``min(xtol, 1e4 eps)`` with the residual, conditioning and branch tests met, and
      the others get the robust loop.  One step suffices on smooth strokes with the
      default 256 anchors (measured: every one of 1e6 four-bar positions).
    - `dtype`: require this floating dtype (``"float64"`` raises if x64 is off or an
      argument is float32); ``None`` follows the arguments.
    """

    max_steps: int = 80
    xtol: float | None = None
    ftol: float | None = None
    cond_max: float | None = None
    max_step: float = 1.0
    patience: int = 8
    lean_steps: int = 1
    dtype: str | None = None


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Solution:
    """Result of a position solve (a pytree; every array field has the batch shape in front).

    - `q`: dependent coordinates, ``(..., m)``; NaN where the status is not ``CONVERGED``.
    - `status`: ``(...)`` int32 ``Status`` codes.
    - `steps`: iterations used.
    - `residual`: final ``|Phi / R|_2``, R the residual scale (the length scale for loops).
    - `cond`: 1-norm condition number of the scaled constraint Jacobian ``Phi_q``.
    - `branch`: the mechanism's branch indicator at the solution (NaN if none defined).
    - `coords`: coordinate names (static).
    """

    q: jax.Array
    status: jax.Array
    steps: jax.Array
    residual: jax.Array
    cond: jax.Array
    branch: jax.Array
    coords: tuple = dataclasses.field(metadata=dict(static=True), default=())

    def __getitem__(self, name: str):
        """Coordinate by name: ``sol["theta3"]``."""
        try:
            return self.q[..., self.coords.index(name)]
        except ValueError:
            raise KeyError(f"unknown coordinate {name!r}; coordinates: {self.coords}") from None

    @property
    def ok(self):
        """Boolean mask of converged samples."""
        return self.status == Status.CONVERGED


# --------------------------------------------------------------------------- small linear algebra
# Per-sample systems are tiny (m = 1..8) and run under vmap over up to 1e6 samples.  XLA's
# CPU batched LAPACK path is ~12x slower per sample than straight-line code, and reductions
# over a size-m axis end an XLA fusion (everything feeding them is recomputed in the next
# one), so small sizes are unrolled into elementwise operations.  Up to 4x4: unrolling a
# 6x6 elimination (flap_msd) added ~8 s of compile per function for no measurable gain.
_UNROLL_MAX = 4


def _small_max(x):
    """Max over the last axis, unrolled for small sizes."""
    if x.shape[-1] > _UNROLL_MAX:
        return jnp.max(x, axis=-1)
    return functools.reduce(jnp.maximum, [x[..., i] for i in range(x.shape[-1])])


def _small_sum(x):
    """Sum over the last axis, unrolled for small sizes."""
    if x.shape[-1] > _UNROLL_MAX:
        return jnp.sum(x, axis=-1)
    return functools.reduce(jnp.add, [x[..., i] for i in range(x.shape[-1])])


def _small_norm(x):
    """Euclidean norm of a vector, unrolled for small sizes."""
    return jnp.sqrt(_small_sum(x * x))


def _gauss_small(a, b):
    """Gaussian elimination with partial pivoting, written out for ``3 <= n <= _UNROLL_MAX``.

    `b` is ``(n,)`` or ``(n, k)``.  Row swaps are selects, so the whole solve is one
    straight-line elementwise program under vmap.  ``a`` and ``b`` are eliminated side by
    side (not as one augmented matrix) so the solve stays linear in ``b`` for reverse mode.
    """
    n = a.shape[-1]
    vec = b.ndim == 1
    ra = [a[i] for i in range(n)]
    rb = [b[i].reshape(-1) for i in range(n)]
    for k in range(n):
        # pivot: bring the largest |a[i, k]|, i >= k, to row k
        for i in range(k + 1, n):
            swap = jnp.abs(ra[i][k]) > jnp.abs(ra[k][k])
            ra[k], ra[i] = jnp.where(swap, ra[i], ra[k]), jnp.where(swap, ra[k], ra[i])
            rb[k], rb[i] = jnp.where(swap, rb[i], rb[k]), jnp.where(swap, rb[k], rb[i])
        for i in range(k + 1, n):
            f = ra[i][k] / ra[k][k]
            ra[i] = ra[i] - f * ra[k]
            rb[i] = rb[i] - f * rb[k]
    x = [None] * n
    for i in reversed(range(n)):
        acc = rb[i]
        for j in range(i + 1, n):
            acc = acc - ra[i][j] * x[j]
        x[i] = acc / ra[i][i]
    out = jnp.stack(x)
    return out[:, 0] if vec else out


def _gauss_loop(a, b):
    """Gaussian elimination with partial pivoting as a ``fori_loop`` over columns, for
    ``n > _UNROLL_MAX``: compact to compile, elementwise under vmap (no batched LAPACK
    call; those were seen to hang the jaxlib 0.10 CPU runtime in large batched loops).
    ``a`` and ``b`` are eliminated side by side so the solve stays linear in ``b``.
    """
    n = a.shape[-1]
    vec = b.ndim == 1
    rhs = b.reshape(n, -1)
    rows = jnp.arange(n)

    def eliminate(k, state):
        m, r = state
        col = jnp.where(rows >= k, jnp.abs(m[:, k]), -1.0)
        piv = jnp.argmax(col)
        perm = rows.at[k].set(piv).at[piv].set(k)
        m, r = m[perm], r[perm]
        f = jnp.where(rows > k, m[:, k] / m[k, k], 0.0)
        return m - f[:, None] * m[k][None, :], r - f[:, None] * r[k][None, :]

    m, r = jax.lax.fori_loop(0, n, eliminate, (a, rhs))

    def substitute(j, x):
        i = n - 1 - j
        xi = (r[i] - m[i] @ x) / m[i, i]  # x[i:] rows not yet set are zero
        return x.at[i].set(xi)

    x = jax.lax.fori_loop(0, n, substitute, jnp.zeros_like(r))
    return x[:, 0] if vec else x


def _solve_small(a, b):
    """Solve ``a x = b`` for one small dense system (``b`` of shape ``(n,)`` or ``(n, k)``).

    Cramer's rule for 1x1 and 2x2, unrolled elimination up to ``_UNROLL_MAX``, a loop beyond.
    """
    n = a.shape[-1]
    if n == 1:
        return b / a[0, 0]
    if n == 2:
        det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
        x0 = (a[1, 1] * b[0] - a[0, 1] * b[1]) / det
        x1 = (a[0, 0] * b[1] - a[1, 0] * b[0]) / det
        return jnp.stack([x0, x1])
    if n <= _UNROLL_MAX:
        return _gauss_small(a, b)
    return _gauss_loop(a, b)


def _inv_small(a):
    return _solve_small(a, jnp.eye(a.shape[-1], dtype=a.dtype))


def _materialize(*xs):
    """The arrays ``xs`` (one sample's few values), each computed once under jit on CPU.

    A value used by several outputs (the fast path's ``ok`` feeds all of them) is otherwise
    recomputed, with its whole cone, in each output's fusion; the values are packed into
    one vector and passed through ``_unfused`` (see there for exactness).
    """
    flat = [jnp.ravel(jnp.asarray(x, dtype=jnp.result_type(*xs))) for x in xs]
    v = _unfused(jnp.concatenate(flat))
    out, start = [], 0
    for x, f in zip(xs, flat):
        out.append(v[start : start + f.shape[0]].reshape(jnp.shape(x)).astype(jnp.asarray(x).dtype))
        start += f.shape[0]
    return out


def _cond1(a):
    """1-norm condition number of a small square matrix (inf where singular)."""
    norm1 = lambda m: _small_max(_small_sum(jnp.abs(m).T))  # noqa: E731  (max column sum)
    c = norm1(a) * norm1(_inv_small(a))
    return jnp.where(jnp.isfinite(c), c, jnp.inf)


# --------------------------------------------------------------------------- tolerances
def _tolerances(opts: SolverOptions, dtype):
    eps = float(jnp.finfo(dtype).eps)
    xtol = opts.xtol if opts.xtol is not None else eps ** (2.0 / 3.0)
    ftol = opts.ftol if opts.ftol is not None else 1024.0 * eps
    cond_max = opts.cond_max if opts.cond_max is not None else eps**-0.5
    return xtol, ftol, cond_max


def _all_finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


# --------------------------------------------------------------------------- Newton (no gradients)
def _coord_scales(mech: Mechanism, p, dtype):
    """``s (m,)``: 1 for angles, the design's length scale for lengths (m)."""
    L = mech.length_scale(p).astype(dtype)
    return jnp.where(jnp.asarray(mech.coord_is_length()), L, jnp.ones((), dtype))


def _scaled_residual(mech: Mechanism, u, p, dtype):
    """``q -> (Phi/R, d(Phi/R)/dz)`` with ``z = q / s``, and the coordinate scales ``s``.

    ``s`` is 1 for angles and the design's length scale for lengths; ``R`` is the residual
    scale (the length scale for loop closures).  Both make tolerances unit-independent.
    """
    R = mech.residual_scales(p, dtype)
    s = _coord_scales(mech, p, dtype)

    def evaluate(q):
        def f(q_):
            r = mech.residual(q_, u, p) / R
            return r, r

        j, r = jax.jacfwd(f, has_aux=True)(q)
        return r, j * s[None, :]

    return evaluate, s


def _lean_newton(mech: Mechanism, opts: SolverOptions, iters: int, u, p, guess, b0):
    """A fixed number of plain Newton steps from a close guess, then the same convergence,
    conditioning, finiteness and branch tests as ``_newton``: the fast path for stroke
    points predicted from a solved anchor.  No loop control, no damping, no gradients.

    Returns ``(q_check, q, ok, rn, cond, branch)``: ``q_check`` is the last iterate, at which
    the tests (and, in ``_stroke_batch``, the derivatives) are evaluated; it is always
    finite, so derivative code at it never produces NaN.  ``q = q_check - dz`` adds the
    Newton step computed by the test.  Samples with ``ok`` False go to ``_newton``.
    """
    dtype = guess.dtype
    _, ftol, cond_max = _tolerances(opts, dtype)
    evaluate, s = _scaled_residual(mech, u, p, dtype)
    q = guess
    for _ in range(iters):
        r, js = evaluate(q)
        q = q - _solve_small(js, r) * s
    finite_q = jnp.all(jnp.isfinite(q))
    q = jnp.where(finite_q, q, jnp.zeros_like(q))
    r, js = evaluate(q)
    dz = _solve_small(js, r)
    rn = _small_norm(r)
    cond = _cond1(js)
    br = mech.branch_value(q, u, p)
    ok = (_small_max(jnp.abs(dz)) <= _lean_xtol(opts, dtype)) & (rn <= ftol) & (cond <= cond_max)
    ok = ok & finite_q & jnp.all(jnp.isfinite(dz)) & _on_branch_value(b0, br)
    qf = jnp.where(ok, q - dz * s, q)
    # ok feeds every output; computing it once saves ~20% of the fast path (all finite here)
    qf, okf = _materialize(qf, ok.astype(dtype))
    return q, qf, okf > 0.5, rn, cond, br


def _lean_xtol(opts: SolverOptions, dtype):
    """Step test of the fast path.  Its derivatives are taken at the last iterate, one
    Newton step ``dz`` from the reported root, and they move by ``|dz|`` times the
    curvature; ``dz <= 1e4 eps`` keeps that below 1e-9 relative up to a condition number
    of ~1e3 (beyond which the robust loop re-solves the point anyway).
    """
    return min(_tolerances(opts, dtype)[0], 1e4 * float(jnp.finfo(dtype).eps))


def _newton(mech: Mechanism, opts: SolverOptions, u, p, guess):
    """Damped Newton / Levenberg-Marquardt for one sample.  Returns raw (q, status, ...).

    Work is in scaled variables: ``z = q / s`` with ``s`` = 1 for angles and the design's
    length scale ``L`` for lengths, residual ``Phi / R`` (``R = L`` for loop closures, or
    the mechanism's ``residual_scale``).  A full Newton step is tried
    first; when it does not lower ``|Phi|`` the step is regularised (LM parameter ``mu``),
    which makes far-off guesses safe without costing the quadratic convergence near a root.
    """
    dtype = guess.dtype
    xtol, ftol, cond_max = _tolerances(opts, dtype)
    evaluate, s = _scaled_residual(mech, u, p, dtype)
    m = mech.m
    eye = jnp.eye(m, dtype=dtype)

    def step(r, js, mu):
        newton = _solve_small(js, r)
        jtj = js.T @ js
        lm = _solve_small(jtj + mu * (jnp.diag(jnp.diag(jtj)) + 1e-12 * eye), js.T @ r)
        dz = jnp.where(mu > 0, lm, newton)
        dz = jnp.where(jnp.all(jnp.isfinite(dz)), dz, jnp.zeros_like(dz))
        size = jnp.max(jnp.abs(dz))
        # Cap the step: far from a root a Newton step can leap onto another branch.
        return dz * jnp.minimum(1.0, opts.max_step / jnp.maximum(size, 1e-300)), size

    # With a branch indicator, a step that changes its sign is refused like one that raises
    # the residual: the damping then finds the root on the guess's own assembly branch.
    if mech.branch is not None:
        b_guess = jnp.sign(mech.branch_value(guess, u, p))

        def same_branch(q):
            return (b_guess == 0) | (jnp.sign(mech.branch_value(q, u, p)) == b_guess)
    else:

        def same_branch(q):
            return jnp.asarray(True)
    # If the residual stalls while the guard refused better steps across the branch, the
    # guard is lifted once: a root found there is reported BRANCH; none found, INFEASIBLE.

    inputs_ok = _all_finite((u, p, guess))
    r0, j0 = evaluate(guess)
    rn0 = jnp.linalg.norm(r0)
    mu0 = jnp.zeros((), dtype)
    dz0, size0 = step(r0, j0, mu0)
    conv0 = (size0 <= xtol) & (rn0 <= ftol)

    # state: k, q, r, rn, js, dz, size, mu, slow, done, stalled, guard, crossed
    state = (0, guess, r0, rn0, j0, dz0, size0, mu0, 0, conv0 | ~inputs_ok | ~jnp.isfinite(rn0), False, True, False)

    def cond_fn(st):
        k, *_, done, _stalled, _guard, _crossed = st
        return (~done) & (k < opts.max_steps)

    def body(st):
        k, q, r, rn, js, dz, size, mu, slow, done, stalled, guard, crossed = st
        qt = q - dz * s
        rt, jt = evaluate(qt)
        rtn = jnp.linalg.norm(rt)
        better = jnp.isfinite(rtn) & ((rtn < rn) | (rtn <= ftol))
        on_branch = same_branch(qt) | ~guard
        crossed = crossed | (better & ~on_branch)
        accept = better & on_branch
        q, r, rn, js = jax.tree_util.tree_map(lambda a, b: jnp.where(accept, a, b), (qt, rt, rtn, jt), (q, r, rn, js))
        jtj_scale = jnp.max(jnp.diag(js.T @ js))
        mu = jnp.where(accept, jnp.where(mu > 1e-6, mu / 10.0, 0.0), jnp.maximum(10.0 * mu, 1e-3))
        # Steps refused only for crossing the branch are not lack of progress: the damping
        # is still shortening them towards this branch's root.
        slow = jnp.where(accept & (rtn < 0.9 * st[3]), 0, jnp.where(better & ~on_branch, slow, slow + 1))
        stalled = (slow >= opts.patience) | (mu > 1e12 * jnp.maximum(jtj_scale, 1.0))
        lift = stalled & guard & crossed
        guard = guard & ~lift
        mu = jnp.where(lift, 0.0, mu)
        slow = jnp.where(lift, 0, slow)
        stalled = stalled & ~lift
        dz, size = step(r, js, mu)
        converged = (size <= xtol) & (rn <= ftol)
        # A closed loop with a singular Jacobian will never meet xtol: stop and report it.
        singular_closed = (rn <= ftol) & (_cond1(js) > cond_max)
        done = converged | stalled | singular_closed | ~jnp.isfinite(rn)
        return (k + 1, q, r, rn, js, dz, size, mu, slow, done, stalled, guard, crossed)

    k, q, r, rn, js, dz, size, mu, slow, done, stalled, guard, crossed = jax.lax.while_loop(cond_fn, body, state)

    converged = (size <= xtol) & (rn <= ftol)
    q = jnp.where(converged, q - dz * s, q)  # the last Newton step is free: it was computed already
    cond = _cond1(js)
    finite = inputs_ok & jnp.isfinite(rn) & jnp.all(jnp.isfinite(q))
    closed = rn <= ftol
    status = jnp.where(
        ~finite,
        Status.NONFINITE,
        jnp.where(
            closed & (cond > cond_max),
            Status.SINGULAR,
            jnp.where(converged, Status.CONVERGED, jnp.where(stalled, Status.INFEASIBLE, Status.MAX_STEPS)),
        ),
    ).astype(jnp.int32)
    if mech.branch is not None:
        b_guess = mech.branch_value(guess, u, p)
        b_sol = mech.branch_value(q, u, p)
        flipped = (jnp.sign(b_guess) != jnp.sign(b_sol)) & (b_guess != 0)
        status = jnp.where((status == Status.CONVERGED) & flipped, Status.BRANCH, status).astype(jnp.int32)
        branch = b_sol
    else:
        branch = jnp.asarray(jnp.nan, dtype)
    return q, status, k, rn, cond, branch


# --------------------------------------------------------------------------- implicit derivatives
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
    q_s = jnp.where(ok, q, jnp.zeros_like(q))
    u_s = jnp.where(ok, u, jnp.zeros_like(u))
    p_s = jax.tree_util.tree_map(lambda x: jnp.where(ok, x, jnp.ones_like(x)), p)
    du = jnp.where(ok, du, jnp.zeros_like(du))
    dp = jax.tree_util.tree_map(lambda x: jnp.where(ok, x, jnp.zeros_like(x)), dp)
    _, rhs = jax.jvp(lambda u_, p_: mech.residual(q_s, u_, p_), (u_s, p_s), (du, dp))
    jac = jax.jacfwd(mech.residual)(q_s, u_s, p_s)
    jac = jnp.where(ok, jac, jnp.eye(mech.m, dtype=jac.dtype))
    dq = -_solve_small(jac, rhs)
    return q, jnp.where(ok, dq, jnp.zeros_like(dq))


def _derivatives_at(mech: Mechanism, q, u, p, ok):
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
    jq = jnp.where(ok, jq, jnp.eye(m, dtype=jq.dtype))
    ju = jax.jacfwd(mech.residual, 1)(q, u, p)
    d1 = -_solve_small(jq, ju)
    res = lambda q_, u_: mech.residual(q_, u_, p)  # noqa: E731
    eye = jnp.eye(dof, dtype=d1.dtype)

    def second(j, k):
        inner = lambda q_, u_: jax.jvp(res, (q_, u_), (d1[:, k], eye[k]))[1]  # noqa: E731
        return jax.jvp(inner, (q, u), (d1[:, j], eye[j]))[1]

    hess = jnp.stack([jnp.stack([second(j, k) for k in range(dof)], axis=-1) for j in range(dof)], axis=-2)
    d2 = -_solve_small(jq, hess.reshape(m, dof * dof)).reshape(m, dof, dof)
    zero_if = lambda x: jnp.where(ok, x, jnp.zeros_like(x))  # noqa: E731
    return zero_if(d1), zero_if(d2)


def solve_one(mech: Mechanism, u, p, guess, options: SolverOptions = SolverOptions()) -> Solution:
    """Solve ``Phi(q, u, p) = 0`` for one sample, differentiable in ``u`` and ``p``.

    `u`: ``(dof,)``; `p`: mapping of scalars; `guess`: ``(m,)``, which selects the branch.
    Returns a ``Solution`` with scalar status.  No checks: use ``solve`` from user code.
    """
    stop = jax.lax.stop_gradient
    q_raw, status, steps, rn, cond, branch = _newton(mech, options, stop(u), jax.tree_util.tree_map(stop, p), stop(guess))
    ok = status == Status.CONVERGED
    q_star = jnp.where(ok, q_raw, jnp.nan)
    q = implicit_root(mech, q_star, ok, u, p)
    return Solution(q=q, status=status, steps=steps, residual=rn, cond=cond, branch=branch, coords=mech.coords)


# --------------------------------------------------------------------------- user-facing batching
def _stack_named(mech: Mechanism, names, values: Mapping, what: str, kind: str):
    """``{name: array}`` -> array ``(..., len(names))`` in ``names`` order, or ValueError."""
    unknown = [k for k in values if k not in names]
    if unknown:
        raise ValueError(f"{mech.name}: unknown {kind} name(s) {unknown} in {what}; {kind}s are {list(names)}")
    missing = [k for k in names if k not in values]
    if missing:
        raise ValueError(f"{mech.name}: missing {kind}(s) {missing} in {what}")
    return jnp.stack(jnp.broadcast_arrays(*[jnp.asarray(values[k]) for k in names]), axis=-1)


def _with_last_axis(mech: Mechanism, x, names, what: str, kind: str):
    x = jnp.asarray(x)
    if x.ndim == 0 or x.shape[-1] != len(names):
        raise ValueError(f"{mech.name}: {what} must have a last axis of size {len(names)} ({kind}s {names}), got shape {x.shape}")
    return x


def _as_inputs(mech: Mechanism, u, what="u"):
    """Inputs as an array ``(..., dof)``.  A dict maps input names to arrays; for one-input
    mechanisms a bare array is the batch of that input."""
    if isinstance(u, Mapping):
        return _stack_named(mech, mech.inputs, u, what, "input")
    if mech.dof == 1:
        return jnp.asarray(u)[..., None]
    return _with_last_axis(mech, u, mech.inputs, what, "input")


def _as_coords(mech: Mechanism, q, what="guess"):
    """Coordinates as an array ``(..., m)``, from an array or ``{coord_name: array}``."""
    if isinstance(q, Mapping):
        return _stack_named(mech, mech.coords, q, what, "coordinate")
    return _with_last_axis(mech, q, mech.coords, what, "coordinate")


def _check_dtype(options: SolverOptions, named: dict[str, Any]):
    if options.dtype is None:
        return
    want = jnp.dtype(options.dtype)
    if want == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError(
            "dtype='float64' was asked for but JAX runs in float32: call "
            "jax.config.update('jax_enable_x64', True) before creating arrays"
        )
    for name, x in named.items():
        for leaf in jax.tree_util.tree_leaves(x):
            dt = np.asarray(leaf).dtype if not isinstance(leaf, jax.Array) else leaf.dtype
            if jnp.issubdtype(dt, jnp.floating) and dt != want:
                raise ValueError(f"{name} is {dt} but dtype={want} was asked for; convert it with .astype({want.name!r})")


def _prepare(mech: Mechanism, u, p, guess, options: SolverOptions, u_what="u"):
    mech.check_params(p)
    _check_dtype(options, {u_what: u, "p": p, "guess": guess})
    u = _as_inputs(mech, u, u_what)
    guess = _as_coords(mech, guess)
    dtype = jnp.result_type(u, guess, *[jnp.asarray(v) for v in p.values()], float)
    if options.dtype is not None:
        dtype = jnp.dtype(options.dtype)
    u = u.astype(dtype)
    guess = guess.astype(dtype)
    p = {k: jnp.asarray(p[k], dtype) for k in mech.params}
    return u, p, guess


def _batch_shape(mech, shapes: dict[str, tuple]):
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        desc = ", ".join(f"{k}: {v}" for k, v in shapes.items())
        raise ValueError(f"{mech.name}: batch shapes do not broadcast ({desc})") from None


@functools.partial(jax.jit, static_argnums=(0, 1))
def _solve_flat(mech, options, u, p, guess):
    return jax.vmap(lambda u_, p_, g_: solve_one(mech, u_, p_, g_, options))(u, p, guess)


def solve(mech: Mechanism, u, p: Mapping, guess, *, options: SolverOptions = SolverOptions(), throw: bool = False) -> Solution:
    """Solve the loop closure for a batch of inputs and designs (jit-compiled, vmapped).

    **Arguments**

    - `u`: driven inputs; array ``(..., dof)`` (or the bare batch array for one input), or a
      dict ``{input_name: array}``.  Radians for angles, metres for lengths.
    - `p`: ``{param_name: scalar or array}``; arrays broadcast against the batch.
    - `guess`: ``(..., m)`` or ``{coord_name: array}``; picks the assembly branch.
    - `options`: ``SolverOptions``.
    - `throw`: raise ``RuntimeError`` if any sample did not converge (one bad sample raises
      for the whole batch).

    **Returns** a ``Solution`` whose fields have the broadcast batch shape in front;
    differentiable in ``u`` and ``p`` by the implicit function theorem.

    **Raises** ``ValueError`` for unknown names, bad values, shapes or dtypes (before tracing).
    """
    u, p, guess = _prepare(mech, u, p, guess, options)
    shape = _batch_shape(mech, {"u": u.shape[:-1], "guess": guess.shape[:-1], **{f"p[{k!r}]": v.shape for k, v in p.items()}})
    n = int(np.prod(shape, dtype=np.int64))
    uf = jnp.broadcast_to(u, shape + u.shape[-1:]).reshape(n, -1)
    gf = jnp.broadcast_to(guess, shape + guess.shape[-1:]).reshape(n, -1)
    pf = {k: jnp.broadcast_to(v, shape).reshape(n) for k, v in p.items()}
    sol = _solve_flat(mech, options, uf, pf, gf)
    sol = jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), sol)
    if throw:
        _raise_if_failed(sol)
    return sol


def _raise_if_failed(sol: Solution):
    from .status import status_counts

    status = np.asarray(sol.status)
    if np.any(status != Status.CONVERGED):
        bad = {k: v for k, v in status_counts(status).items() if k != "CONVERGED"}
        first = int(np.flatnonzero(status.ravel() != Status.CONVERGED)[0])
        from .status import status_message

        raise RuntimeError(
            f"{int(np.sum(status != Status.CONVERGED))} of {status.size} samples failed {bad}; "
            f"first at flat index {first}: {status_message(status.ravel()[first])}"
        )


# --------------------------------------------------------------------------- continuation
def _on_branch_value(b0, branch):
    """Whether a branch indicator value has the stroke's sign ``b0`` (0 or no indicator: any)."""
    return (b0 == 0) | ~jnp.isfinite(b0) | (jnp.sign(branch) == b0)


def _on_branch(mech: Mechanism, b0, q, u, p):
    """Whether ``q`` is on the assembly branch whose indicator sign is ``b0`` (0: any)."""
    if mech.branch is None:
        return jnp.asarray(True)
    return _on_branch_value(b0, mech.branch_value(q, u, p))


def _taylor(q, d1, d2, du):
    """Second-order Taylor step from a solved anchor: ``q + q' du + q'' du du / 2``."""
    return q + d1 @ du + 0.5 * jnp.einsum("ijk,j,k->i", d2, du, du)


def _trusted_terms(d1, d2, du, s, max_step):
    """``(d1, d2)`` with the terms the Taylor series cannot be trusted with over ``du`` zeroed.

    Near a singular position the series diverges (there ``q''`` is huge: a flap design
    that starts near a toggle had its second-order term predict 2000 rad, and Newton then
    converged to the same pose 319 turns away, where angle-dependent loads are wrong).  So
    the second-order term is kept only while it is under a quarter of the first-order one
    (scaled max norms: the series is then converging), and a step of more than ``max_step``
    (scaled, as Newton's) is not predicted at all: the anchor itself is the guess.
    """
    first = d1 @ du
    second = 0.5 * jnp.einsum("ijk,j,k->i", d2, du, du)
    size = lambda x: _small_max(jnp.abs(x) / s)  # noqa: E731
    keep2 = size(second) <= 0.25 * size(first)
    step = jnp.where(keep2, first + second, first)
    keep1 = size(step) <= max_step
    return jnp.where(keep1, d1, 0.0), jnp.where(keep1 & keep2, d2, 0.0)


def _predict(q, d1, d2, du, s, max_step):
    """The guarded predictor ``_taylor`` with ``_trusted_terms`` over ``du``."""
    return _taylor(q, *_trusted_terms(d1, d2, du, s, max_step), du)


def _anchor_step(n: int, n_anchors: int) -> int:
    """Stroke points per anchor for ``n`` points and (at most about) ``n_anchors`` anchors."""
    return max(1, -(-n // max(1, n_anchors)))


def _stroke_anchors(mech: Mechanism, options: SolverOptions, k: int, us, ps, guess):
    """Anchors of the strokes of D designs (``ps`` leaves ``(D,)``, ``guess (D, m)``), solved
    in sequence along ``us (N, dof)`` (no gradients).

    Anchors (every k-th input and the last) are solved by the robust Newton from the
    second-order predictor of the previous anchor, which keeps the branch.  (Trying plain
    Newton steps first, with the robust loop under a ``lax.cond``, cut the anchors' time
    by 30% for 1e3 designs but added ~2 s to every compile.)  Returns
    ``((q, dq/du, d2q/du2, u) at each anchor, each (D, A, ...)), b0 (D,))`` with ``b0`` the
    stroke's branch sign (its first guess's); ``_stroke_guesses`` turns them into a guess
    for any point.
    """
    n = us.shape[0]
    m, dof = mech.m, mech.dof
    d = guess.shape[0]
    idx = np.unique(np.concatenate([np.arange(0, n, k), [n - 1]]))
    ua = us[idx]
    # A large step can carry the predictor across the branch boundary, where Newton then
    # converges (per its own guess) on the other branch; so every anchor is checked against
    # the stroke's branch.
    if mech.branch is not None:
        b0 = jnp.sign(jax.vmap(lambda g_, p_: mech.branch_value(g_, us[0], p_))(guess, ps))
    else:
        b0 = jnp.zeros((d,), guess.dtype)
    on_branch = jax.vmap(lambda b_, q_, u_, p_: _on_branch(mech, b_, q_, u_, p_), (0, 0, None, 0))
    scales = jax.vmap(lambda p_: _coord_scales(mech, p_, guess.dtype))(ps)

    def scan_fn(carry, u_next):
        q, d1, d2, u_prev = carry
        g = jax.vmap(lambda *a: _predict(*a, options.max_step))(q, d1, d2, u_next - u_prev, scales)
        g = jnp.where(on_branch(b0, g, u_next, ps)[:, None], g, q)  # a predictor off the branch: fall back to q
        qn, status, *_ = jax.vmap(lambda p_, g_: _newton(mech, options, u_next, p_, g_))(ps, g)
        good = (status == Status.CONVERGED) & on_branch(b0, qn, u_next, ps)
        e1, e2 = jax.vmap(lambda q_, p_, g_: _derivatives_at(mech, q_, u_next, p_, g_))(jnp.where(good[:, None], qn, q), ps, good)
        # After a failure keep the last good anchor: later anchors restart from it.
        keep = lambda new, old: jnp.where(good.reshape((d,) + (1,) * (new.ndim - 1)), new, old)  # noqa: E731
        carry = (keep(qn, q), keep(e1, d1), keep(e2, d2), keep(jnp.broadcast_to(u_next, u_prev.shape), u_prev))
        return carry, carry

    # The first anchor is solved from the user's guess (zero derivatives: the predictor is
    # the guess itself); one traced Newton serves every anchor, which halves compile time.
    init = (guess, jnp.zeros((d, m, dof), guess.dtype), jnp.zeros((d, m, dof, dof), guess.dtype), jnp.broadcast_to(ua[0], (d, dof)))
    _, anchors = jax.lax.scan(scan_fn, init, ua)
    return tuple(jnp.moveaxis(x, 0, 1) for x in anchors), b0


def _stroke_guesses(anchors, k: int, us, s, max_step):
    """Guesses ``(N, m)`` for every point of a stroke from its nearest anchor, and that anchor's
    ``q`` (the fallback start).

    Point ``i`` belongs to anchor ``round(i / k)``: the stroke is padded by ``k // 2`` in
    front and cut into blocks of ``k``, block ``j`` centred on anchor ``j``, so the anchor
    data broadcast over a block (no per-point gather).  The guess is the anchor's
    second-order predictor, with the terms its series cannot be trusted with over the
    block dropped (``_trusted_terms``); its error is about ``|d3q/du3| h^3 / 6``
    at distance ``h``, so one Newton step from it reaches machine precision on a smooth
    stroke.  ``s``: the coordinate scales; ``max_step``: the largest predicted step.
    """
    qa, d1a, d2a, uaa = anchors
    n, na = us.shape[0], qa.shape[0]
    # Trust each anchor's series over the spacing to the next anchor: twice the farthest
    # point it guesses, a margin against uneven strokes.
    spacing = jnp.concatenate([jnp.abs(uaa[1:] - uaa[:-1]), jnp.abs(uaa[-1:] - uaa[-2:-1])], axis=0) if na > 1 else jnp.zeros_like(uaa)
    d1a, d2a = jax.vmap(lambda a_, b_, h_: _trusted_terms(a_, b_, h_, s, max_step))(d1a, d2a, spacing)
    shift = k // 2
    blocks = -(-(n + shift) // k)
    pad = blocks * k - n - shift
    u_blk = jnp.concatenate([jnp.broadcast_to(us[:1], (shift,) + us.shape[1:]), us, jnp.broadcast_to(us[-1:], (pad,) + us.shape[1:])])
    u_blk = u_blk.reshape((blocks, k) + us.shape[1:])
    j = np.minimum(np.arange(blocks), na - 1)
    g = jax.vmap(lambda q_, a_, b_, ua_, u_: jax.vmap(lambda uu: _taylor(q_, a_, b_, uu - ua_))(u_))(
        qa[j], d1a[j], d2a[j], uaa[j], u_blk
    )
    g = g.reshape((blocks * k,) + g.shape[2:])[shift : shift + n]
    q0 = jnp.broadcast_to(qa[j][:, None], (blocks, k) + qa.shape[1:]).reshape((blocks * k,) + qa.shape[1:])[shift : shift + n]
    return g, q0


@functools.partial(jax.jit, static_argnums=(0, 1, 2, 3, 4))
def _stroke_batch(mech, options, n_anchors, derivs, single, us, p, guess):
    """Strokes of D designs: ``p`` leaves ``(D,)``, ``guess (D, m)``; ``(D, N)`` fields
    (``(N,)`` fields with ``single``, D = 1).

    Every point is first solved by ``options.lean_steps`` plain Newton steps from its
    anchor's predictor (``_lean_newton``); only if some point of the whole batch fails that
    test is the robust damped Newton run (one batch-level ``lax.cond``, so a clean batch
    never pays for it).  With ``derivs``, ``dq/du`` and ``d2q/du2`` are computed in the same
    pass, at the fast path's last iterate, sharing its Jacobian's sines and cosines.

    Returns ``(Solution, d1, d2)`` (``d1``, ``d2`` None without ``derivs``; NaN where the
    status is not ``CONVERGED``).
    """
    stop = jax.lax.stop_gradient
    n = us.shape[0]
    # Non-finite inputs and parameters are replaced once, here, by harmless values (their
    # samples are flagged): every later evaluation then shares the same operands, and no
    # derivative code ever sees a NaN that could leak into a batch gradient.
    us_fin = jnp.all(jnp.isfinite(us), axis=-1)
    us_s = jnp.where(jnp.isfinite(us), us, 0.0)
    p_fin = jnp.ones(guess.shape[:1], bool)
    for v in p.values():
        p_fin = p_fin & jnp.isfinite(v)
    p_s = {k: jnp.where(jnp.isfinite(v), v, 1.0) for k, v in p.items()}
    ps = jax.tree_util.tree_map(stop, p_s)
    k = _anchor_step(n, n_anchors)
    anchors, b0 = _stroke_anchors(mech, options, k, us_s, ps, stop(guess))
    inputs_ok = p_fin[:, None] & us_fin[None, :] & jnp.all(jnp.isfinite(guess), axis=-1)[:, None]
    scales = jax.vmap(lambda p_: _coord_scales(mech, p_, guess.dtype))(ps)
    guesses, starts = jax.vmap(lambda a_, s_: _stroke_guesses(a_, k, us_s, s_, options.max_step))(anchors, scales)

    def per_point(fn, *args):
        """``fn(u, p, b0, *per-point args)`` over designs (outer) and stroke points (inner)."""
        return jax.vmap(lambda p_, b_, *pts: jax.vmap(lambda u_, *pp: fn(u_, p_, b_, *pp))(us_s, *pts))(*args)

    def lean(u, p_, b_, g):
        return _lean_newton(mech, options, options.lean_steps, u, p_, g, b_)

    def robust(u, p_, b_, g, q0):
        g = jnp.where(_on_branch(mech, b_, g, u, p_), g, q0)  # a predictor off the branch: start at the anchor
        return _newton(mech, options, u, p_, g)

    def derivatives(q, ok):
        if not derivs:
            return None, None
        # q is attached to (u, p) by the implicit function theorem at q itself, so these
        # derivatives differentiate again correctly in u and p.
        fn = lambda u_, p_, b_, q_, ok_: _derivatives_at(mech, implicit_root(mech, q_, ok_, u_, p_), u_, p_, ok_)  # noqa: E731
        return per_point(fn, p_s, b0, q, ok)

    qc, qf, ok, rn, cond, br = per_point(lean, ps, b0, guesses)
    ok = ok & inputs_ok
    d1, d2 = derivatives(qc, ok)
    status = jnp.where(ok, Status.CONVERGED, Status.MAX_STEPS).astype(jnp.int32)
    steps = jnp.full(ok.shape, options.lean_steps, jnp.int32)

    def finish(fields):
        """NaN where not converged; attach the roots to (u, p); drop the design axis if single."""
        qf, status, steps, rn, cond, br, d1, d2 = fields
        ok = status == Status.CONVERGED
        q_star = jnp.where(ok[..., None], qf, jnp.nan)
        q = per_point(lambda u_, p_, b_, q_, ok_: implicit_root(mech, q_, ok_, u_, p_), p, b0, q_star, ok)
        if derivs:
            d1 = jnp.where(ok[..., None, None], d1, jnp.nan)
            d2 = jnp.where(ok[..., None, None, None], d2, jnp.nan)
        out = (q, status, steps, rn, cond, br, d1, d2)
        return jax.tree_util.tree_map(lambda x: x[0], out) if single else out

    def fallback(fields):
        lean_ok = fields[1] == Status.CONVERGED
        q_r, st_r, k_r, rn_r, cond_r, br_r = per_point(robust, ps, b0, guesses, starts)
        st_r = jnp.where(inputs_ok, st_r, Status.NONFINITE)
        # Converged, but on another branch than the stroke's: BRANCH, positions NaN.
        flipped = (st_r == Status.CONVERGED) & ~_on_branch_value(b0[:, None], br_r)
        st_r = jnp.where(flipped, Status.BRANCH, st_r)
        ok_r = st_r == Status.CONVERGED
        q_r = jnp.where(ok_r[..., None], q_r, jnp.zeros_like(q_r))
        e1, e2 = derivatives(q_r, ok_r)
        new = (q_r, st_r.astype(jnp.int32), jnp.asarray(k_r, jnp.int32), rn_r, cond_r, br_r, e1, e2)

        def pick(a, b):
            return None if a is None else jnp.where(lean_ok.reshape(lean_ok.shape + (1,) * (a.ndim - 2)), a, b)

        return finish(tuple(pick(a, b) for a, b in zip(fields, new)))

    fields = (qf, status, steps, rn, cond, br, d1, d2)
    q, status, steps, rn, cond, br, d1, d2 = jax.lax.cond(jnp.any(~ok), fallback, finish, fields)
    sol = Solution(q=q, status=status, steps=steps, residual=rn, cond=cond, branch=br, coords=mech.coords)
    return sol, d1, d2


def _stroke(mech: Mechanism, us, p: Mapping, guess, options: SolverOptions, anchors: int, derivs: bool):
    """Checks and broadcasting shared by ``solve_stroke`` and ``stroke_kinematics``."""
    us_, p, guess = _prepare(mech, us, p, guess, options, u_what="us")
    if us_.ndim != 2:
        raise ValueError(f"{mech.name}: us must be one stroke of shape (N,) or (N, {mech.dof}), got {jnp.shape(us)}")
    shapes = {f"p[{k!r}]": v.shape for k, v in p.items()}
    shapes["guess"] = guess.shape[:-1]
    shape = _batch_shape(mech, shapes)
    if len(shape) > 1:
        raise ValueError(f"{mech.name}: solve_stroke takes one batch axis of designs, got batch shape {shape}")
    single = shape == ()
    d = 1 if single else shape[0]
    pf = {k: jnp.broadcast_to(v, (d,)) for k, v in p.items()}
    gf = jnp.broadcast_to(guess, (d, mech.m))
    return _stroke_batch(mech, options, int(anchors), bool(derivs), single, us_, pf, gf)


def solve_stroke(mech: Mechanism, us, p: Mapping, guess, *, options: SolverOptions = SolverOptions(), anchors: int = 256, throw: bool = False) -> Solution:
    """Solve a whole stroke by continuation, for one design or a batch of designs.

    **Arguments**

    - `us`: the stroke, ``(N,)`` for one input or ``(N, dof)``, in order along the path.
    - `p`: parameters; scalar leaves for one design, or leaves of shape ``(D,)`` for D designs.
    - `guess`: coordinates at ``us[0]``, ``(m,)`` or ``(D, m)``: it picks the branch, which
      continuation then keeps (``BRANCH`` status if a branch indicator changes sign).
    - `anchors`: how many inputs are solved in sequence; the rest are solved in parallel
      from the nearest anchor's predictor.  More anchors: safer near toggles, slower.

    **Returns** a ``Solution`` with shape ``(N, ...)`` for one design, ``(D, N, ...)`` for D.
    """
    sol, _, _ = _stroke(mech, us, p, guess, options, anchors, derivs=False)
    if throw:
        _raise_if_failed(sol)
    return sol
