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

from .mechanism import Mechanism
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
    - `lean_steps`: plain Newton steps tried first for stroke points (from their anchor's
      predictor) before the robust loop; points that fail its tests get the robust loop.
    - `dtype`: require this floating dtype (``"float64"`` raises if x64 is off or an
      argument is float32); ``None`` follows the arguments.
    """

    max_steps: int = 80
    xtol: float | None = None
    ftol: float | None = None
    cond_max: float | None = None
    max_step: float = 1.0
    patience: int = 8
    lean_steps: int = 2
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
def _solve_small(a, b):
    """Solve ``a x = b`` for one small dense system; explicit for 1x1 and 2x2 (fast under vmap)."""
    n = a.shape[-1]
    if n == 1:
        return b / a[0, 0]
    if n == 2:
        det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
        x0 = (a[1, 1] * b[0] - a[0, 1] * b[1]) / det
        x1 = (a[0, 0] * b[1] - a[1, 0] * b[0]) / det
        return jnp.stack([x0, x1])
    return jnp.linalg.solve(a, b)


def _inv_small(a):
    n = a.shape[-1]
    if n <= 2:
        return jax.vmap(lambda e: _solve_small(a, e), out_axes=1)(jnp.eye(n, dtype=a.dtype))
    return jnp.linalg.inv(a)


def _cond1(a):
    """1-norm condition number of a small square matrix (inf where singular)."""
    norm1 = lambda m: jnp.max(jnp.sum(jnp.abs(m), axis=0))  # noqa: E731
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
def _scaled_residual(mech: Mechanism, u, p, dtype):
    """``q -> (Phi/R, d(Phi/R)/dz)`` with ``z = q / s``, and the coordinate scales ``s``.

    ``s`` is 1 for angles and the design's length scale for lengths; ``R`` is the residual
    scale (the length scale for loop closures).  Both make tolerances unit-independent.
    """
    L = mech.length_scale(p).astype(dtype)
    R = mech.residual_scales(p, dtype)
    s = jnp.where(jnp.asarray(mech.coord_is_length()), L, jnp.ones((), dtype))

    def evaluate(q):
        def f(q_):
            r = mech.residual(q_, u, p) / R
            return r, r

        j, r = jax.jacfwd(f, has_aux=True)(q)
        return r, j * s[None, :]

    return evaluate, s


def _lean_newton(mech: Mechanism, opts: SolverOptions, iters: int, u, p, guess):
    """A fixed number of plain Newton steps from a close guess, then the same convergence,
    conditioning and finiteness tests as ``_newton``.  No loop control, no damping: the fast
    path for stroke points predicted from a solved anchor.  Returns ``(q, ok, rn, cond)``;
    samples with ``ok`` False are re-solved by ``_newton``.
    """
    dtype = guess.dtype
    xtol, ftol, cond_max = _tolerances(opts, dtype)
    evaluate, s = _scaled_residual(mech, u, p, dtype)
    q = guess
    for _ in range(iters):
        r, js = evaluate(q)
        q = q - _solve_small(js, r) * s
    r, js = evaluate(q)
    dz = _solve_small(js, r)
    rn = jnp.linalg.norm(r)
    cond = _cond1(js)
    ok = (jnp.max(jnp.abs(dz)) <= xtol) & (rn <= ftol) & (cond <= cond_max) & jnp.all(jnp.isfinite(dz))
    return q - dz * s, ok & _all_finite((u, p, guess)), rn, cond


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
def _tangent(mech, q, u, p):
    """``dq/du`` (m x dof) at a solution: ``-Phi_q^{-1} Phi_u``."""
    jq = jax.jacfwd(mech.residual, 0)(q, u, p)
    ju = jax.jacfwd(mech.residual, 1)(q, u, p)
    return jax.vmap(lambda c: -_solve_small(jq, c), in_axes=1, out_axes=1)(ju)


def _on_branch(mech: Mechanism, b0, q, u, p):
    """Whether ``q`` is on the assembly branch whose indicator sign is ``b0`` (0: any)."""
    if mech.branch is None:
        return jnp.asarray(True)
    return (b0 == 0) | (jnp.sign(mech.branch_value(q, u, p)) == b0)


def _stroke_guesses(mech: Mechanism, options: SolverOptions, n_anchors: int, us, p, guess):
    """Guesses for every input of one stroke ``us (N, dof)`` of one design (no gradients).

    Anchors (every k-th input and the last) are solved in sequence by the robust Newton, each
    guessed by the first-order predictor ``q + dq/du du`` from the previous anchor, which
    keeps the branch.  Every input's guess is the predictor of its nearest anchor.  Returns
    ``(guesses (N, m), b0)`` with ``b0`` the stroke's branch sign (its first guess's).
    """
    n = us.shape[0]
    k = max(1, -(-n // n_anchors))
    idx = np.unique(np.concatenate([np.arange(0, n, k), [n - 1]]))
    ua = us[idx]
    # A large step can carry the predictor across the branch boundary, where Newton then
    # converges (per its own guess) on the other branch; so every anchor is checked against
    # the stroke's branch.
    b0 = jnp.sign(mech.branch_value(guess, us[0], p)) if mech.branch is not None else jnp.zeros((), guess.dtype)

    def predict(q, t, u_from, u_to):
        return q + t @ (u_to - u_from)

    def scan_fn(carry, u_next):
        q, t, u_prev = carry
        g = predict(q, t, u_prev, u_next)
        g = jnp.where(_on_branch(mech, b0, g, u_next, p), g, q)  # a predictor off the branch: fall back to q
        qn, status, *_ = _newton(mech, options, u_next, p, g)
        good = (status == Status.CONVERGED) & _on_branch(mech, b0, qn, u_next, p)
        tn = _tangent(mech, jnp.where(good, qn, q), u_next, p)
        tn = jnp.where(good & jnp.all(jnp.isfinite(tn)), tn, t)
        # After a failure keep the last good anchor: later anchors restart from it.
        carry = (jnp.where(good, qn, q), tn, jnp.where(good, u_next, u_prev))
        return carry, carry

    # The first anchor is solved from the user's guess (zero tangent: the predictor is the
    # guess itself); one traced Newton serves every anchor, which halves compile time.
    t_init = jnp.zeros((mech.m, mech.dof), guess.dtype)
    _, (qa, ta, uaa) = jax.lax.scan(scan_fn, (guess, t_init, ua[0]), ua)
    nearest = np.clip(np.round(np.arange(n) / k).astype(int), 0, len(idx) - 1)
    guesses = jax.vmap(predict)(qa[nearest], ta[nearest], uaa[nearest], us)
    on = jax.vmap(lambda g_, u_: _on_branch(mech, b0, g_, u_, p))(guesses, us)
    return jnp.where(on[:, None], guesses, qa[nearest]), b0


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _stroke_batch(mech, options, n_anchors, us, p, guess):
    """Strokes of D designs: ``p`` leaves ``(D,)``, ``guess (D, m)``; returns ``(D, N)`` fields.

    Every point is first solved by a few plain Newton steps from its anchor's predictor
    (``_lean_newton``); only if some point of the whole batch fails that test is the robust
    damped Newton run (one batch-level ``lax.cond``, so a clean batch never pays for it).
    """
    stop = jax.lax.stop_gradient
    ps = jax.tree_util.tree_map(stop, p)
    guesses, b0 = jax.vmap(lambda p_, g_: _stroke_guesses(mech, options, n_anchors, us, p_, g_))(ps, stop(guess))
    per_point = lambda fn: jax.vmap(lambda p_, g_: jax.vmap(lambda u_, gg: fn(u_, p_, gg))(us, g_))  # noqa: E731
    ql, okl, rnl, condl = per_point(lambda u_, p_, g_: _lean_newton(mech, options, options.lean_steps, u_, p_, g_))(ps, guesses)
    branch_of = per_point(lambda u_, p_, q_: mech.branch_value(q_, u_, p_))
    on_branch = jax.vmap(lambda b_, p_, q_: jax.vmap(lambda u_, qq: _on_branch(mech, b_, qq, u_, p_))(us, q_))
    okl = okl & on_branch(b0, ps, ql)

    def robust(_):
        q, st, k, rn, cond, br = per_point(lambda u_, p_, g_: _newton(mech, options, u_, p_, g_))(ps, guesses)
        return q, st.astype(jnp.int32), jnp.asarray(k, jnp.int32), rn, cond, br

    def lean_only(_):
        return (ql, jnp.full(okl.shape, Status.CONVERGED, jnp.int32), jnp.full(okl.shape, options.lean_steps, jnp.int32),
                rnl, condl, branch_of(ps, ql))

    qr, st, steps, rn, cond, br = jax.lax.cond(jnp.any(~okl), robust, lean_only, None)
    lean_br = branch_of(ps, ql)
    q_raw = jnp.where(okl[..., None], ql, qr)
    status = jnp.where(okl, Status.CONVERGED, st)
    steps = jnp.where(okl, options.lean_steps, steps)
    rn, cond, br = (jnp.where(okl, a, b) for a, b in ((rnl, rn), (condl, cond), (lean_br, br)))
    # Converged, but on another branch than the stroke's: BRANCH, positions NaN.
    flipped = (status == Status.CONVERGED) & ~on_branch(b0, ps, q_raw)
    status = jnp.where(flipped, Status.BRANCH, status).astype(jnp.int32)
    ok = status == Status.CONVERGED
    q_star = jnp.where(ok[..., None], q_raw, jnp.nan)
    q = jax.vmap(lambda qs, ok_, p_: jax.vmap(lambda qq, oo, u_: implicit_root(mech, qq, oo, u_, p_))(qs, ok_, us))(q_star, ok, p)
    return Solution(q=q, status=status, steps=steps, residual=rn, cond=cond, branch=br, coords=mech.coords)


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
    sol = _stroke_batch(mech, options, int(anchors), us_, pf, gf)
    if single:
        sol = jax.tree_util.tree_map(lambda x: x[0], sol)
    if throw:
        _raise_if_failed(sol)
    return sol
