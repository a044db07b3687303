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
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..xla import jit
from .figures import as_batch
from .sensitivities import batch_jacobian

__all__ = ["ToleranceResult", "analyse", "monte_carlo"]


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
    ``failed``: number of samples out of `samples` that did not evaluate).
    """
    arrays, names, t = _designs(designs, tol, "monte_carlo")
    if samples < 2:
        raise ValueError(f"monte_carlo: samples must be at least 2, got {samples}")
    varied = jnp.asarray(np.stack([arrays[k] for k in names], axis=1))
    rest = {k: jnp.asarray(v) for k, v in arrays.items() if k not in names}
    rng = np.random.default_rng(seed)
    sums: dict = {}
    shift: dict = {}
    done = 0
    while done < samples:
        m = min(chunk, samples - done)
        dev = rng.standard_normal((chunk, len(names))) * (t / z)  # one shape: one compile
        out = _sampled(figure, names, varied, rest, jnp.asarray(dev))
        for k, v in out.items():
            v = np.asarray(v)[:, :m]
            good = np.isfinite(v)
            if k not in shift:  # sums of deviations from a nearby value: no cancellation
                shift[k] = np.array([np.mean(r[g]) if np.any(g) else 0.0 for r, g in zip(v, good)])
            v0 = np.where(good, v - shift[k][:, None], 0.0)
            s = sums.setdefault(k, [0, 0.0, 0.0, 0])
            s[0] = s[0] + good.sum(axis=1)
            s[1] = s[1] + v0.sum(axis=1)
            s[2] = s[2] + np.square(v0).sum(axis=1)
            s[3] = s[3] + (~good).sum(axis=1)
        done += m
    result = {}
    for k, (n, s1, s2, failed) in sums.items():
        mean = s1 / np.maximum(n, 1)
        var = np.maximum(s2 - n * np.square(mean), 0.0) / np.maximum(n - 1, 1)
        result[k] = {"mean": mean + shift[k], "std": np.sqrt(var), "failed": failed}
    return result
