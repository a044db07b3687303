"""The batched least squares of four-bar path synthesis (``jaxmech.design.synthesis``):
residuals and exact Jacobians of every (start, target) pair from one compiled JAX program,
Levenberg-Marquardt steps in numpy with the crank angles eliminated (a Schur complement),
feasible steps only; successive halving and basin hopping over a pool of starts; MINPACK's
polish of one start.  Designs are normalised: ``x = (x0, y0, phi, log a, log b, log c,
log d, px, py)`` in a frame where the targets' centroid is 0 and their rms radius 1.
"""

from __future__ import annotations

import functools
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.xla import jit
from .coupler_path import TAU, crank_interval, local_point

__all__ = ["CHUNK", "Pool", "Problem", "basin_hopping", "closest_angles", "evaluator", "feasible", "polish",
           "reassigned", "successive_halving"]

# =========================================================================== least squares
CHUNK = 1024  #: (start, target) pairs per call of the compiled evaluator: one program for every problem


def point_real(x, th, mode):
    """Normalised design ``x = (x0, y0, phi, log a, log b, log c, log d, px, py)``: coupler point
    ``(2,)`` at crank angle ``th`` from the ground line, and ``s2`` (``local_point``).  Real
    arithmetic (XLA compiles it faster than the complex form)."""
    a, b, c, d = jnp.exp(x[3]), jnp.exp(x[4]), jnp.exp(x[5]), jnp.exp(x[6])
    ca, sa = jnp.cos(th), jnp.sin(th)
    ax, ay = a * ca, a * sa
    ux, uy = d - ax, -ay
    r2 = ux * ux + uy * uy
    r = jnp.sqrt(r2)
    cg = (b * b + r2 - c * c) / (2.0 * b * r)
    s2 = 1.0 - cg * cg
    sg = mode * jnp.sqrt(jnp.where(s2 > 0, s2, 1.0))
    ex, ey = (ux * cg - uy * sg) / r, (ux * sg + uy * cg) / r  # unit vector A -> B
    lx, ly = ax + x[7] * ex - x[8] * ey, ay + x[7] * ey + x[8] * ex
    cp, sp = jnp.cos(x[2]), jnp.sin(x[2])
    return jnp.stack([x[0] + cp * lx - sp * ly, x[1] + sp * lx + cp * ly]), s2


@functools.cache
def evaluator():
    """``(x (M, 9), th (M,), mode (M,), target (M, 2)) -> (r (M, 2), dr/dx (M, 2, 9), dr/dth
    (M, 2), s2 (M,))`` for ``M = CHUNK`` pairs, compiled once (forward mode)."""

    def one(x, th, mode, tg):
        P, s2 = point_real(x, th, mode)
        return P - tg, s2

    def with_jac(x, th, mode, tg):
        def res(xx, tt):
            r, s2 = one(xx, tt, mode, tg)
            return r, (r, s2)

        (gx, gt), (r, s2) = jax.jacfwd(res, argnums=(0, 1), has_aux=True)(x, th)
        return r, gx, gt, s2

    prog = jit(jax.vmap(with_jac))
    z = jnp.zeros
    t0 = time.perf_counter()
    with jax.enable_x64(True):
        compiled = prog.lower(z((CHUNK, 9)), z(CHUNK), z(CHUNK), z((CHUNK, 2))).compile()
    return compiled, time.perf_counter() - t0


class PairEvaluation(NamedTuple):
    """Residuals and Jacobians of (start, target) pairs (``evaluate_pairs``): the coupler point
    minus the target `r` ``(K, n, 2)``, its derivatives `gx` ``(K, n, 2, 9)`` in the design
    and `gt` ``(K, n, 2)`` in the crank angle, and `s2` ``(K, n)`` (``local_point``'s
    ``sin^2`` of the coupler-rocker angle: <= 0 where the loop does not close)."""

    r: np.ndarray
    gx: np.ndarray
    gt: np.ndarray
    s2: np.ndarray


class LMResult(NamedTuple):
    """Where the batched Levenberg-Marquardt stopped (``levenberg_marquardt``): designs
    `x`, crank angles `th`, `cost` ``(K,)`` (inf: infeasible from the beginning), the
    `iterations` ``(K,)`` taken and the damping `lam` ``(K,)`` to continue from."""

    x: np.ndarray
    th: np.ndarray
    cost: np.ndarray
    iterations: np.ndarray
    lam: np.ndarray


def evaluate_pairs(x, th, mode, tg) -> PairEvaluation:
    """Residuals and Jacobians of every (start, target) pair: ``x (K, 9)``, ``th (K, n)``,
    ``mode (K,)``, ``tg (n, 2)`` -> ``r (K, n, 2), gx (K, n, 2, 9), gt (K, n, 2), s2 (K, n)``."""
    k, n = th.shape
    m = k * n
    xs = np.repeat(x, n, axis=0)
    ths = th.reshape(-1)
    ms = np.repeat(mode, n)
    tgs = np.tile(tg, (k, 1))
    pad = (-m) % CHUNK
    if pad:
        xs = np.concatenate([xs, np.repeat(xs[-1:], pad, axis=0)])
        ths, ms = np.concatenate([ths, np.repeat(ths[-1:], pad)]), np.concatenate([ms, np.repeat(ms[-1:], pad)])
        tgs = np.concatenate([tgs, np.repeat(tgs[-1:], pad, axis=0)])
    prog, _ = evaluator()
    outs = []
    with jax.enable_x64(True):
        for i in range(0, m + pad, CHUNK):
            sl = slice(i, i + CHUNK)
            outs.append(prog(xs[sl], ths[sl], ms[sl], tgs[sl]))
        outs = [np.concatenate([np.asarray(o[j]) for o in outs])[:m] for j in range(4)]
    r, gx, gt, s2 = outs
    return PairEvaluation(r.reshape(k, n, 2), gx.reshape(k, n, 2, 9), gt.reshape(k, n, 2), s2.reshape(k, n))


def feasible(x, theta, s2, curve, ordered, timed, max_size, cmu):
    """Exact feasibility of normalised designs ``x (K, 9)`` at target crank angles ``theta
    (K, n)`` (from the ground line, unwrapped): the module docstring's rules; lengths, the
    coupler point's offset and both ground pivots within `max_size` (targets' rms radii) of
    the targets' centroid (the origin here)."""
    a, b, c, d = (np.exp(x[:, i]) for i in range(3, 7))
    lengths = np.stack([a, b, c, d], axis=1)
    with np.errstate(all="ignore"):
        ok = np.all(s2 > 1e-14, axis=1) & np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(theta), axis=1)
        ok &= np.all(lengths < max_size, axis=1) & np.all(lengths > 1e-4, axis=1)
        o4 = x[:, 0] + 1j * x[:, 1] + d * np.exp(1j * x[:, 2])
        ok &= (np.hypot(x[:, 0], x[:, 1]) < max_size) & (np.abs(o4) < max_size) & (np.hypot(x[:, 7], x[:, 8]) < max_size)
        full, center, half, two, closes = crank_interval(a, b, c, d, cmu)
        if curve in ("closed", "partial"):
            ok &= full
        else:
            ctr = np.where(two & (np.sin(theta[:, 0]) < 0), -center, center)
            k0 = np.round((theta[:, 0] - ctr) / TAU)
            inside = np.all(np.abs(theta - (ctr + TAU * k0)[:, None]) < half[:, None], axis=1)
            ok &= full | (closes & inside)
        if ordered and not timed:
            dt = np.diff(theta, axis=1)
            ok &= (np.all(dt >= 0, axis=1) | np.all(dt <= 0, axis=1)) & (np.abs(theta[:, -1] - theta[:, 0]) < TAU)
    return ok


def levenberg_marquardt(x, th, mode, tg, alpha, curve, ordered, max_size, cmu, iterations, lam=None) -> LMResult:
    """Every start at once (numpy over the batch; the compiled evaluator for residuals and
    exact Jacobians).  Returns an ``LMResult``; ``cost = inf`` for a start that was
    infeasible from the beginning."""
    timed = alpha is not None
    k, n = th.shape

    def angles(x, th):
        return alpha[None, :] - x[:, 2:3] if timed else th

    def evaluate(x, th, mode):
        theta = angles(x, th)
        r, gx, gt, s2 = evaluate_pairs(x, theta, mode, tg)
        if timed:  # theta = alpha - phi
            gx = gx.copy()
            gx[..., 2] -= gt
        cost = np.sum(r * r, axis=(1, 2))
        ok = feasible(x, theta, s2, curve, ordered, timed, max_size, cmu) & np.isfinite(cost)
        return r, gx, gt, cost, ok

    r, gx, gt, cost, ok = evaluate(x, th, mode)
    cost = np.where(ok, cost, np.inf)
    lam = np.full(k, 1e-3) if lam is None else lam.copy()
    active = ok.copy()
    its = np.zeros(k, int)
    eye = np.eye(9)
    for _ in range(iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        ra, gxa, gta, la = r[idx], gx[idx], gt[idx], lam[idx]
        G = gxa.reshape(idx.size, 2 * n, 9)
        Gt = G.transpose(0, 2, 1)
        A = Gt @ G
        gdx = (Gt @ ra.reshape(idx.size, 2 * n, 1))[..., 0]
        damp = la[:, None, None] * eye * np.maximum(np.diagonal(A, axis1=1, axis2=2), 1e-12)[:, None, :]
        if timed:
            dx = np.linalg.solve(A + damp, -gdx[..., None])[..., 0]
            dth = np.zeros((idx.size, n))
        else:
            B = gxa[:, :, 0, :] * gta[:, :, 0:1] + gxa[:, :, 1, :] * gta[:, :, 1:2]  # (k, n, 9)
            D = np.sum(gta * gta, axis=2)
            gdt = np.sum(gta * ra, axis=2)
            Dl = D + la[:, None] * np.maximum(D, 1e-12)
            Bt = B.transpose(0, 2, 1)
            S = A + damp - Bt @ (B / Dl[..., None])
            rhs = -gdx + (Bt @ (gdt / Dl)[..., None])[..., 0]
            dx = np.linalg.solve(S, rhs[..., None])[..., 0]
            dth = (-gdt - (B @ dx[..., None])[..., 0]) / Dl
        xn, thn = x[idx] + dx, th[idx] + dth
        rn, gxn, gtn, costn, okn = evaluate(xn, thn, mode[idx])
        take = okn & (costn < cost[idx])
        small = take & (cost[idx] - costn <= 1e-10 * cost[idx])
        its[idx] += 1
        t = idx[take]
        x[t], th[t], r[t], gx[t], gt[t], cost[t] = xn[take], thn[take], rn[take], gxn[take], gtn[take], costn[take]
        lam[idx] = np.where(take, np.maximum(la * 0.3, 1e-15), la * 8.0)
        stop = small | (lam[idx] > 1e14) | (cost[idx] <= 1e-28 * n)
        active[idx[stop]] = False
    return LMResult(x, th, cost, its, lam)


def polish(x, th, mode, tg, alpha, curve, ordered, max_size, cmu):
    """One start to full precision: ``scipy.optimize.least_squares`` (MINPACK's Levenberg-Marquardt, QR of the
    exact Jacobian; the batched solver above forms normal equations, which square the
    condition number of an ill-conditioned problem such as a short arc).  Kept only if the
    result is feasible and better: ``(x, th, cost)``."""
    from scipy.optimize import least_squares

    timed = alpha is not None
    n = tg.shape[0]
    m = np.array([mode])

    def split(z):
        return z[:9], (alpha - z[2] if timed else z[9:])

    def fun_jac(z):
        xz, thz = split(z)
        r, gx, gt, s2 = (v[0] for v in evaluate_pairs(xz[None], thz[None], m, tg))
        if timed:
            gx = gx.copy()
            gx[..., 2] -= gt
            jac = gx.reshape(2 * n, 9)
        else:
            jac = np.zeros((n, 2, 9 + n))
            jac[:, :, :9] = gx
            jac[np.arange(n), :, 9 + np.arange(n)] = gt
            jac = jac.reshape(2 * n, 9 + n)
        return r.reshape(-1), jac, s2

    cache = {}

    def get(z):
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = fun_jac(z)
        return cache[key]

    z0 = x.copy() if timed else np.concatenate([x, th])
    try:
        with np.errstate(all="ignore"):
            res = least_squares(lambda z: get(z)[0], z0, jac=lambda z: get(z)[1], method="lm", x_scale="jac",
                                ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=40)
    except (ValueError, np.linalg.LinAlgError):
        return x, th, np.inf
    xz, thz = split(res.x)
    r, _, s2 = get(res.x)
    cost = float(np.sum(r * r))
    ok = feasible(xz[None], np.asarray(thz)[None], s2[None], curve, ordered, timed, max_size, cmu)[0]
    if not (ok and np.isfinite(cost)):
        return x, th, np.inf
    return xz, (th if timed else thz), cost


class Problem(NamedTuple):
    """One synthesis problem in the normalised frame, as the least-squares stages take it:
    targets `tg` ``(n, 2)``, prescribed crank angles `alpha` ``(n,)`` or None, the `curve`,
    whether the targets must be met in order, the size limit and the transmission limit's
    cosine."""

    tg: np.ndarray
    alpha: np.ndarray | None
    curve: str
    ordered: bool
    max_size: float
    cmu: float


class Pool(NamedTuple):
    """Starts being solved: designs `x` ``(K, 9)``, crank angles `th` ``(K, n)``, `mode`
    ``(K,)``, `cost` ``(K,)`` (sum of squared residuals; inf: infeasible) and the
    Levenberg-Marquardt `iterations` ``(K,)`` each took."""

    x: np.ndarray
    th: np.ndarray
    mode: np.ndarray
    cost: np.ndarray
    iterations: np.ndarray


def successive_halving(pb: Problem, X, TH, M, schedule) -> Pool:
    """Successive halving: every start a few steps, the best quarter further, ... the last
    few to convergence (`schedule` ``[(survivors, steps), ...]``)."""
    cost, lam = np.zeros(X.shape[0]), np.full(X.shape[0], 1e-3)
    its = np.zeros(X.shape[0], int)
    alive = np.arange(X.shape[0])
    for stage, (keep_n, steps) in enumerate(schedule):
        if stage and pb.alpha is None and not pb.ordered:  # the best twice over to their nearest points, then the cut
            alive = alive[np.argsort(cost[alive], kind="stable")[: 2 * keep_n]]
            alive = alive[np.isfinite(cost[alive])]
            for b0 in range(0, alive.size, 128):
                blk = alive[b0:b0 + 128]
                TH[blk], cost[blk] = closest_angles(X[blk], TH[blk], M[blk], pb.tg, pb.curve, pb.cmu)
        if alive.size > keep_n:
            alive = alive[np.argsort(cost[alive], kind="stable")[:keep_n]]
            alive = alive[np.isfinite(cost[alive])]
        if alive.size == 0:
            break
        X[alive], TH[alive], cost[alive], it_, lam[alive] = levenberg_marquardt(
            X[alive], TH[alive], M[alive], pb.tg, pb.alpha, pb.curve, pb.ordered, pb.max_size, pb.cmu, steps, lam[alive])
        its[alive] += it_
    return Pool(X, TH, M, np.where(np.isfinite(cost), cost, np.inf), its)


def basin_hopping(pb: Problem, pool: Pool, rng, hops: int, iterations: int) -> Pool:
    """`hops` rounds of basin hopping: 128 perturbed copies of the best four designs
    (lengths by 2, 7 or 20 %), solved by successive halving and added to the pool."""
    X, TH, m0, cost, its = pool
    for _ in range(int(hops)):
        best_i = np.argsort(cost)[:4]
        best_i = best_i[np.isfinite(cost[best_i])]
        if best_i.size == 0:
            break
        per = 128 // best_i.size
        src = np.repeat(best_i, per)
        scale = rng.choice([0.02, 0.07, 0.2], src.size)[:, None]
        noise = rng.normal(size=(src.size, 9)) * scale
        noise[:, [0, 1, 7, 8]] *= np.maximum(np.exp(X[src, 3:7]).max(axis=1, keepdims=True), 0.3) * 0.5
        Xh = X[src] + noise
        Xh, THh, _, ch, ih = successive_halving(pb, Xh, TH[src].copy(), m0[src], [(128, 12), (32, 24), (8, int(iterations))])
        X, TH, cost = np.concatenate([X, Xh]), np.concatenate([TH, THh]), np.concatenate([cost, ch])
        m0, its = np.concatenate([m0, m0[src]]), np.concatenate([its, ih])
    return Pool(X, TH, m0, cost, its)


def closest_angles(x, th, mode, tg, curve, cmu, samples=720):
    """Each target's nearest point on each design's feasible curve, on a sampling of
    `samples` crank angles (the whole turn for a crank that turns fully, else the toggle-free
    interval the first target's angle is in), taken where it is nearer than the point at the
    target's crank angle now: ``(th (K, n), cost (K,))``, the crank angles from the ground
    line and the sum of squared distances at them (never above the cost at `th`)."""
    a, b, c, d = (np.exp(x[:, i])[:, None] for i in range(3, 7))
    full, center, half, two, _ = crank_interval(a[:, 0], b[:, 0], c[:, 0], d[:, 0], cmu)
    if curve == "open":
        ctr = np.where(two & (np.sin(th[:, 0]) < 0), -center, center)
        ctr = ctr + TAU * np.round((th[:, 0] - ctr) / TAU)
    else:
        ctr, half = th[:, 0], np.full(th.shape[0], np.pi)
    u = np.linspace(-1.0, 1.0, samples)[1:-1] if curve == "open" else np.linspace(-1.0, 1.0, samples, endpoint=False)
    grid = np.where(full[:, None], th[:, :1] + np.pi * u, ctr[:, None] + half[:, None] * u)  # (K, S)
    grid = np.concatenate([th, grid], axis=1)  # the crank angles now first: kept unless another is nearer

    def distances(cols):
        C, s2 = local_point(np, a, b, c, d, x[:, 7:8], x[:, 8:9], mode[:, None], cols)
        P = np.where(s2 > 0, x[:, :1] + 1j * x[:, 1:2] + np.exp(1j * x[:, 2:3]) * C, np.nan)
        return np.abs((tg[:, 0] + 1j * tg[:, 1])[None, :, None] - P[:, None, :])  # (K, n, cols)

    n = th.shape[1]
    now = np.diagonal(distances(th), axis1=1, axis2=2)  # (K, n): each target at its own angle
    dist = distances(grid[:, n:])
    j = np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=2)
    near = np.take_along_axis(dist, j[..., None], axis=2)[..., 0]
    take = np.isfinite(near) & ~(near >= now)
    th = np.where(take, np.take_along_axis(grid[:, n:], j, axis=1), th)
    return th, np.sum(np.where(take, near, now) ** 2, axis=1)


def reassigned(pb: Problem, pool: Pool, count: int = 8, rounds: int = 3, iterations: int = 60) -> Pool:
    """A polish on the exact distance: the best `count` starts' targets moved to their nearest
    points on the design's curve (``closest_angles``: the least squares can stop with a target
    held on the wrong branch of a curve that crosses itself, or on the wrong side of a cusp),
    then Levenberg-Marquardt again where one moved; kept where the error drops, `rounds`
    times.  Free crank angles only (``pb.alpha`` None, not ``pb.ordered``); changes `pool` in
    place."""
    X, TH, M, cost, its = pool
    if pb.alpha is not None or pb.ordered:
        return pool
    idx = np.argsort(cost)[:count]
    idx = idx[np.isfinite(cost[idx])]
    for _ in range(int(rounds)):
        if idx.size == 0:
            break
        th, _ = closest_angles(X[idx], TH[idx], M[idx], pb.tg, pb.curve, pb.cmu)
        moved = np.any(th != TH[idx], axis=1)  # only where a target found a nearer point
        idx, th = idx[moved], th[moved]
        if idx.size == 0:
            break
        x, th, c, it_, _ = levenberg_marquardt(X[idx].copy(), th, M[idx], pb.tg, None, pb.curve, False, pb.max_size, pb.cmu,
                                               iterations)
        better = np.isfinite(c) & (c < cost[idx] * (1 - 1e-9))
        t = idx[better]
        X[t], TH[t], cost[t] = x[better], th[better], c[better]
        its[idx] += it_
        idx = t
    return pool
