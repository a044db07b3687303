"""Four-bar coupler-path synthesis: a coupler point through N target points.

A four-bar anywhere in the plane: crank ``a`` about ``(x0, y0)``, ground line ``d`` at angle
``phi``, coupler ``b``, rocker ``c``, coupler point ``(px, py)`` in the coupler's frame (x
along crank pin A -> coupler-rocker pin B), and the assembly ``mode`` (+1 or -1), the sign of
the loop's Jacobian determinant, ``sin(theta4 - theta3)`` (+1: the "open" assembly of
``examples/path_synthesis.GENERAL_FOURBAR``; the C1 circuit of four-bar-rs).  A design is a
``{name: float}`` over ``PARAMS`` and ``"mode"``; crank angles ``alpha`` are absolute (from
the x axis).  The RRR dyad is solved in closed form (the circle intersection, on the
design's mode), so a curve and its derivatives are exact.

**Curves** (`curve`):

- ``"closed"``: the targets lie around a closed path traced once per crank turn.  The crank
  must turn fully on the design's mode with the transmission angle at least
  `min_transmission` from a toggle all the way round (with 0: ``|d - a| > |b - c|`` and
  ``d + a < b + c``).
- ``"partial"``: the targets lie on part of a closed coupler curve: the crank turns fully
  (as for a closed curve), the targets cover an arc of less than one turn.
- ``"open"``: the targets lie on an arc of the coupler curve on one toggle-free crank
  interval of the design's mode (the crank need not turn fully): the crank moves from the
  first target to the last without a lock or a change of assembly mode.

(Closed, partial and open as in four-bar-rs: a closed target on a closed curve; an open
target on part of a closed curve; an open target on an open curve, here also allowed on a
crank that turns fully.)  With ``ordered=True`` the targets must also be met in order,
monotonically along the crank (once round for a closed curve); by default the order is
reported (``PathError.in_order``), not imposed.

A design that locks or changes mode within the path is **infeasible**: its error is
``inf``, never a low number.  The usable crank intervals are computed exactly, not
sampled: the transmission angle ``mu`` obeys ``|AO4|^2 = b^2 + c^2 - 2 b c cos(mu)`` and
``|AO4|^2 = a^2 + d^2 - 2 a d cos(theta)``, so ``mu`` stays in ``[mu_min, 180 - mu_min]``
exactly on an interval of ``cos(theta)``: one full turn, or one or two crank intervals
ending at toggles (where the mode could change or the crank locks).

**Error** (`path_error`): the root-mean-square distance from each target to the design's
feasible coupler curve, ``sqrt(mean_i min_alpha |P(alpha) - T_i|^2)``, the curve parameter
free.  The feasible curve is the part traced with the transmission angle (between coupler
and rocker) at least `min_transmission` (default 5 deg) away from a toggle: nearer one the
design is taken to lock.  The error does not depend on how the curve is sampled: the
closest point is searched on a dense sampling and then polished by a golden-section search
to ~1e-14 rad, around every local minimum of the sampled distance near the best.

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

PARAMS = ("x0", "y0", "phi", "a", "b", "c", "d", "px", "py")
CURVES = ("closed", "open", "partial")
TAU = 2.0 * np.pi
_GOLDEN_STEPS = 72  # golden-section steps: a bracket of 2 samples shrinks by 0.618^72 ~ 1e-15


# =========================================================================== the four-bar
def _check_design(design) -> dict:
    missing = [k for k in PARAMS if k not in design]
    if missing:
        raise ValueError(f"four-bar design is missing {missing} (expected {PARAMS} and 'mode')")
    out = {k: float(design[k]) for k in PARAMS}
    mode = float(design.get("mode", 1.0))
    if mode not in (1.0, -1.0):
        raise ValueError(f"four-bar design: mode must be +1 or -1, got {design.get('mode')!r}")
    if min(out["a"], out["b"], out["c"], out["d"]) <= 0:
        raise ValueError("four-bar design: a, b, c, d must be positive")
    out["mode"] = mode
    return out


def _local_point(xp, a, b, c, d, px, py, mode, theta):
    """Coupler point in the ground frame (O2 at 0, O4 at d) at crank angle ``theta`` from the
    ground line, and ``s2 = sin^2`` of the dyad's angle at A (> 0: assembled there)."""
    A = a * xp.cos(theta) + 1j * a * xp.sin(theta)
    AO = d - A
    r2 = AO.real**2 + AO.imag**2
    r = xp.sqrt(r2)
    cg = (b * b + r2 - c * c) / (2.0 * b * r)
    s2 = 1.0 - cg * cg
    sg = xp.sqrt(xp.where(s2 > 0, s2, 1.0))
    e3 = (AO / r) * (cg + 1j * mode * sg)  # unit vector A -> B on the design's mode
    return A + (px + 1j * py) * e3, s2


def coupler_curve(design, alpha):
    """Coupler points (complex, NaN where the loop does not close) at absolute crank angles
    `alpha` (rad), on the design's assembly mode.  numpy."""
    p = _check_design(design)
    theta = np.asarray(alpha, float) - p["phi"]
    P, s2 = _local_point(np, p["a"], p["b"], p["c"], p["d"], p["px"], p["py"], p["mode"], theta)
    P = p["x0"] + 1j * p["y0"] + np.exp(1j * p["phi"]) * P
    return np.where(s2 >= 0, P, np.nan + 0j)


def _bounds(a, b, c, d, cmu):
    """``cos theta`` range ``(lo, hi)`` where the loop closes with a transmission angle (between
    coupler and rocker) of at least ``arccos(cmu)`` away from 0 and 180 deg: ``|AO4|^2`` in
    ``[b^2 + c^2 - 2 b c cmu, b^2 + c^2 + 2 b c cmu]`` (``cmu = 1``: just closes)."""
    lo = (a * a + d * d - (b * b + c * c + 2 * b * c * cmu)) / (2 * a * d)
    hi = (a * a + d * d - (b * b + c * c - 2 * b * c * cmu)) / (2 * a * d)
    return lo, hi


def _interval(a, b, c, d, cmu=1.0, xp=np):
    """The crank's usable set on one mode, from the ground line: ``cos theta`` in ``(lo, hi)``
    (``_bounds``).  Returns ``(full, center, half, two, closes)``: the crank turns fully;
    else the interval ``center +- half`` (and its mirror ``-center +- half`` when ``two``);
    ``closes``: the set is not empty.  Within an interval there is no toggle: the mode cannot
    change and the crank does not lock."""
    lo, hi = _bounds(a, b, c, d, cmu)
    ta = xp.arccos(xp.clip(hi, -1.0, 1.0))  # 0 when hi >= 1 (theta = 0 inside)
    tb = xp.arccos(xp.clip(lo, -1.0, 1.0))  # pi when lo <= -1 (theta = pi inside)
    full = (lo < -1.0) & (hi > 1.0)
    two = (lo > -1.0) & (hi < 1.0)
    around0 = (hi >= 1.0) & ~full
    center = xp.where(around0, 0.0, xp.where(two, 0.5 * (ta + tb), np.pi))
    half = xp.where(around0, tb, xp.where(two, 0.5 * (tb - ta), np.pi - ta))
    closes = (lo < hi) & (lo < 1.0) & (hi > -1.0)
    return full, center, half, two, closes


def _cmu(min_transmission) -> float:
    mt = float(min_transmission)
    if not 0.0 <= mt < 90.0:
        raise ValueError(f"min_transmission must be in [0, 90) degrees, got {min_transmission!r}")
    return float(np.cos(np.radians(mt)))


def crank_intervals(design, min_transmission: float = 0.0) -> list[tuple[float, float]]:
    """The design's toggle-free crank intervals on its mode, absolute angles (rad), where the
    transmission angle stays at least `min_transmission` (deg) from 0 and 180 deg: one
    ``(phi - pi, phi + pi)`` turn when the crank turns fully, else the one or two intervals
    ``(lo, hi)`` bounded by toggles (where the mode could change or the crank locks); ``[]``
    if there is none."""
    p = _check_design(design)
    full, center, half, two, closes = (v.item() for v in np.broadcast_arrays(*_interval(p["a"], p["b"], p["c"], p["d"], _cmu(min_transmission))))
    phi = p["phi"]
    if not closes:
        return []
    if full:
        return [(phi - np.pi, phi + np.pi)]
    out = [(phi + center - half, phi + center + half)]
    if two:
        out.append((phi - center - half, phi - center + half))
    return out


def fully_rotatable(design, min_transmission: float = 0.0) -> bool:
    """Whether the crank turns fully on the design's mode with the transmission angle at least
    `min_transmission` (deg) from 0 and 180 deg all the way round (0: without a toggle)."""
    p = _check_design(design)
    return bool(_interval(p["a"], p["b"], p["c"], p["d"], _cmu(min_transmission))[0])


def transmission_angle(design, alpha):
    """Transmission angle (deg) at absolute crank angles `alpha`: the angle between coupler and
    rocker, folded to ``[0, 90]`` (0: a toggle); NaN where the loop does not close."""
    p = _check_design(design)
    theta = np.asarray(alpha, float) - p["phi"]
    r2 = p["a"] ** 2 + p["d"] ** 2 - 2 * p["a"] * p["d"] * np.cos(theta)
    cmu = (p["b"] ** 2 + p["c"] ** 2 - r2) / (2 * p["b"] * p["c"])
    mu = np.degrees(np.arccos(np.where(np.abs(cmu) <= 1, cmu, np.nan)))
    return np.minimum(mu, 180.0 - mu)


# =========================================================================== the error
@dataclasses.dataclass(frozen=True)
class PathError:
    """Distance from targets to a design's feasible coupler curve (``path_error``).

    - `error`: rms distance (length units; ``inf`` when infeasible).
    - `distances`: ``(N,)`` each target's distance to the curve; `alpha`: ``(N,)`` the absolute
      crank angle of its closest point (rad).
    - `feasible`: the design can trace the path (see the module docstring); `reason`: why not.
    - `in_order`: the closest points are met in the targets' order (cyclically, once round,
      for a closed curve); `interval`: the crank interval used (absolute, rad).
    """

    error: float
    distances: np.ndarray
    alpha: np.ndarray
    feasible: bool
    in_order: bool
    reason: str
    interval: tuple

    @property
    def sum_squares(self) -> float:
        """``sum_i distance_i^2``: the objective most of the literature reports."""
        return float(np.sum(self.distances**2))

    @property
    def max_distance(self) -> float:
        return float(np.max(self.distances))


def _closest_on(p, targets, lo, hi, periodic, samples):
    """Closest points of `targets` on the curve over crank angles ``[lo, hi]`` (from the
    ground line): dense sampling, then golden section around the best local minima."""
    n = targets.shape[0]
    if periodic:
        th = lo + (hi - lo) * np.arange(samples) / samples
    else:
        th = np.linspace(lo, hi, samples)
    P, s2 = _local_point(np, p["a"], p["b"], p["c"], p["d"], p["px"], p["py"], p["mode"], th)
    P = np.where(s2 >= 0, P, P.real * 0 + np.nan)
    dist = np.abs(targets[:, None] - P[None, :])  # (N, M)
    dist = np.where(np.isfinite(dist), dist, np.inf)
    # Local minima of the sampled distance (periodic or not), the best few per target.
    if periodic:
        left, right = np.roll(dist, 1, axis=1), np.roll(dist, -1, axis=1)
    else:
        left = np.concatenate([np.full((n, 1), np.inf), dist[:, :-1]], axis=1)
        right = np.concatenate([dist[:, 1:], np.full((n, 1), np.inf)], axis=1)
    is_min = (dist <= left) & (dist <= right) & np.isfinite(dist)
    cand = np.where(is_min, dist, np.inf)
    k = min(4, samples)
    idx = np.argsort(cand, axis=1)[:, :k]  # (N, k)
    valid = np.isfinite(np.take_along_axis(cand, idx, axis=1))
    step = (hi - lo) / samples if periodic else (hi - lo) / (samples - 1)
    t0 = th[idx]
    x_lo, x_hi = t0 - step, t0 + step
    if not periodic:
        x_lo, x_hi = np.maximum(x_lo, lo), np.minimum(x_hi, hi)
    T = np.broadcast_to(targets[:, None], idx.shape)

    def f(t):
        Q, q2 = _local_point(np, p["a"], p["b"], p["c"], p["d"], p["px"], p["py"], p["mode"], t)
        return np.where(q2 >= 0, np.abs(Q - T), np.inf)

    g = (np.sqrt(5.0) - 1.0) / 2.0
    c1, c2 = x_hi - g * (x_hi - x_lo), x_lo + g * (x_hi - x_lo)
    f1, f2 = f(c1), f(c2)
    for _ in range(_GOLDEN_STEPS):
        left_better = f1 < f2
        x_hi = np.where(left_better, c2, x_hi)
        x_lo = np.where(left_better, x_lo, c1)
        c2n = np.where(left_better, c1, x_lo + g * (x_hi - x_lo))
        c1n = np.where(left_better, x_hi - g * (x_hi - x_lo), c2)
        f1n = np.where(left_better, f(c1n), f2)
        f2n = np.where(left_better, f1, f(c2n))
        c1, c2, f1, f2 = c1n, c2n, f1n, f2n
    # the sample itself and the bracket's ends are candidates too
    cands_t = np.stack([c1, c2, t0], axis=-1)
    cands_f = np.stack([f1, f2, np.take_along_axis(dist, idx, axis=1)], axis=-1)
    best_in = np.argmin(cands_f, axis=-1)
    tt = np.take_along_axis(cands_t, best_in[..., None], axis=-1)[..., 0]
    ff = np.take_along_axis(cands_f, best_in[..., None], axis=-1)[..., 0]
    ff = np.where(valid, ff, np.inf)
    j = np.argmin(ff, axis=1)
    return ff[np.arange(n), j], tt[np.arange(n), j]


def _in_order(theta, periodic_once: bool, full: bool, tol=np.radians(2.0)) -> bool:
    """Targets met in order by a crank turning one way: ``theta`` from the ground line.  A step
    back of at most `tol` (2 deg of crank) is not counted: targets a hair apart, or listed a
    hair out of sequence, do not make a design out of order."""
    n = theta.size
    if n < 3:
        return True
    for sgn in (1.0, -1.0):
        if periodic_once:  # closed: one turn exactly, cyclic
            inc = np.mod(sgn * (np.roll(theta, -1) - theta), TAU)
            inc = np.where(inc > TAU - tol, 0.0, inc)
            if abs(np.sum(inc) - TAU) < 1e-6:
                return True
        elif full:  # open arc on a rotatable crank: less than one turn
            inc = np.mod(sgn * np.diff(theta), TAU)
            inc = np.where(inc > TAU - tol, 0.0, inc)
            if np.sum(inc) < TAU - tol:
                return True
        else:  # within one interval: monotone
            if np.all(sgn * np.diff(theta) >= -tol):
                return True
    return False


def path_error(design, targets, curve: str = "closed", *, min_transmission: float = 5.0, ordered: bool = False,
               samples: int = 720) -> PathError:
    """rms distance from `targets` (complex ``(N,)``) to the design's feasible coupler curve.

    - `curve`: ``"closed"`` or ``"partial"`` (the crank must turn fully; one turn is the
      curve) or ``"open"`` (each toggle-free crank interval of the design's mode is a
      candidate arc; the one nearest the targets is used).
    - `min_transmission` (deg): the curve is the part traced with the transmission angle at
      least this far from 0 and 180 deg; nearer a toggle the design is taken to lock.  A
      closed or partial path needs it all the way round.
    - `ordered`: an out-of-order design (closest points not met in the targets' order) is
      infeasible; by default the order is only reported (`in_order`).
    - `samples`: the dense sampling the closest-point search starts from (the answer does not
      depend on it once every local minimum of the distance is resolved: the default
      resolves features down to 1/720 of the crank's range).
    """
    p = _check_design(design)
    targets = np.asarray(targets, complex).reshape(-1)
    if curve not in CURVES:
        raise ValueError(f"path_error: curve must be one of {CURVES}, got {curve!r}")
    n = targets.size
    nan = np.full(n, np.nan)
    local = (targets - (p["x0"] + 1j * p["y0"])) * np.exp(-1j * p["phi"])  # targets in the ground frame
    full, center, half, two, closes = (v.item() for v in np.broadcast_arrays(*_interval(p["a"], p["b"], p["c"], p["d"],
                                                                                           _cmu(min_transmission))))
    if not closes:
        return PathError(np.inf, nan, nan, False, False, "the loop never closes with that transmission angle", ())
    if curve in ("closed", "partial") and not full:
        return PathError(np.inf, nan, nan, False, False,
                         f"the crank does not turn fully with a transmission angle of at least {min_transmission:g} deg: "
                         f"a {curve} path would pass a toggle or lock", ())
    if full:
        arcs = [(-np.pi, np.pi, True)]
    else:
        arcs = [(center - half, center + half, False)] + ([(-center - half, -center + half, False)] if two else [])
    best = None
    for lo, hi, periodic in arcs:
        d, th = _closest_on(p, local, lo, hi, periodic, samples)
        err = float(np.sqrt(np.mean(d**2)))
        order = _in_order(th, curve == "closed", full)
        key = (ordered and not order, err)
        if best is None or key < best[0]:
            best = (key, d, th, order, (lo + p["phi"], hi + p["phi"]))
    _, d, th, order, interval = best
    alpha = th + p["phi"]
    if ordered and not order:
        return PathError(np.inf, d, alpha, False, False, "the closest points are not met in the targets' order", interval)
    return PathError(float(np.sqrt(np.mean(d**2))), d, alpha, True, order, "", interval)


# =========================================================================== least squares
CHUNK = 1024  #: (start, target) pairs per call of the compiled evaluator: one program for every problem


def _point_real(x, th, mode):
    """Normalised design ``x = (x0, y0, phi, log a, log b, log c, log d, px, py)``: coupler point
    ``(2,)`` at crank angle ``th`` from the ground line, and ``s2`` (``_local_point``).  Real
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
        full, center, half, two, closes = _interval(a, b, c, d, cmu)
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


# =========================================================================== starts (numpy)
def _arc_fractions(targets, closed: bool):
    seg = np.abs(np.diff(targets))
    if closed:
        seg = np.append(seg, np.abs(targets[0] - targets[-1]))
        total = np.sum(seg)
        return np.concatenate([[0.0], np.cumsum(seg[:-1])]) / max(total, 1e-300)
    total = np.sum(seg)
    return np.concatenate([[0.0], np.cumsum(seg)]) / max(total, 1e-300)


def _random_shapes(rng, m, rotatable_fraction, cmu):
    """``m`` random four-bar shapes with ground ``d = 1``: ``(a, b, c, px, py)``; a fraction
    with a crank that turns fully (with the transmission margin `cmu`), the rest with some
    usable crank interval."""
    out = []
    need_rot = int(round(m * rotatable_fraction))
    got_rot, got_any = 0, 0
    for _ in range(200):
        if got_rot >= need_rot and got_any >= m - need_rot:
            break
        k = 4 * m
        a = np.exp(rng.uniform(np.log(0.08), np.log(2.5), k))
        b = np.exp(rng.uniform(np.log(0.2), np.log(4.0), k))
        c = np.exp(rng.uniform(np.log(0.2), np.log(4.0), k))
        rho = np.exp(rng.uniform(np.log(0.05), np.log(4.0), k)) * np.maximum(b, 1.0)
        ang = rng.uniform(-np.pi, np.pi, k)
        px, py = rho * np.cos(ang), rho * np.sin(ang)
        full, _, half, _, closes = _interval(a, b, c, 1.0, cmu)
        rot = np.flatnonzero(full)[: need_rot - got_rot]
        other = np.flatnonzero(~full & closes & (half > 0.05))[: m - need_rot - got_any]
        for idx in (rot, other):
            out.extend(zip(a[idx], b[idx], c[idx], px[idx], py[idx]))
        got_rot, got_any = got_rot + rot.size, got_any + other.size
    return np.array(out).reshape(-1, 5)


GRID = 128  #: samples per random shape's coupler curve when placing it on the targets


def _starts(targets_n, curve, alpha, mode_choices, n_shapes, keep, rng, ordered, cmu):
    """Best-placed random shapes: ``(x (keep, 9), theta (keep, n), mode (keep,), cost (keep,))``
    in the normalised frame.

    Each shape's coupler curve is sampled once (``GRID`` points over its crank interval);
    a placement assigns the targets crank angles spread by arc length (a phase, a span, a
    direction), and is scored by the best similarity (or, with prescribed crank angles,
    scale and translation) taking the curve points to the targets: closed form."""
    n = targets_n.size
    closed = curve == "closed"
    timed = alpha is not None
    shapes = _random_shapes(rng, n_shapes, 0.5 if curve == "open" and not timed else 1.0, cmu)
    a, b, c, px, py = (shapes[:, i] for i in range(5))
    m = a.size
    full, center, half, two, _ = _interval(a, b, c, 1.0, cmu)
    mirror = two & (rng.uniform(size=m) < 0.5)
    lo = np.where(full, -np.pi, np.where(mirror, -center, center) - half)
    width = np.where(full, TAU, 2 * half)
    g = np.arange(GRID)
    grid = lo[:, None] + width[:, None] * np.where(full[:, None], g / GRID, (g + 0.5) / GRID)  # (m, GRID)
    sub = np.unique(np.round(np.linspace(0, n - 1, min(n, 32))).astype(int))
    frac = _arc_fractions(targets_n, closed)
    # placements as positions u in [0, 1) along each shape's interval, (m, P, n)
    us = []
    if timed:
        phis = rng.uniform(-np.pi, np.pi, (m, 8))
        u = (alpha[None, None, :] - phis[:, :, None] - lo[:, None, None]) / width[:, None, None]
        u = np.where(full[:, None, None], np.mod(u, 1.0), u)
        us.append(u)
    elif closed:
        for ph in np.linspace(0, 1, 12, endpoint=False):
            for sgn in (1.0, -1.0):
                us.append(np.broadcast_to(np.mod(ph + sgn * frac, 1.0), (m, n)))
    else:
        for span in (0.35, 0.65, 0.95):
            for off in (0.0, 0.5, 1.0):
                for sgn in (1.0, -1.0):
                    v = off * (1 - span) + span * (frac if sgn > 0 else 1 - frac)
                    us.append(np.broadcast_to(v * 0.999 + 0.0005, (m, n)))
    U = us[0] if timed else np.stack(us, axis=1)  # (m, P, n)
    inside = np.all((U >= 0) & (U < 1), axis=-1)
    idx = np.clip(np.floor(U[..., sub] * GRID).astype(int), 0, GRID - 1)
    Ts = targets_n[sub]
    Tc = Ts - Ts.mean()
    cands = []
    for mode in mode_choices:
        C, s2 = _local_point(np, a[:, None], b[:, None], c[:, None], 1.0, px[:, None], py[:, None], mode, grid)
        C = np.where(s2 >= 0, C, np.nan)
        P = np.take_along_axis(C[:, None, :], idx.reshape(m, -1, sub.size), axis=2) if U.ndim == 3 else None
        if timed:
            rot = np.exp(1j * phis)[:, :, None]
            Q = rot * P
            Qc = Q - Q.mean(-1, keepdims=True)
            k = np.maximum(np.sum((np.conj(Qc) * Tc).real, -1) / np.maximum(np.sum(np.abs(Qc) ** 2, -1), 1e-300), 1e-3)
            z = k * rot[..., 0]
            w = Ts.mean() - k * Q.mean(-1)
            cost = np.sum(np.abs(k[..., None] * Qc - Tc) ** 2, -1)
        else:
            Pc = P - P.mean(-1, keepdims=True)
            z = np.sum(np.conj(Pc) * Tc, -1) / np.maximum(np.sum(np.abs(Pc) ** 2, -1), 1e-300)
            w = Ts.mean() - z * P.mean(-1)
            cost = np.sum(np.abs(z[..., None] * Pc - Tc) ** 2, -1)
        cost = np.where(inside & np.isfinite(cost) & (np.abs(z) > 1e-6), cost, np.inf)
        cands.append((cost, z, w, mode, C))
    costs = np.stack([cd[0] for cd in cands])  # (modes, m, P)
    icp = not (timed or ordered)
    flat = np.argsort(costs, axis=None)[: (2 * keep if icp else keep)]
    flat = flat[np.isfinite(costs.reshape(-1)[flat])]
    gi, i, j = np.unravel_index(flat, costs.shape)
    z = np.array([cands[g][1][ii, jj] for g, ii, jj in zip(gi, i, j)])
    w = np.array([cands[g][2][ii, jj] for g, ii, jj in zip(gi, i, j)])
    mode = np.array([cands[g][3] for g in gi], float)
    curves = np.stack([cands[g][4][ii] for g, ii in zip(gi, i)]) if flat.size else np.zeros((0, GRID), complex)
    if icp and flat.size:
        # closest-point iterations: each target to its nearest point of the placed curve,
        # then the best similarity again (the distance to the curve, not to a timing guess)
        for _ in range(2):
            jj = _nearest(curves, z, w, Ts)
            P = np.take_along_axis(curves, jj, axis=1)
            Pc = P - P.mean(-1, keepdims=True)
            z = np.sum(np.conj(Pc) * Tc, -1) / np.maximum(np.sum(np.abs(Pc) ** 2, -1), 1e-300)
            w = Ts.mean() - z * P.mean(-1)
        jj = _nearest(curves, z, w, Ts)
        P = np.take_along_axis(curves, jj, axis=1)
        cost = np.sum(np.abs(z[:, None] * P + w[:, None] - Ts) ** 2, -1)
        cost = np.where(np.isfinite(cost) & (np.abs(z) > 1e-6), cost, np.inf)
        sel = np.argsort(cost)[:keep]
        sel = sel[np.isfinite(cost[sel])]
        jj = _nearest(curves[sel], z[sel], w[sel], targets_n)
        theta = np.take_along_axis(grid[i[sel]], jj, axis=1)
        cost = cost[sel]
    else:
        sel = np.arange(flat.size)
        cost = costs.reshape(-1)[flat]
        theta = lo[i, None] + width[i, None] * U[i, j]
        theta = np.unwrap(theta, axis=1) if (timed or closed) else theta  # ordered crank angles, unwrapped
    ii, s_ = i[sel], np.abs(z[sel])
    lens = np.log(np.stack([a[ii], b[ii], c[ii], np.ones(ii.size)], axis=1) * s_[:, None])
    x = np.concatenate([np.stack([w[sel].real, w[sel].imag, np.angle(z[sel])], axis=1), lens,
                        np.stack([px[ii] * s_, py[ii] * s_], axis=1)], axis=1)
    return x, theta.reshape(-1, n), mode[sel], cost


def _nearest(curves, z, w, targets, block=64):
    """Index of each target's nearest sample on each placed curve ``z C + w``: ``(K, n)``."""
    out = np.empty((curves.shape[0], targets.size), int)
    for s0 in range(0, curves.shape[0], block):
        sl = slice(s0, s0 + block)
        placed = z[sl, None] * curves[sl] + w[sl, None]  # (k, GRID)
        d = np.abs(targets[None, :, None] - placed[:, None, :])
        out[sl] = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    return out


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
    cmu = _cmu(min_transmission)
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
    x0, th0, m0, _ = _starts(Tn, curve, alpha, modes, shapes, starts, rng, bool(ordered), cmu)
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
