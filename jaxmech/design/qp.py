"""Small dense convex quadratic programs by Mehrotra's predictor-corrector, in JAX (vmappable).

    min  1/2 d' H d + g' d    s.t.   E d + e = 0   (p rows),   A d + b <= 0   (m rows)

``H`` positive semidefinite, with ``H + A' D A`` positive definite for every positive diagonal
``D`` (so a variable that appears only linearly, like an epigraph variable, is fine when an
inequality bounds it).  With slacks ``A d + b + s = 0, s >= 0`` and multipliers ``y``,
``z >= 0``, each iteration solves the condensed Newton system

    [ H + A' (Z/S) A   E' ] [dd]   [ -r_d - A' S^-1 (Z r_i - r_c) ]
    [ E                0  ] [dy] = [ -r_e                         ]

twice with one factorisation: an affine step, then a centred and corrected one (centring
``sigma = (mu_aff / mu)^3``).  Primal and dual take one step length (fraction to the
boundary 0.99), which keeps the dual residual of a QP exact along the step.  The sizes are
those of a design's step (``n`` up to a few tens): the system is solved by Gaussian
elimination with partial pivoting written in JAX (``linalg.solve_small``: no LAPACK call).

This is the inner solver of ``design.sqp``; it is not a general QP code (no presolve, no
infeasibility certificate: an infeasible or unbounded QP ends with ``ok`` False).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.linalg import solve_small, where

__all__ = ["solve_qp"]


class QPSolution(NamedTuple):
    """``d`` the minimiser, ``y`` ``z`` the equality and inequality multipliers (``z >= 0``),
    ``iterations``, ``ok`` (converged to the tolerance, everything finite)."""

    d: jax.Array
    y: jax.Array
    z: jax.Array
    iterations: jax.Array
    ok: jax.Array


class _QPState(NamedTuple):
    k: jax.Array
    d: jax.Array
    y: jax.Array
    z: jax.Array
    s: jax.Array
    err: jax.Array  # largest scaled residual or complementarity product
    best: tuple  # (err, d, y, z) of the best iterate so far


def _residuals(H, g, E, e, A, b, st: _QPState):
    r_d = H @ st.d + g + E.T @ st.y + A.T @ st.z
    return r_d, E @ st.d + e, A @ st.d + b + st.s


class _Direction(NamedTuple):
    dd: jax.Array
    dy: jax.Array
    dz: jax.Array
    ds: jax.Array


def _direction(H, E, A, st: _QPState, r_d, r_e, r_i, r_c) -> _Direction:
    """The Newton system's step for the complementarity target ``r_c``."""
    n, p = H.shape[0], E.shape[0]
    sig = st.z / st.s
    K = H + (A.T * sig[None, :]) @ A
    kkt = jnp.block([[K, E.T], [E, jnp.zeros((p, p), H.dtype)]]) if p else K
    rhs = -r_d - A.T @ ((st.z * r_i - r_c) / st.s)
    full = jnp.concatenate([rhs, -r_e]) if p else rhs
    sol = solve_small(kkt, full)
    sol = sol + solve_small(kkt, full - kkt @ sol)  # one refinement: K's entries span many decades near the end
    dd, dy = sol[:n], sol[n:]
    ds = -r_i - A @ dd
    dz = (-r_c - st.z * ds) / st.s
    return _Direction(dd, dy, dz, ds)


def _to_boundary(v, dv, tau):
    ratio = jnp.where(dv < 0, -tau * v / jnp.where(dv < 0, dv, -1.0), jnp.inf)
    return jnp.minimum(1.0, jnp.min(ratio, initial=jnp.inf))


def _error(H, g, E, e, A, b, st: _QPState, scale):
    r_d, r_e, r_i = _residuals(H, g, E, e, A, b, st)
    res = jnp.maximum(jnp.max(jnp.abs(r_d)), jnp.maximum(jnp.max(jnp.abs(r_e), initial=0.0), jnp.max(jnp.abs(r_i), initial=0.0)))
    return jnp.maximum(res, jnp.max(st.s * st.z, initial=0.0)) / scale


def solve_qp(H, g, E, e, A, b, *, tol: float = 1e-10, ok_tol: float = 1e-9, max_iter: int = 40) -> QPSolution:
    """Solve the convex QP of the module docstring for one problem (vmap it for a batch).

    The error of an iterate is its largest residual or complementarity product relative to
    the data's size; the loop ends when it is at most `tol` or after `max_iter` iterations,
    and returns the best iterate met (on a degenerate QP, a vertex with a weakly active
    constraint, the condensed system's conditioning can spoil later iterates), ``ok`` when
    its error is at most `ok_tol`."""
    n, m, p = H.shape[0], A.shape[0], E.shape[0]
    dtype = H.dtype
    scale = 1.0 + jnp.maximum(jnp.max(jnp.abs(g), initial=0.0), jnp.maximum(jnp.max(jnp.abs(e), initial=0.0), jnp.max(jnp.abs(b), initial=0.0)))
    # slacks from the constraints at d = 0 (exact where they hold with room), unit multipliers
    z0 = jnp.ones((m,), dtype)
    d0, y0 = jnp.zeros((n,), dtype), jnp.zeros((p,), dtype)
    st0 = _QPState(jnp.zeros((), jnp.int32), d0, y0, z0, jnp.maximum(-b, 1.0), jnp.asarray(jnp.inf, dtype), (jnp.asarray(jnp.inf, dtype), d0, y0, z0))
    st0 = st0._replace(err=_error(H, g, E, e, A, b, st0, scale))

    def body(st: _QPState) -> _QPState:
        r_d, r_e, r_i = _residuals(H, g, E, e, A, b, st)
        mu = jnp.sum(st.s * st.z) / max(m, 1)
        # predictor (affine scaling)
        dd, dy, dz, ds = _direction(H, E, A, st, r_d, r_e, r_i, st.s * st.z)
        a_aff = jnp.minimum(_to_boundary(st.s, ds, 1.0), _to_boundary(st.z, dz, 1.0))
        mu_aff = jnp.sum((st.s + a_aff * ds) * (st.z + a_aff * dz)) / max(m, 1)
        sigma = (mu_aff / jnp.maximum(mu, 1e-300)) ** 3
        # corrector: centring and the affine step's second-order term
        dd, dy, dz, ds = _direction(H, E, A, st, r_d, r_e, r_i, st.s * st.z + ds * dz - sigma * mu)
        a = 0.99 * jnp.minimum(_to_boundary(st.s, ds, 1.0), _to_boundary(st.z, dz, 1.0))
        new = st._replace(k=st.k + 1, d=st.d + a * dd, y=st.y + a * dy, z=st.z + a * dz, s=st.s + a * ds)
        err = _error(H, g, E, e, A, b, new, scale)
        err = jnp.where(jnp.isfinite(err), err, jnp.inf)
        better = err < st.best[0]
        best = jax.tree_util.tree_map(lambda x, y: where(better, x, y), (err, new.d, new.y, new.z), st.best)
        return new._replace(err=err, best=best)

    st0 = st0._replace(best=(st0.err, d0, y0, z0))
    st = jax.lax.while_loop(lambda st: (st.err > tol) & (st.k < max_iter), body, st0)
    err, d, y, z = st.best
    ip = QPSolution(d, y, z, st.k, err <= ok_tol)
    return polish(H, g, E, e, A, b, ip, -(A @ d + b), scale, ok_tol)


def _largest(x, k: int):
    """``(values, indices)`` of the ``k`` largest entries of ``x (m,)``, largest first (ties
    by index), by ranks and reductions: ``lax.top_k``'s sort made the executables that hold
    it fail to serialise (jaxlib 0.10: "`LessThan` is not serializable"), so never stored."""
    i = jnp.arange(x.shape[0])
    ahead = (x[None, :] > x[:, None]) | ((x[None, :] == x[:, None]) & (i[None, :] < i[:, None]))
    rank = jnp.sum(ahead, axis=1)
    idx = jnp.argmax(rank[None, :] == jnp.arange(k)[:, None], axis=1)
    return x[idx], idx


def polish(H, g, E, e, A, b, ip: QPSolution, s, scale, ok_tol: float) -> QPSolution:
    """The interior point's answer made exact: the constraints it finds active (multiplier
    above slack), at most ``n`` of them, solved as equalities with the equalities
    (one ``n + p + k`` KKT system), kept where that point is feasible and its multipliers
    are nonnegative (to ``ok_tol`` of the data's size), else the interior point's answer.

    An interior point stops a little inside the bounds it should touch (its complementarity
    products near ``tol``); an SQP step that is off by that much is no longer a descent
    direction once the iterate is at round-off from the optimum."""
    n, p, m = H.shape[0], E.shape[0], A.shape[0]
    k = min(n, m)
    if k == 0:
        return ip
    score = ip.z / jnp.maximum(ip.z + jnp.maximum(s, 0.0), 1e-300)
    top, idx = _largest(score, k)
    on = top > 0.5
    a_s = A[idx] * on[:, None]
    dtype = H.dtype
    kkt = jnp.block([[H, E.T, a_s.T], [E, jnp.zeros((p, p + k), dtype)], [a_s, jnp.zeros((k, p), dtype), jnp.diag(jnp.where(on, 0.0, 1.0))]])
    sol = solve_small(kkt, jnp.concatenate([-g, -e, jnp.where(on, -b[idx], 0.0)]))
    d, y, lam = sol[:n], sol[n:n + p], sol[n + p:]
    z = jnp.zeros((m,), dtype).at[idx].set(jnp.where(on, lam, 0.0))
    good = (jnp.all(jnp.isfinite(sol)) & (jnp.min(z, initial=0.0) >= -ok_tol * scale)
            & (jnp.max(A @ d + b, initial=0.0) <= ok_tol * scale) & (jnp.max(jnp.abs(E @ d + e), initial=0.0) <= ok_tol * scale))
    pick = lambda a, b_: where(good, a, b_)  # noqa: E731
    return QPSolution(pick(d, ip.d), pick(y, ip.y), pick(jnp.maximum(z, 0.0), ip.z), ip.iterations, ip.ok | good)
