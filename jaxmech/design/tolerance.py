"""Tolerance analysis: the spread of any figure of merit from manufacturing tolerances.

Every length and pivot coordinate ``p_k`` of a design is made within ``+-t_k`` of its
nominal value.  To first order a figure ``f`` (flap travel, peak torque, a coupler point's
position) moves by ``df = sum_k J_k dp_k`` with ``J = df/dp`` the exact Jacobian (implicit
function theorem through the position solve), so

- worst case:      ``|df| <= sum_k |J_k| t_k``  (every deviation at its limit, signs aligned);
- root-sum-square: ``sqrt(sum_k (J_k t_k)^2)``, the spread at the confidence the ``t_k``
  stand for when the deviations are independent (e.g. ``t_k = 3 sigma_k``: ``rss = 3 sigma_f``);
- standard deviation ``sigma_f = rss / z`` with ``t_k = z sigma_k`` (``z = 3`` by default).

``analyse`` evaluates these for a batch of designs and several figures in one compiled
call (``jax.vmap(jax.jacfwd(figure))``: ``sensitivities.batch_jacobian`` in forward
mode); ``monte_carlo`` checks them by sampling
``dp_k ~ N(0, (t_k / z)^2)`` and evaluating the figure on every sample, batched.  The two
agree while ``f`` is close to linear over the tolerance box; as tolerances grow the
curvature of ``f`` adds a bias and a spread the linear model misses (``benchmarks/design.py
--tolerance`` shows where).

**Yield** (``yield_estimate``): the fraction of made designs whose figure lies within a
specification ``low <= f <= high`` (figure units), per figure and for all specified figures
at once, by Monte Carlo with a Wilson score interval (``wilson_interval``) at a chosen
confidence, beside the first-order estimate ``Phi((high - f0) / sigma_f) - Phi((low - f0) /
sigma_f)`` (``f0`` the nominal value, ``sigma_f`` the first-order standard deviation).  A
sample whose design cannot be assembled (a non-finite figure) is out of specification.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np
from scipy.special import ndtr, ndtri

from ..solver.xla import jit
from .figures import as_batch
from .sensitivities import batch_jacobian

__all__ = ["ToleranceResult", "analyse", "monte_carlo", "wilson_interval", "yield_estimate"]


def _designs(designs: Mapping, tol: Mapping, what: str):
    """``({name: (D,)}, toleranced names, their half-widths)``: designs as ``as_batch``
    takes them (scalars broadcast), tolerances checked (``ValueError`` naming them)."""
    arrays, _ = as_batch(designs, what)
    unknown = [k for k in tol if k not in arrays]
    if unknown:
        raise ValueError(f"{what}: tolerances given for {unknown}, which are not design parameters {list(arrays)}")
    bad = [k for k, v in tol.items() if not float(v) >= 0]
    if bad:
        raise ValueError(f"{what}: tolerances must be >= 0 (half-widths, parameter units); check {bad}")
    return {k: np.asarray(v) for k, v in arrays.items()}, tuple(tol), np.array([float(tol[k]) for k in tol])


@dataclasses.dataclass(frozen=True)
class ToleranceResult:
    """First-order spread of each figure for each design (figure units).

    - `value`: ``{figure: (D,)}`` nominal values; `jacobian`: ``{figure: {param: (D,)}}``.
    - `worst`: ``{figure: (D,)}`` worst-case half-spread ``sum |J_k| t_k``.
    - `rss`: ``{figure: (D,)}`` root-sum-square ``sqrt(sum (J_k t_k)^2)``; `std` = ``rss / z``.
    - `ok`: ``(D,)`` designs whose figures and Jacobians are all finite (a figure that is
      not finite for a design has NaN spreads there; the others are kept).
    """

    value: dict
    jacobian: dict
    worst: dict
    rss: dict
    std: dict
    ok: np.ndarray
    z: float

    def table(self) -> str:
        lines = [f"{'figure':>24}  {'design':>6}  {'nominal':>12}  {'rss':>10}  {'worst':>10}"]
        for f in self.value:
            for i in range(len(self.ok)):
                lines.append(f"{f:>24}  {i:>6}  {self.value[f][i]:>12.6g}  {self.rss[f][i]:>10.4g}  {self.worst[f][i]:>10.4g}")
        return "\n".join(lines)


@dataclasses.dataclass(frozen=True)
class _Figures:
    """The user's figures as ``batch_jacobian`` takes them: ``p -> ({figure: value}, None)``;
    hashable as the function is (one compiled program per figure function)."""

    figure: Callable

    def __call__(self, p):
        return {k: jnp.asarray(x) for k, x in self.figure(p).items()}, None


def analyse(figure: Callable, designs: Mapping, tol: Mapping[str, float], *, z: float = 3.0) -> ToleranceResult:
    """Worst-case and root-sum-square spread of every figure, for a batch of designs.

    **Arguments**

    - `figure`: ``figure({name: scalar}) -> {figure name: scalar}`` for one design, in
      ``jax.numpy`` (non-finite where the design fails).  Its object identity keys the
      compiled program: build it once.
    - `designs`: ``{name: (D,) or scalar}`` every parameter the figure reads (SI units;
      scalars broadcast).
    - `tol`: ``{name: t}`` half-widths ``+-t`` (parameter units) of the toleranced
      parameters; the others are exact.
    - `z`: ``t_k = z sigma_k`` for the standard deviation (default 3).

    **Returns** a ``ToleranceResult``.
    """
    arrays, names, t = _designs(designs, tol, "analyse")
    varied = {k: jnp.asarray(arrays[k]) for k in names}
    rest = {k: jnp.asarray(v) for k, v in arrays.items() if k not in names}
    # forward mode: one tangent per toleranced parameter, however many figures
    value, _, jac = batch_jacobian(_Figures(figure), True, varied, rest)
    value = {k: np.asarray(v) for k, v in value.items()}
    jac = {k: np.stack([np.asarray(j[n]) for n in names], axis=1) for k, j in jac.items()}
    good = {k: np.isfinite(value[k]) & np.all(np.isfinite(jac[k]), axis=1) for k in value}  # per figure
    ok = np.all(list(good.values()), axis=0)
    worst = {k: np.where(good[k], np.sum(np.abs(j) * t, axis=1), np.nan) for k, j in jac.items()}
    rss = {k: np.where(good[k], np.sqrt(np.sum(np.square(j * t), axis=1)), np.nan) for k, j in jac.items()}
    return ToleranceResult(
        value=value, jacobian={k: {n: j[:, i] for i, n in enumerate(names)} for k, j in jac.items()},
        worst=worst, rss=rss, std={k: v / z for k, v in rss.items()}, ok=ok, z=float(z),
    )


@functools.partial(jit, static_argnums=(0, 1))
def _sampled(figure, names, varied, rest, dev):
    # varied (D, P), dev (M, P): figure at every design x sample, (D, M) per figure.
    def one(v, r):
        return jax.vmap(lambda d: figure({**r, **dict(zip(names, v + d))}))(dev)

    return jax.vmap(one)(varied, rest)


def monte_carlo(figure: Callable, designs: Mapping, tol: Mapping[str, float], samples: int, *, z: float = 3.0,
                seed: int = 0, chunk: int = 10_000) -> dict[str, dict[str, np.ndarray]]:
    """Sample ``dp_k ~ N(0, (t_k / z)^2)`` independently and evaluate every figure.

    Batched: every design times `chunk` samples per compiled call.  Samples where a
    figure is not finite (the design could not be assembled) are counted, not averaged.

    **Returns** ``{figure: {"mean", "std", "failed"}}`` with ``(D,)`` arrays (figure units;
    ``failed``: number of samples out of `samples` that did not evaluate).  The fraction
    within a specification, with its confidence interval: ``yield_estimate``.
    """
    arrays, names, t = _designs(designs, tol, "monte_carlo")
    if samples < 2:
        raise ValueError(f"monte_carlo: samples must be at least 2, got {samples}")
    sums: dict = {}
    shift: dict = {}
    for out in _sample_chunks(figure, arrays, names, t / z, samples, seed, chunk):
        for k, v in out.items():
            good = np.isfinite(v)
            if k not in shift:  # sums of deviations from a nearby value: no cancellation
                shift[k] = np.array([np.mean(r[g]) if np.any(g) else 0.0 for r, g in zip(v, good)])
            v0 = np.where(good, v - shift[k][:, None], 0.0)
            s = sums.setdefault(k, [0, 0.0, 0.0, 0])
            s[0] = s[0] + good.sum(axis=1)
            s[1] = s[1] + v0.sum(axis=1)
            s[2] = s[2] + np.square(v0).sum(axis=1)
            s[3] = s[3] + (~good).sum(axis=1)
    result = {}
    for k, (n, s1, s2, failed) in sums.items():
        mean = s1 / np.maximum(n, 1)
        var = np.maximum(s2 - n * np.square(mean), 0.0) / np.maximum(n - 1, 1)
        result[k] = {"mean": mean + shift[k], "std": np.sqrt(var), "failed": failed}
    return result


def _sample_chunks(figure, arrays, names, sigma, samples: int, seed: int, chunk: int):
    """``{figure: (D, m)}`` numpy values, chunk after chunk, of every design at ``samples``
    deviations ``dp ~ N(0, sigma^2)`` (the same ones for every design; the same for every
    call with the same `seed` and `chunk`)."""
    varied = jnp.asarray(np.stack([arrays[k] for k in names], axis=1))
    rest = {k: jnp.asarray(v) for k, v in arrays.items() if k not in names}
    rng = np.random.default_rng(seed)
    done = 0
    while done < samples:
        m = min(chunk, samples - done)
        dev = rng.standard_normal((chunk, len(names))) * sigma  # one shape: one compile
        out = _sampled(figure, names, varied, rest, jnp.asarray(dev))
        yield {k: np.asarray(v)[:, :m] for k, v in out.items()}
        done += m


# =========================================================================== yields
def wilson_interval(within, samples, confidence: float = 0.95):
    """Wilson score interval ``(low, high)`` of a proportion: `within` successes out of
    `samples` independent trials (arrays broadcast), at two-sided `confidence`.

    With ``z`` the standard normal quantile of ``(1 + confidence) / 2``::

        centre = (k + z^2 / 2) / (n + z^2),  half = z sqrt(k (n - k) / n + z^2 / 4) / (n + z^2)

    Unlike the normal ``p +- z sqrt(p (1 - p) / n)`` it stays inside ``[0, 1]`` and does not
    collapse to a point at ``k = 0`` or ``k = n`` (Wilson 1927; Brown, Cai & DasGupta 2001)."""
    if not 0.0 < float(confidence) < 1.0:
        raise ValueError(f"wilson_interval: confidence must be in (0, 1), e.g. 0.95; got {confidence!r}")
    k, n = np.asarray(within, float), np.asarray(samples, float)
    if np.any(n < 1) or np.any(k < 0) or np.any(k > n):
        raise ValueError("wilson_interval: need 0 <= within <= samples and samples >= 1")
    z2 = float(ndtri(0.5 + 0.5 * float(confidence))) ** 2
    centre = (k + z2 / 2) / (n + z2)
    half = np.sqrt(z2 * (k * (n - k) / n + z2 / 4)) / (n + z2)
    return np.clip(centre - half, 0.0, 1.0), np.clip(centre + half, 0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class Yield:
    """A yield with its error bars, per design (``(D,)`` arrays, fractions in ``[0, 1]``).

    - `fraction`: Monte Carlo yield ``within / samples``; `low`, `high`: its Wilson score
      interval at the estimate's confidence; `within`: samples inside the specification.
    - `linear`: the first-order estimate, the normal probability of the specification's
      interval with the nominal value as mean and the first-order standard deviation (NaN
      where the nominal design fails, and for the joint yield of several figures, whose
      first-order figures are correlated).
    """

    fraction: np.ndarray
    low: np.ndarray
    high: np.ndarray
    within: np.ndarray
    linear: np.ndarray


@dataclasses.dataclass(frozen=True)
class YieldEstimate:
    """Answer of ``yield_estimate``.

    - `figures`: ``{figure: Yield}`` each specified figure within its own limits; `joint`: a
      ``Yield`` of every specified figure within its limits at once (a made part passes).
    - `spec`: ``{figure: (low (D,), high (D,))}`` as read (figure units; +-inf: no limit).
    - `failed`: ``(D,)`` samples where a specified figure did not evaluate (out of spec).
    - `samples`, `confidence`, `z` (``t_k = z sigma_k``).
    """

    figures: dict
    joint: Yield
    spec: dict
    failed: np.ndarray
    samples: int
    confidence: float
    z: float

    def table(self) -> str:
        pct = f"{100 * self.confidence:g} %"
        lines = [f"{'figure':>16}  {'design':>6}  {'first order':>11}  {'Monte Carlo':>11}  {pct + ' interval':>19}  "
                 f"{'within':>9}  {'failed':>7}"]
        for name, y in [*self.figures.items(), ("all at once", self.joint)]:
            for i in range(len(self.failed)):
                lines.append(f"{name:>16}  {i:>6}  {y.linear[i]:>11.4f}  {y.fraction[i]:>11.4f}  "
                             f"[{y.low[i]:.4f}, {y.high[i]:.4f}]  {y.within[i]:>9d}  {self.failed[i]:>7d}")
        return "\n".join(lines) + f"\n({self.samples} samples per design)"


def _limits(spec, d: int) -> dict:
    """``{figure: (low (D,), high (D,))}`` from ``{figure: (low, high)}`` (scalars or ``(D,)``;
    None: no limit), checked: ``ValueError`` naming the figure."""
    if not isinstance(spec, Mapping) or not spec:
        raise ValueError("yield_estimate: spec must be a non-empty mapping {figure: (low, high)} in figure units")
    return {k: _pair(k, lim, d) for k, lim in spec.items()}


def _pair(name, lim, d: int):
    if not isinstance(lim, (tuple, list)) or len(lim) != 2:
        raise ValueError(f"yield_estimate: spec[{name!r}] must be a pair (low, high), None for no limit; got {lim!r}")
    bounds = []
    for v, default in zip(lim, (-np.inf, np.inf)):
        try:
            bounds.append(np.broadcast_to(np.asarray(default if v is None else v, float), (d,)))
        except (TypeError, ValueError):
            raise ValueError(f"yield_estimate: spec[{name!r}] limits must be numbers or ({d},) arrays, got {v!r}") from None
    lo, hi = bounds
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
        raise ValueError(f"yield_estimate: spec[{name!r}] needs low <= high (None for no limit), got {lim!r}")
    return lo, hi


def _normal_yield(mean, std, lo, hi):
    """Normal probability of ``[lo, hi]`` with `mean` and `std` (an indicator where ``std = 0``;
    NaN where either is not finite)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        p = ndtr((hi - mean) / std) - ndtr((lo - mean) / std)
    p = np.where(std > 0, p, ((lo <= mean) & (mean <= hi)).astype(float))
    return np.where(np.isfinite(mean) & np.isfinite(std), p, np.nan)


def _count_within(figure, arrays, names, sigma, limits, samples, seed, chunk):
    """``({figure: (D,)}, joint (D,), failed (D,))`` sample counts: inside each figure's limits
    (a non-finite value is outside), inside all of them, and not evaluated."""
    d = len(next(iter(limits.values()))[0])
    within = {k: np.zeros(d, int) for k in limits}
    joint, failed = np.zeros(d, int), np.zeros(d, int)
    for out in _sample_chunks(figure, arrays, names, sigma, samples, seed, chunk):
        every = True
        bad = False
        for k, (lo, hi) in limits.items():
            v = out[k]
            inside = np.isfinite(v) & (v >= lo[:, None]) & (v <= hi[:, None])  # NaN compares False: out
            within[k] += inside.sum(axis=1)
            every = every & inside
            bad = bad | ~np.isfinite(v)
        joint += np.sum(every, axis=1)
        failed += np.sum(bad, axis=1)
    return within, joint, failed


def _yield(within, samples, confidence, linear) -> Yield:
    low, high = wilson_interval(within, samples, confidence)
    return Yield(fraction=within / samples, low=low, high=high, within=within, linear=linear)


def yield_estimate(figure: Callable, designs: Mapping, tol: Mapping[str, float], spec: Mapping, samples: int, *,
                   z: float = 3.0, confidence: float = 0.95, seed: int = 0, chunk: int = 10_000) -> YieldEstimate:
    """The yield of each design against a specification: the fraction of made designs whose
    figures lie within ``low <= f <= high``, with error bars, beside the first-order estimate.

    **Arguments** as ``analyse`` and ``monte_carlo`` (`figure`, `designs`, `tol`, `z`,
    `seed`, `chunk`: deviations ``dp_k ~ N(0, (t_k / z)^2)``, independent), and

    - `spec`: ``{figure: (low, high)}`` limits in figure units, scalars or ``(D,)`` per
      design; None for a one-sided specification (``(None, 0.3)``: at most 0.3).
    - `samples`: designs sampled per nominal design (the interval narrows as
      ``1 / sqrt(samples)``).
    - `confidence`: two-sided confidence of the Wilson score intervals (default 0.95).

    A sample whose figure is not finite (the design cannot be assembled there) counts as
    **out of specification**, never as a NaN in the count; `failed` says how many.  The
    first-order yield (`linear`) assumes the figure normal with the nominal value as mean
    and ``analyse``'s standard deviation: it misses the curvature's bias and skew and the
    designs that fail, which the Monte Carlo yield includes.

    **Returns** a ``YieldEstimate`` (``.table()`` prints it).  For example, a coupler point's
    x within +-0.5 mm of 1.2 m and its transmission angle above 40 deg (in rad)::

        est = yield_estimate(figures, designs, tol, {"x": (1.1995, 1.2005), "mu": (0.698, None)}, 10_000)
        est.joint.fraction, est.joint.low, est.joint.high   # all at once, 95 % interval
    """
    arrays, names, t = _designs(designs, tol, "yield_estimate")
    if int(samples) < 1:
        raise ValueError(f"yield_estimate: samples must be at least 1, got {samples}")
    if not 0.0 < float(confidence) < 1.0:
        raise ValueError(f"yield_estimate: confidence must be in (0, 1), e.g. 0.95; got {confidence!r}")
    limits = _limits(spec, len(next(iter(arrays.values()))))
    first = analyse(figure, designs, tol, z=z)
    unknown = [k for k in limits if k not in first.value]
    if unknown:
        raise ValueError(f"yield_estimate: spec names {unknown}, which the figure does not return; its figures: {list(first.value)}")
    linear = {k: _normal_yield(first.value[k], first.std[k], lo, hi) for k, (lo, hi) in limits.items()}
    within, joint, failed = _count_within(figure, arrays, names, t / z, limits, int(samples), seed, chunk)
    one = next(iter(linear.values())) if len(linear) == 1 else np.full(len(failed), np.nan)
    return YieldEstimate(figures={k: _yield(within[k], int(samples), confidence, linear[k]) for k in limits},
                         joint=_yield(joint, int(samples), confidence, one), spec=limits, failed=failed,
                         samples=int(samples), confidence=float(confidence), z=float(z))
