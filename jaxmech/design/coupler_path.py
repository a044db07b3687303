"""Four-bar coupler paths: the curve, its usable crank intervals and the error of a design
against target points (``path_error``); the synthesis itself is ``jaxmech.design.synthesis``.

A four-bar anywhere in the plane: crank ``a`` about ``(x0, y0)``, ground line ``d`` at angle
``phi``, coupler ``b``, rocker ``c``, coupler point ``(px, py)`` in the coupler's frame (x
along crank pin A -> coupler-rocker pin B), and the assembly ``mode`` (+1 or -1), the sign of
the loop's Jacobian determinant, ``sin(theta4 - theta3)`` (+1: the "open" assembly of
``examples/tolerance_study.GENERAL_FOURBAR``; the C1 circuit of four-bar-rs).  A design is a
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
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import numpy as np

__all__ = ["CURVES", "PARAMS", "TAU", "PathError", "coupler_curve", "cos_transmission_limit", "crank_interval",
           "crank_intervals", "fully_rotatable", "local_point", "path_error", "read_targets", "transmission_angle"]

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


def local_point(xp, a, b, c, d, px, py, mode, theta):
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
    P, s2 = local_point(np, p["a"], p["b"], p["c"], p["d"], p["px"], p["py"], p["mode"], theta)
    P = p["x0"] + 1j * p["y0"] + np.exp(1j * p["phi"]) * P
    return np.where(s2 >= 0, P, np.nan + 0j)


def _bounds(a, b, c, d, cmu):
    """``cos theta`` range ``(lo, hi)`` where the loop closes with a transmission angle (between
    coupler and rocker) of at least ``arccos(cmu)`` away from 0 and 180 deg: ``|AO4|^2`` in
    ``[b^2 + c^2 - 2 b c cmu, b^2 + c^2 + 2 b c cmu]`` (``cmu = 1``: just closes)."""
    lo = (a * a + d * d - (b * b + c * c + 2 * b * c * cmu)) / (2 * a * d)
    hi = (a * a + d * d - (b * b + c * c - 2 * b * c * cmu)) / (2 * a * d)
    return lo, hi


class CrankInterval(NamedTuple):
    """The crank's usable set on one mode (``crank_interval``); unpacks like the 5-tuple it
    replaces.  Angles in rad from the ground line."""

    full: Any  # the crank turns fully
    center: Any  # the interval is center +- half ...
    half: Any
    two: Any  # ... and its mirror -center +- half too
    closes: Any  # the set is not empty


def crank_interval(a, b, c, d, cmu=1.0, xp=np) -> CrankInterval:
    """The crank's usable set on one mode, from the ground line: ``cos theta`` in ``(lo, hi)``
    (``_bounds``).  Returns a ``CrankInterval`` ``(full, center, half, two, closes)``: the crank turns fully;
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
    return CrankInterval(full, center, half, two, closes)


def cos_transmission_limit(min_transmission) -> float:
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
    full, center, half, two, closes = (v.item() for v in np.broadcast_arrays(*crank_interval(p["a"], p["b"], p["c"], p["d"], cos_transmission_limit(min_transmission))))
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
    return bool(crank_interval(p["a"], p["b"], p["c"], p["d"], cos_transmission_limit(min_transmission))[0])


def transmission_angle(design, alpha):
    """Transmission angle (deg) at absolute crank angles `alpha`: the angle between coupler and
    rocker, folded to ``[0, 90]`` (0: a toggle); NaN where the loop does not close."""
    p = _check_design(design)
    theta = np.asarray(alpha, float) - p["phi"]
    r2 = p["a"] ** 2 + p["d"] ** 2 - 2 * p["a"] * p["d"] * np.cos(theta)
    cmu = (p["b"] ** 2 + p["c"] ** 2 - r2) / (2 * p["b"] * p["c"])
    mu = np.degrees(np.arccos(np.where(np.abs(cmu) <= 1, cmu, np.nan)))
    return np.minimum(mu, 180.0 - mu)


# =========================================================================== the targets
def read_targets(targets, what: str) -> np.ndarray:
    """Target points as complex ``(N,)`` (``x + i y``, length units) from either accepted
    form: complex ``(N,)``, or real ``(N, 2)`` with one ``(x, y)`` row per point.

    Any other shape or type is refused with a ``ValueError`` naming `what` (the calling
    function): a real ``(N,)`` array (x alone? a flattened ``(x, y)`` list?), ``(2, N)``
    columns or complex ``(N, 2)`` would otherwise be read as different points without a
    word.  Non-finite points are refused too."""
    T = np.asarray(targets)
    accepted = "complex (N,) (x + 1j*y) or real (N, 2) (one (x, y) row per point)"
    if T.dtype.kind not in "iufc":
        raise ValueError(f"{what}: targets must be numbers, {accepted}; got dtype {T.dtype}")
    if T.ndim == 2 and T.shape[1] == 2 and T.dtype.kind != "c":
        T = T[:, 0].astype(float) + 1j * T[:, 1].astype(float)
    elif not (T.ndim == 1 and T.dtype.kind == "c"):
        kind = "complex" if T.dtype.kind == "c" else "real"
        hint = " (for (2, N) columns pass targets.T)" if T.ndim == 2 and T.shape[0] == 2 else ""
        raise ValueError(f"{what}: targets must be {accepted}; got {kind} {T.shape}{hint}")
    T = T.astype(complex)
    if T.size == 0 or not np.all(np.isfinite(T)):
        raise ValueError(f"{what}: targets must be at least one finite point, got {T.size} with "
                         f"{int(np.sum(~np.isfinite(T)))} not finite")
    return T


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
    P, s2 = local_point(np, p["a"], p["b"], p["c"], p["d"], p["px"], p["py"], p["mode"], th)
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
        Q, q2 = local_point(np, p["a"], p["b"], p["c"], p["d"], p["px"], p["py"], p["mode"], t)
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
    """rms distance from `targets` to the design's feasible coupler curve (length units, those of
    the design and the targets).

    - `targets`: complex ``(N,)`` (``x + 1j*y``) or real ``(N, 2)`` (one ``(x, y)`` row per
      point), as ``synthesize_path`` takes them; any other shape is a ``ValueError``.

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
    targets = read_targets(targets, "path_error")
    if curve not in CURVES:
        raise ValueError(f"path_error: curve must be one of {CURVES}, got {curve!r}")
    n = targets.size
    nan = np.full(n, np.nan)
    local = (targets - (p["x0"] + 1j * p["y0"])) * np.exp(-1j * p["phi"])  # targets in the ground frame
    full, center, half, two, closes = (v.item() for v in np.broadcast_arrays(*crank_interval(p["a"], p["b"], p["c"], p["d"],
                                                                                           cos_transmission_limit(min_transmission))))
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


