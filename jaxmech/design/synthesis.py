"""Four-bar coupler-path synthesis: a coupler point through N target points
(``synthesize_path``).  The designs, curves and the error measure are those of
``jaxmech.design.coupler_path`` (re-exported here).

**Method** (`synthesize_path`): least squares over the design and one crank angle per
target (each target's own curve parameter: at the optimum the residual is orthogonal to the
curve, its length the distance to the curve), or over the design alone when the crank
angles are prescribed.

- Starts: random four-bar shapes (8000 by default), each sampled once along its crank and
  placed on the targets by the best similarity (rotation, scale, translation: closed form).
  With free crank angles the targets go to the points at the same fractions of arc length
  along the shape's curve as along the targets (several phases, both directions, both
  modes; a curve descriptor that does not depend on how fast the crank draws the curve),
  then two closest-point iterations (each target to its nearest curve sample, the
  similarity again); with prescribed or ordered crank angles, to the same fractions of the
  crank's interval.
- The best-placed starts (1024 by default) are solved as one batch by Levenberg-Marquardt:
  residuals and their exact Jacobians for every (start, target) pair from one compiled JAX
  program (forward mode; the same program for every problem size), the steps in numpy with
  the crank-angle unknowns eliminated through their diagonal block (a Schur complement: a
  9x9 solve per start whatever N).  A step is taken only if it lowers the error and keeps
  the design feasible (the crank interval rules above at every target, lengths within
  `max_size`), so every iterate is a feasible design.  Successive halving keeps the best
  quarter after 12, 24, 48... steps; the last eight go on to convergence (at most 150
  steps); then one round of basin hopping (perturbed copies of the best four) the same way.
- A polish on the exact distance (free crank angles): the best eight starts' targets moved
  to their nearest points on the design's curve (the least squares can hold a target on the
  wrong branch of a curve that crosses itself), Levenberg-Marquardt again, up to 3 times.
- The best few are scored by ``path_error``; the best wins.

The starts are ``jaxmech.design.synthesis_starts``; the least squares, successive halving
and basin hopping ``jaxmech.design.synthesis_lsq``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .coupler_path import (CURVES, PARAMS, TAU, PathError, cos_transmission_limit, coupler_curve, crank_interval, crank_intervals,
                           fully_rotatable, local_point, path_error, read_targets, transmission_angle)
from .synthesis_lsq import Pool, Problem, basin_hopping, evaluator, reassigned, successive_halving
from .synthesis_lsq import polish as polish_start
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
    - `reached_best`: how many starts ended at the best answer (``starts_at_best()``, within
      0.1 %): evidence for the answer; 1 is a lucky start (try another `seed`, more `shapes`).

    ``starts_at_best()`` counts the starts that ended at the best answer: many (the optimum
    was found from many places) is more trust than one (a lucky start: try another `seed`).
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
    reached_best: int = 0

    def starts_at_best(self, rtol: float = 1e-3) -> int:
        """Starts whose own error (`start_errors`, length units) ended within `rtol` (relative)
        of the best start's, or within 1e-9 of the design's longest link of it (an exact fit,
        where relative differences of round-off mean nothing); 0 when no start is feasible.
        Successive halving runs only the best few to convergence, so this counts those (and
        the basin-hopping copies) that reached the best."""
        finite = self.start_errors[np.isfinite(self.start_errors)]
        if self.design is None or finite.size == 0:
            return 0
        scale = max(self.design[k] for k in ("a", "b", "c", "d"))
        return int(np.sum(finite <= finite.min() * (1 + rtol) + 1e-9 * scale))

    def report(self) -> str:
        lines = [f"path synthesis ({self.curve} curve, {'prescribed' if self.timed else 'free'} crank angles): "
                 f"rms distance to the curve {self.error:.6g}; {self.feasible_starts}/{self.starts} starts feasible, "
                 f"{self.reached_best} at the best (0.1 %); {self.wall_s:.2f} s ({self.compile_s:.2f} s compiling)"]
        if self.design is not None:
            lines.append("  " + ", ".join(f"{k} = {v:.6g}" for k, v in self.design.items()))
            lines.append(f"  max distance {self.path.max_distance:.3g}, sum of squares {self.path.sum_squares:.4g}, "
                         f"in order: {self.path.in_order}")
        return "\n".join(lines)


def _rounds(starts, rounds, iterations):
    if rounds is not None:
        return [(int(k), int(s)) for k, s in rounds]
    out, k, steps = [], int(starts), 12
    while k > 8:
        out.append((k, steps))
        k, steps = max(k // 4, 8), steps * 2
    out.append((k, int(iterations)))
    return out


def best_scored(pb: Problem, pool: Pool, start_err, T, centre, size, score: int, polish: bool, min_transmission):
    """The best of the `score` lowest-cost starts by ``path_error`` (the first polished by
    ``synthesis_lsq.polish`` when `polish`, in place in `pool` and `start_err`): ``(design, PathError)``,
    or ``(None, None)`` when no start is feasible."""
    X, TH, m0, cost, _ = pool
    n = T.size
    best = None
    for rank, i in enumerate(np.argsort(cost)[: max(1, score)]):
        if not np.isfinite(cost[i]):
            break
        if polish and rank == 0:
            xi, thi, ci = polish_start(X[i], TH[i], m0[i], pb.tg, pb.alpha, pb.curve, pb.ordered, pb.max_size, pb.cmu)
            if ci < cost[i]:
                X[i], TH[i], cost[i] = xi, thi, ci
                start_err[i] = np.sqrt(ci / n) * size
        design = _denormalise(X[i], m0[i], centre, size)
        pe = path_error(design, T, pb.curve, min_transmission=min_transmission)
        if best is None or pe.error < best[1].error:
            best = (design, pe)
    return best if best is not None else (None, None)


def checked_targets(targets, alpha, modes):
    """``(T (N,) complex, alpha (N,) or None, modes)`` checked: ``ValueError`` for targets of
    neither accepted shape (``read_targets``, as ``path_error`` reads them), fewer than 3,
    `alpha` not of the targets' shape, modes not +-1."""
    T = read_targets(targets, "synthesize_path")
    n = T.size
    if n < 3:
        raise ValueError(f"synthesize_path: need at least 3 finite target points, got {n}")
    if alpha is not None:
        alpha = np.asarray(alpha, float)
        if alpha.shape != (n,):
            raise ValueError(f"synthesize_path: alpha must have the targets' shape ({n},), got {alpha.shape}")
    modes = tuple(float(m) for m in modes)
    if not modes or any(m not in (1.0, -1.0) for m in modes):
        raise ValueError(f"synthesize_path: modes must be +1 and/or -1, got {modes}")
    return T, alpha, modes


def synthesize_path(targets, curve: str = "closed", alpha=None, *, starts: int | None = None, shapes: int = 8000,
                    rounds=None, iterations: int = 150, hops: int = 1, ordered: bool = False, modes=(1, -1),
                    min_transmission: float = 5.0, max_size: float = 10.0, seed: int = 0, score: int = 3,
                    polish: bool = False) -> PathSynthesis:
    """A four-bar whose coupler point passes through (or nearest to) `targets`.

    **Arguments**

    - `targets`: complex ``(N,)`` (``x + 1j*y``) or real ``(N, 2)`` (one ``(x, y)`` row per
      point), N >= 3, in path order (length units: the design comes back in them).
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
    T, alpha, modes = checked_targets(targets, alpha, modes)
    n = T.size
    timed = alpha is not None
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
    misses = evaluator.cache_info().misses
    _, compile_s = evaluator()
    compile_s = compile_s if evaluator.cache_info().misses > misses else 0.0
    pb = Problem(np.stack([Tn.real, Tn.imag], axis=1), alpha, curve, bool(ordered), float(max_size), cmu)
    pool = successive_halving(pb, x0.copy(), th0.copy(), m0, _rounds(starts, rounds, iterations))
    # basin hopping: perturbed copies of the best few, solved the same way
    pool = basin_hopping(pb, pool, rng, hops, iterations)
    pool = reassigned(pb, pool)
    start_err = np.sqrt(pool.cost / n) * size
    design, pe = best_scored(pb, pool, start_err, T, centre, size, score, polish, min_transmission)
    wall = time.perf_counter() - t_start
    cost = pool.cost
    res = PathSynthesis(design=design, error=pe.error if pe is not None else np.inf, path=pe, curve=curve, timed=timed,
                        starts=int(cost.size), feasible_starts=int(np.sum(np.isfinite(cost))), start_errors=start_err,
                        iterations=pool.iterations, wall_s=wall, compile_s=compile_s)
    return dataclasses.replace(res, reached_best=res.starts_at_best())


def _denormalise(x, mode, centre, size) -> dict:
    w = centre + size * (x[0] + 1j * x[1])
    lens = np.exp(x[3:7]) * size
    return {"x0": float(w.real), "y0": float(w.imag), "phi": float(np.angle(np.exp(1j * x[2]))), "a": float(lens[0]),
            "b": float(lens[1]), "c": float(lens[2]), "d": float(lens[3]), "px": float(x[7] * size), "py": float(x[8] * size),
            "mode": float(mode)}
