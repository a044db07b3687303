"""Four-bar coupler-path synthesis: a coupler point through N target points
(``synthesize_path``).  The designs, curves and the error measure are those of
``jaxmech.design.coupler_path`` (re-exported here).

**Method** (`synthesize_path`): least squares over the design and one crank angle per
target (each target's own curve parameter: at the optimum the residual is orthogonal to the
curve, its length the distance to the curve), or over the design alone when the crank
angles are prescribed.

- Starts: random four-bar shapes, each sampled once along its crank and placed on the
  targets by the best similarity (rotation, scale, translation: closed form), first with
  crank angles spread along the targets by arc length (several phases, both turning
  directions, both modes), then by two closest-point iterations (each target to its
  nearest curve sample, the similarity again).
- The best-placed starts (1024 by default) are solved as one batch by Levenberg-Marquardt:
  residuals and their exact Jacobians for every (start, target) pair from one compiled JAX
  program (forward mode; the same program for every problem size), the steps in numpy with
  the crank-angle unknowns eliminated through their diagonal block (a Schur complement: a
  9x9 solve per start whatever N).  A step is taken only if it lowers the error and keeps
  the design feasible (the crank interval rules above at every target, lengths within
  `max_size`), so every iterate is a feasible design.  Successive halving keeps the best
  quarter after 12, 24, 48... steps; the last eight go on to convergence (at most 150
  steps); then one round of basin hopping (perturbed copies of the best four) the same way.
- The best few are scored by ``path_error``; the best wins.
"""

from __future__ import annotations

import dataclasses
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..xla import jit
from .coupler_path import (CURVES, PARAMS, TAU, PathError, cos_transmission_limit, coupler_curve, crank_interval, crank_intervals,
                           fully_rotatable, local_point, path_error, transmission_angle)
from .synthesis_starts import placed_starts

__all__ = [
    "CURVES",
    "PARAMS",
    "PathError",
    "PathSynthesis",
    "coupler_curve",
    "crank_intervals",
    "fully_rotatable",
    "path_error",
    "synthesize_path",
    "transmission_angle",
]

# =========================================================================== least squares
CHUNK = 1024  #: (start, target) pairs per call of the compiled evaluator: one program for every problem


def _point_real(x, th, mode):
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
def _evaluator():
    """``(x (M, 9), th (M,), mode (M,), target (M, 2)) -> (r (M, 2), dr/dx (M, 2, 9), dr/dth
    (M, 2), s2 (M,))`` for ``M = CHUNK`` pairs, compiled once (forward mode)."""

    def one(x, th, mode, tg):
        P, s2 = _point_real(x, th, mode)
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


def _evaluate(x, th, mode, tg):
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
    prog, _ = _evaluator()
    outs = []
    with jax.enable_x64(True):
        for i in range(0, m + pad, CHUNK):
            sl = slice(i, i + CHUNK)
            outs.append(prog(xs[sl], ths[sl], ms[sl], tgs[sl]))
        outs = [np.concatenate([np.asarray(o[j]) for o in outs])[:m] for j in range(4)]
    r, gx, gt, s2 = outs
    return r.reshape(k, n, 2), gx.reshape(k, n, 2, 9), gt.reshape(k, n, 2), s2.reshape(k, n)


def _feasible(x, theta, s2, curve, ordered, timed, max_size, cmu):
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


def _levenberg_marquardt(x, th, mode, tg, alpha, curve, ordered, max_size, cmu, iterations, lam=None):
    """Every start at once (numpy over the batch; the compiled evaluator for residuals and
    exact Jacobians).  Returns ``x, th, cost (K,), iterations (K,)``; ``cost = inf`` for a
    start that was infeasible from the beginning."""
    timed = alpha is not None
    k, n = th.shape

    def angles(x, th):
        return alpha[None, :] - x[:, 2:3] if timed else th

    def evaluate(x, th, mode):
        theta = angles(x, th)
        r, gx, gt, s2 = _evaluate(x, theta, mode, tg)
        if timed:  # theta = alpha - phi
            gx = gx.copy()
            gx[..., 2] -= gt
        cost = np.sum(r * r, axis=(1, 2))
        ok = _feasible(x, theta, s2, curve, ordered, timed, max_size, cmu) & np.isfinite(cost)
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
    return x, th, cost, its, lam


# =========================================================================== synthesis
@dataclasses.dataclass(frozen=True)
class PathSynthesis:
    """Answer of ``synthesize_path``.

    - `design`: ``{name: float}`` over ``PARAMS`` and ``"mode"`` (None if no start stayed
      feasible); `error`: its ``path_error`` (rms distance to the curve, length units; ``inf``
      if none); `path`: the whole ``PathError`` (distances, crank angles, order).
    - `curve`, `timed`: the problem; `starts`: starts solved (basin-hopping copies included);
      `feasible_starts`: those feasible from the beginning (every step keeps a design
      feasible); `start_errors`: ``(starts,)`` each one's rms residual at its own crank angles
      where it stopped (successive halving stops most of them early; ``inf``: infeasible).
    - `wall_s` (everything, compile included), `compile_s` (0 when an earlier call compiled
      the same program), `iterations`: ``(starts,)`` Levenberg-Marquardt steps of each.
    """

    design: dict | None
    error: float
    path: PathError | None
    curve: str
    timed: bool
    starts: int
    feasible_starts: int
    start_errors: np.ndarray
    iterations: np.ndarray
    wall_s: float
    compile_s: float

    def report(self) -> str:
        lines = [f"path synthesis ({self.curve} curve, {'prescribed' if self.timed else 'free'} crank angles): "
                 f"rms distance to the curve {self.error:.6g}; {self.feasible_starts}/{self.starts} starts feasible; "
                 f"{self.wall_s:.2f} s ({self.compile_s:.2f} s compiling)"]
        if self.design is not None:
            lines.append("  " + ", ".join(f"{k} = {v:.6g}" for k, v in self.design.items()))
            lines.append(f"  max distance {self.path.max_distance:.3g}, sum of squares {self.path.sum_squares:.4g}, "
                         f"in order: {self.path.in_order}")
        return "\n".join(lines)


def _polish(x, th, mode, tg, alpha, curve, ordered, max_size, cmu):
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
        r, gx, gt, s2 = (v[0] for v in _evaluate(xz[None], thz[None], m, tg))
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
    ok = _feasible(xz[None], np.asarray(thz)[None], s2[None], curve, ordered, timed, max_size, cmu)[0]
    if not (ok and np.isfinite(cost)):
        return x, th, np.inf
    return xz, (th if timed else thz), cost


def _rounds(starts, rounds, iterations):
    if rounds is not None:
        return [(int(k), int(s)) for k, s in rounds]
    out, k, steps = [], int(starts), 12
    while k > 8:
        out.append((k, steps))
        k, steps = max(k // 4, 8), steps * 2
    out.append((k, int(iterations)))
    return out


def synthesize_path(targets, curve: str = "closed", alpha=None, *, starts: int | None = None, shapes: int = 4000,
                    rounds=None, iterations: int = 150, hops: int = 1, ordered: bool = False, modes=(1, -1),
                    min_transmission: float = 5.0, max_size: float = 10.0, seed: int = 0, score: int = 3,
                    polish: bool = False) -> PathSynthesis:
    """A four-bar whose coupler point passes through (or nearest to) `targets`.

    **Arguments**

    - `targets`: complex ``(N,)`` (or real ``(N, 2)``), N >= 3, in path order.
    - `curve`: ``"closed"``, ``"open"`` or ``"partial"`` (module docstring).
    - `alpha`: ``(N,)`` prescribed absolute crank angles (rad), or None (each target's crank
      angle is an unknown).  With `alpha` the error is still ``path_error``'s (the design's
      distance to the curve); `start_errors` are the timed residuals.
    - `starts`: starts solved together (the best-placed of `shapes` random shapes, each tried
      at several placements; default 1024, fewer for many targets: ``50000 / N``, at least
      256), by successive halving: all take 12 Levenberg-Marquardt steps,
      the best quarter 24 more, ... the last 8 up to `iterations` more (or convergence);
      `rounds` ``[(survivors, steps), ...]`` sets the schedule instead.
    - `hops`: rounds of basin hopping after that: 128 perturbed copies of the best four
      designs (lengths by 2, 7 or 20 %), solved by successive halving again.
    - `ordered`: the targets must be met in order (cyclically once round for a closed curve,
      monotonically along an arc otherwise).
    - `modes`: assembly modes tried (+1, -1 or both).
    - `min_transmission` (deg): along the path the transmission angle stays at least this
      far from 0 and 180 deg (``path_error``'s feasible curve); nearer a toggle the design
      is taken to lock.
    - `max_size`: link lengths, the coupler point's offset and both ground pivots' distances
      from the targets' centroid at most this many times the targets' rms radius.
    - `score`: how many of the best starts are scored by ``path_error`` (the best wins).
    - `polish`: the best start is polished further by MINPACK's Levenberg-Marquardt (QR of the
      exact Jacobian): for an ill-conditioned problem (a short arc) where the batched normal
      equations stall.

    **Returns** a ``PathSynthesis``.
    """
    t_start = time.perf_counter()
    if curve not in CURVES:
        raise ValueError(f"synthesize_path: curve must be one of {CURVES}, got {curve!r}")
    cmu = cos_transmission_limit(min_transmission)
    T = np.asarray(targets)
    if T.ndim == 2 and T.shape[1] == 2 and not np.iscomplexobj(T):
        T = T[:, 0] + 1j * T[:, 1]
    T = np.asarray(T, complex).reshape(-1)
    n = T.size
    if n < 3 or not np.all(np.isfinite(T)):
        raise ValueError(f"synthesize_path: need at least 3 finite target points, got {n}")
    timed = alpha is not None
    if timed:
        alpha = np.asarray(alpha, float)
        if alpha.shape != (n,):
            raise ValueError(f"synthesize_path: alpha must have the targets' shape ({n},), got {alpha.shape}")
    modes = tuple(float(m) for m in modes)
    if not modes or any(m not in (1.0, -1.0) for m in modes):
        raise ValueError(f"synthesize_path: modes must be +1 and/or -1, got {modes}")
    # normalised frame: centroid at 0, rms radius 1
    centre = T.mean()
    size = float(np.sqrt(np.mean(np.abs(T - centre) ** 2)))
    if size == 0:
        raise ValueError("synthesize_path: the targets are all at one point")
    Tn = (T - centre) / size
    rng = np.random.default_rng(seed)
    starts = int(starts) if starts is not None else int(min(1024, max(256, 50000 // n)))
    x0, th0, m0, _ = placed_starts(Tn, curve, alpha, modes, shapes, starts, rng, bool(ordered), cmu)
    k = x0.shape[0]
    if k < starts:  # too few placeable shapes: repeat the best
        reps = int(np.ceil(starts / max(k, 1)))
        x0, th0, m0 = (np.concatenate([v] * reps)[:starts] for v in (x0, th0, m0))
    misses = _evaluator.cache_info().misses
    _, compile_s = _evaluator()
    compile_s = compile_s if _evaluator.cache_info().misses > misses else 0.0
    tg = np.stack([Tn.real, Tn.imag], axis=1)
    a_ = alpha if timed else None

    def halving(X, TH, M, schedule):
        """Successive halving: every start a few steps, the best quarter further, ... the
        last few to convergence."""
        cost, lam = np.zeros(X.shape[0]), np.full(X.shape[0], 1e-3)
        its = np.zeros(X.shape[0], int)
        alive = np.arange(X.shape[0])
        for keep_n, steps in schedule:
            if alive.size > keep_n:
                alive = alive[np.argsort(cost[alive], kind="stable")[:keep_n]]
                alive = alive[np.isfinite(cost[alive])]
            if alive.size == 0:
                break
            X[alive], TH[alive], cost[alive], it_, lam[alive] = _levenberg_marquardt(
                X[alive], TH[alive], M[alive], tg, a_, curve, bool(ordered), float(max_size), cmu, steps, lam[alive])
            its[alive] += it_
        return X, TH, np.where(np.isfinite(cost), cost, np.inf), its

    X, TH, cost, its = halving(x0.copy(), th0.copy(), m0, _rounds(starts, rounds, iterations))
    # basin hopping: perturbed copies of the best few, solved the same way
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
        Xh, THh, ch, ih = halving(Xh, TH[src].copy(), m0[src], [(128, 12), (32, 24), (8, int(iterations))])
        X, TH, cost = np.concatenate([X, Xh]), np.concatenate([TH, THh]), np.concatenate([cost, ch])
        m0, its = np.concatenate([m0, m0[src]]), np.concatenate([its, ih])
    start_err = np.sqrt(cost / n) * size
    order = np.argsort(cost)
    best = None
    for rank, i in enumerate(order[: max(1, score)]):
        if not np.isfinite(cost[i]):
            break
        if polish and rank == 0:
            xi, thi, ci = _polish(X[i], TH[i], m0[i], tg, a_, curve, bool(ordered), float(max_size), cmu)
            if ci < cost[i]:
                X[i], TH[i], cost[i] = xi, thi, ci
                start_err[i] = np.sqrt(ci / n) * size
        design = _denormalise(X[i], m0[i], centre, size)
        pe = path_error(design, T, curve, min_transmission=min_transmission)
        if best is None or pe.error < best[1].error:
            best = (design, pe)
    wall = time.perf_counter() - t_start
    design, pe = (best if best is not None else (None, None))
    return PathSynthesis(design=design, error=pe.error if pe is not None else np.inf, path=pe, curve=curve, timed=timed,
                         starts=int(cost.size), feasible_starts=int(np.sum(np.isfinite(cost))), start_errors=start_err,
                         iterations=its, wall_s=wall, compile_s=compile_s)


def _denormalise(x, mode, centre, size) -> dict:
    w = centre + size * (x[0] + 1j * x[1])
    lens = np.exp(x[3:7]) * size
    return {"x0": float(w.real), "y0": float(w.imag), "phi": float(np.angle(np.exp(1j * x[2]))), "a": float(lens[0]),
            "b": float(lens[1]), "c": float(lens[2]), "d": float(lens[3]), "px": float(x[7] * size), "py": float(x[8] * size),
            "mode": float(mode)}
