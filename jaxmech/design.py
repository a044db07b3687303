"""Design studies on whole batches: sensitivities, peaks over a stroke, multi-start fits.

A *figure of merit* is any scalar function of one design's parameters, ``f(p)``, for
example the peak motor torque or the final flap angle.  Its derivatives come from the
implicit function theorem through the position solve (``jaxmech.solve``), never from
differentiating Newton iterations, so ``jax.grad`` of a figure is exact to the solver's
tolerance and costs about one extra stroke evaluation whatever the number of parameters.

- ``scene_figure`` builds a figure from a scene and a reduction of its table columns.
- ``sensitivities`` evaluates ``jax.vmap(jax.value_and_grad(figure))`` over a batch of
  designs and reports gradients and elasticities ``(p/f) df/dp``.
- ``peak`` takes a maximum over the stroke in a way whose gradient is right.
- ``fit`` runs optax from a batch of starting designs at once (multi-start) and says which
  start won and why each of the others stopped.

Failed designs (a sample that does not converge) are masked with ``jnp.where`` on the
*inputs* of every later computation, so a failure gives a NaN value and a NaN gradient
for that design alone, never a NaN in the gradient of a batch.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .scenes.base import Scene
from .options import SolverOptions
from .scenes.evaluation import SCENE_OPTIONS
from .status import Status
from .sweep import design_columns
from .xla import jit

__all__ = [
    "FitResult",
    "SceneFigure",
    "Sensitivities",
    "StopReason",
    "fit",
    "peak",
    "scene_figure",
    "sensitivities",
]


# =========================================================================== peaks
def peak(values, mode: str = "argmax", *, axis: int = -1, where=None, temperature=None):
    """Maximum of sampled values along a stroke, differentiable.

    **Arguments**

    - `values`: samples of a quantity along the stroke, maximum taken along `axis`.
    - `mode`:
      - ``"argmax"``: the value at the maximising sample.  Its gradient is the gradient
        of that one sample (the index is held fixed).  By the envelope theorem this is
        the derivative of the continuous maximum ``max_u f(u, p)`` when the maximum is
        interior and the stroke is finely sampled: the index is piecewise constant in
        ``p`` and the value differs from the continuous maximum by ``O(du^2)``, the
        gradient by ``O(du)`` (``du`` the sample spacing).  At a tie between two samples
        the gradient is one-sided.  For a maximum at the end of the stroke it is exact.
      - ``"smooth"``: ``T log sum exp(values / T)``, smooth in ``p`` everywhere, with
        ``max <= smooth <= max + T log N`` (``N`` samples taken): the error bound is
        ``T log N``, in the units of `values`.
    - `where`: optional boolean mask of the samples to consider (failed samples out);
      masked samples never reach a derivative.  A slice with no valid sample gives NaN.
    - `temperature`: ``T`` for ``"smooth"``, in the units of `values`.  Default:
      ``1e-3`` times the (non-differentiated) range of the valid values, so the bound is
      ``1e-3 log N`` of the range.

    **Returns** the peak, with `axis` removed.

    To take a minimum use ``-peak(-values)``.
    """
    values = jnp.asarray(values)
    mask = jnp.isfinite(values) if where is None else (jnp.asarray(where, bool) & jnp.isfinite(values))
    mask = jnp.broadcast_to(mask, values.shape)
    any_valid = jnp.any(mask, axis=axis)
    stop = jax.lax.stop_gradient
    if mode == "argmax":
        idx = jnp.argmax(jnp.where(mask, stop(values), -jnp.inf), axis=axis)
        safe = jnp.where(mask, values, 0.0)
        out = jnp.take_along_axis(safe, jnp.expand_dims(idx, axis), axis=axis)
        out = jnp.squeeze(out, axis)
    elif mode == "smooth":
        hi = jnp.max(jnp.where(mask, stop(values), -jnp.inf), axis=axis, keepdims=True)
        lo = jnp.min(jnp.where(mask, stop(values), jnp.inf), axis=axis, keepdims=True)
        if temperature is None:
            span = jnp.where(jnp.isfinite(hi - lo), hi - lo, 0.0)
            t = 1e-3 * jnp.where(span > 0, span, jnp.maximum(jnp.abs(jnp.where(jnp.isfinite(hi), hi, 0.0)), 1.0))
        else:
            t = jnp.asarray(temperature, values.dtype)
            if not isinstance(temperature, jax.core.Tracer) and np.any(np.asarray(temperature) <= 0):
                raise ValueError(f"peak: temperature must be positive, got {temperature!r}")
        t = jnp.broadcast_to(t, hi.shape)
        ref = jnp.where(jnp.isfinite(hi), hi, 0.0)
        z = jnp.where(mask, (values - ref) / t, 0.0)  # mask the inputs: no exp of NaN anywhere
        out = jnp.squeeze(ref, axis) + jnp.squeeze(t, axis) * jax.nn.logsumexp(z, axis=axis, b=mask.astype(values.dtype))
    else:
        raise ValueError(f"peak: mode must be 'argmax' or 'smooth', got {mode!r}")
    return jnp.where(any_valid, out, jnp.nan)


# =========================================================================== figures
@dataclasses.dataclass(frozen=True)
class SceneFigure:
    """A scalar figure of merit of one scene design: ``f(p) -> (value, ok)``.

    Built by ``scene_figure``; hashable, so jitted callers compile once per figure.
    Calling it with ``{name: scalar}`` (any subset of the scene's parameters; the others
    from `fixed`, then the scene defaults) runs the design over its stroke exactly as
    ``run_scene`` does and applies ``reduce(columns, p)``.

    ``ok`` is False when any sample of the stroke did not converge, or the value is not
    finite; then ``value`` is NaN and its gradient is zero (the placeholders that stand
    in for failed samples keep every intermediate finite).
    """

    scene: Scene
    reduce: Callable
    points: int = 101
    fixed: tuple = ()
    options: SolverOptions = SCENE_OPTIONS
    name: str = "f"

    def __call__(self, p: Mapping):
        unknown = [k for k in p if k not in self.scene.defaults]
        if unknown:
            raise ValueError(f"figure {self.name!r}: scene {self.scene.name!r} has no parameter(s) {unknown}")
        fixed = dict(self.fixed)
        dtype = jnp.result_type(*[jnp.asarray(v) for v in p.values()], float)
        full = {k: jnp.asarray(p[k] if k in p else fixed.get(k, v), dtype) for k, v in self.scene.defaults.items()}
        cols, status = design_columns(self.scene, self.points, full, options=self.options)
        ok = jnp.all(status == Status.CONVERGED)
        cols = {k: jnp.where(jnp.isfinite(v), v, 0.0) for k, v in cols.items()}
        value = jnp.asarray(self.reduce(cols, full))
        if value.shape != ():
            raise ValueError(f"figure {self.name!r}: reduce must return a scalar, got shape {value.shape}")
        ok = ok & jnp.isfinite(value)
        return jnp.where(ok, value, jnp.nan), ok


def scene_figure(
    scene: Scene,
    reduce: Callable,
    *,
    points: int = 101,
    fixed: Mapping[str, float] | None = None,
    options: SolverOptions = SCENE_OPTIONS,
    name: str | None = None,
) -> SceneFigure:
    """A figure of merit from a scene: a reduction of its table over the stroke.

    **Arguments**

    - `scene`: the scene (its stroke, drive, guess and outputs are used as in ``run_scene``).
    - `reduce`: ``reduce(columns, p) -> scalar``; `columns` maps ``NAME[UNIT]`` (the
      names of ``SceneResult.table``, status excepted) to ``(points,)`` arrays, `p` maps
      every parameter name to a scalar.  Examples:
      ``lambda c, p: c["theta4[rad]"][-1]`` (final rocker angle, rad),
      ``lambda c, p: peak(jnp.abs(c["torque[N m]"]))`` (peak torque, N m).
      It must be written in ``jax.numpy`` and be finite on finite columns.
    - `points`: samples along the stroke (both ends included).
    - `fixed`: values for parameters that are not passed to the figure (default: the
      scene defaults).
    - `name`: for tables and messages (default: ``reduce.__name__``).

    **Returns** a ``SceneFigure``: ``f(p) -> (value, ok)``.  Build it once and reuse it:
    jitted callers compile once per figure object.
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"scene_figure: scene must be a Scene, got {type(scene).__name__}")
    if not callable(reduce):
        raise ValueError("scene_figure: reduce must be a function reduce(columns, p) -> scalar")
    fixed = dict(fixed or {})
    unknown = [k for k in fixed if k not in scene.defaults]
    if unknown:
        raise ValueError(f"scene_figure: scene {scene.name!r} has no parameter(s) {unknown}")
    if points < 2:
        raise ValueError(f"scene_figure: points must be at least 2, got {points}")
    if name is None:
        name = getattr(reduce, "__name__", "f")
        name = "f" if name == "<lambda>" else name
    return SceneFigure(scene, reduce, int(points), tuple(sorted((k, float(v)) for k, v in fixed.items())), options, name)


def _split(out):
    """``(value, ok)`` from a figure's output (a bare value: ok where finite)."""
    if isinstance(out, tuple):
        value, ok = out
        value = jnp.asarray(value)
        return value, jnp.asarray(ok, bool) & jnp.isfinite(value)
    value = jnp.asarray(out)
    return value, jnp.isfinite(value)


def _as_batch(params: Mapping, what: str) -> tuple[dict[str, jax.Array], int]:
    if not isinstance(params, Mapping) or not params:
        raise ValueError(f"{what}: give a non-empty mapping {{parameter name: (D,) values}}")
    arrays = {k: jnp.atleast_1d(jnp.asarray(v, jnp.result_type(float))) for k, v in params.items()}
    for k, v in arrays.items():
        if v.ndim != 1:
            raise ValueError(f"{what}: parameter {k!r} must be a scalar or a 1-D batch, got shape {v.shape}")
    sizes = {v.shape[0] for v in arrays.values()}
    d = max(sizes)
    if not sizes <= {1, d}:
        raise ValueError(f"{what}: batch sizes differ: { {k: v.shape[0] for k, v in arrays.items()} }")
    return {k: jnp.broadcast_to(v, (d,)) for k, v in arrays.items()}, d


# =========================================================================== sensitivities
@dataclasses.dataclass(frozen=True)
class Sensitivities:
    """Gradients of a figure of merit for a batch of designs.

    - `figure`: the figure's name.
    - `params`: ``{name: (D,)}`` the designs.
    - `value`: ``(D,)`` the figure (NaN where the design failed).
    - `grad`: ``{name: (D,)}`` ``df/dp`` in figure units per parameter unit (NaN where
      the design failed).
    - `ok`: ``(D,)`` designs whose figure is defined (every sample converged).
    """

    figure: str
    params: dict
    value: np.ndarray
    grad: dict
    ok: np.ndarray

    @property
    def elasticity(self) -> dict[str, np.ndarray]:
        """Normalised sensitivities ``(p / f) df/dp`` (dimensionless: % change of f per %
        change of p); NaN where ``f == 0`` or the design failed."""
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(self.value != 0, self.value, np.nan)
            return {k: self.params[k] * g / f for k, g in self.grad.items()}

    def table(self, kind: str = "elasticity", max_rows: int = 20) -> str:
        """Readable text table, one row per design (at most `max_rows`).

        `kind`: ``"elasticity"`` (``(p/f) df/dp``) or ``"gradient"`` (``df/dp``).
        """
        if kind not in ("elasticity", "gradient"):
            raise ValueError(f"table: kind must be 'elasticity' or 'gradient', got {kind!r}")
        data = self.elasticity if kind == "elasticity" else self.grad
        title = "(p/f) df/dp" if kind == "elasticity" else "df/dp"
        names = list(data)
        width = max(12, *(len(n) + 2 for n in names))
        lines = [f"{kind} {title} of {self.figure}", f"{'design':>6}  {self.figure:>14}" + "".join(f"{n:>{width}}" for n in names)]
        d = len(self.value)
        for i in range(min(d, max_rows)):
            if not self.ok[i]:
                lines.append(f"{i:>6}  {'failed':>14}  (a sample did not converge: no figure, no gradient)")
                continue
            lines.append(f"{i:>6}  {self.value[i]:>14.6g}" + "".join(f"{data[n][i]:>{width}.4g}" for n in names))
        if d > max_rows:
            lines.append(f"... {d - max_rows} more designs")
        return "\n".join(lines)


@functools.partial(jit, static_argnums=(0, 1))
def _value_and_grad_batch(figure, wrt, p_wrt, p_rest):
    def masked(pw, pr):
        value, ok = _split(figure({**pr, **pw}))
        # Differentiate the masked value: a failed design contributes a zero cotangent.
        return jnp.where(ok, value, 0.0), (value, ok)

    (_, (value, ok)), grad = jax.vmap(jax.value_and_grad(masked, has_aux=True))(p_wrt, p_rest)
    return value, ok, grad


def sensitivities(figure: Callable, params: Mapping, *, wrt: Sequence[str] | None = None) -> Sensitivities:
    """Gradient of a scalar figure of merit w.r.t. every parameter, for a batch of designs.

    Computed as ``jax.vmap(jax.value_and_grad(figure))`` in one compiled call; the
    derivatives of the positions come from the implicit function theorem.

    **Arguments**

    - `figure`: ``f(p) -> value`` or ``-> (value, ok)`` for one design, ``p`` a mapping
      of scalars, written in ``jax.numpy`` (for a scene: ``scene_figure``).  A value that
      is not finite, or ``ok`` False, marks the design failed.  A figure must mask the
      inputs of its own computations where it fails (``scene_figure`` does).
    - `params`: ``{name: (D,) or scalar}`` the designs (SI units); scalars broadcast.
    - `wrt`: names to differentiate with respect to (default: every name in `params`).

    **Returns** a ``Sensitivities`` (values, gradients, elasticities, a text table).
    """
    batch, _ = _as_batch(params, "sensitivities")
    wrt = tuple(batch) if wrt is None else tuple(wrt)
    unknown = [k for k in wrt if k not in batch]
    if unknown:
        raise ValueError(f"sensitivities: wrt names {unknown} are not in params {list(batch)}")
    p_wrt = {k: batch[k] for k in wrt}
    p_rest = {k: v for k, v in batch.items() if k not in wrt}
    value, ok, grad = _value_and_grad_batch(figure, wrt, p_wrt, p_rest)
    ok = np.asarray(ok)
    value = np.where(ok, np.asarray(value), np.nan)
    grad = {k: np.where(ok, np.asarray(grad[k]), np.nan) for k in wrt}
    return Sensitivities(
        figure=getattr(figure, "name", getattr(figure, "__name__", "f")),
        params={k: np.asarray(v) for k, v in batch.items()},
        value=value,
        grad=grad,
        ok=ok,
    )


# =========================================================================== fitting
class StopReason(enum.IntEnum):
    """Why one start of a multi-start fit stopped.

    - ``CONVERGED``: a step changed the objective by at most ``tol`` (relative) and every
      parameter by at most ``xtol`` (relative).
    - ``MAX_STEPS``: the step budget ran out while still moving.
    - ``INFEASIBLE``: the objective was not finite or the design failed to solve (a
      status other than converged); the start stopped at its last feasible design.
    - ``DIVERGED``: a parameter or the gradient became non-finite, or the objective grew
      beyond ``diverge`` times its starting magnitude.
    """

    CONVERGED = 0
    MAX_STEPS = 1
    INFEASIBLE = 2
    DIVERGED = 3


_STOP_MESSAGES = {
    StopReason.CONVERGED: "converged: objective and parameter changes below tolerance",
    StopReason.MAX_STEPS: "ran out of steps while still improving",
    StopReason.INFEASIBLE: "infeasible: objective not finite or the design did not solve; kept the last feasible design",
    StopReason.DIVERGED: "diverged: non-finite parameters or gradient, or the objective blew up",
}


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Result of a multi-start fit.

    - `params`: ``{name: (S,)}`` each start's final (last feasible) parameters.
    - `value`: ``(S,)`` objective there (``inf`` where even the start was infeasible).
    - `reason`: ``(S,)`` ``StopReason`` codes; `steps`: ``(S,)`` steps taken.
    - `history`: ``(steps + 1, S)`` objective after each step (once a start has stopped
      its last value is repeated; ``inf`` for a start infeasible from the beginning).
    - `best`: index of the winning start (lowest objective among those that neither
      diverged nor were infeasible from the start), ``-1`` if none.
    """

    params: dict
    value: np.ndarray
    reason: np.ndarray
    steps: np.ndarray
    history: np.ndarray
    best: int
    tol: float
    xtol: float

    @property
    def best_params(self) -> dict[str, float]:
        """The winning start's parameters as ``{name: float}`` (``ValueError`` if none won)."""
        if self.best < 0:
            raise ValueError("fit: no start produced a feasible design")
        return {k: float(v[self.best]) for k, v in self.params.items()}

    def message(self, i: int) -> str:
        """Why start ``i`` stopped, in words."""
        r = StopReason(int(self.reason[i]))
        msg = _STOP_MESSAGES[r]
        if r == StopReason.INFEASIBLE and self.steps[i] == 0:
            msg = "infeasible at the start: objective not finite or the design did not solve"
        elif r == StopReason.CONVERGED:
            msg += f" (tol={self.tol:g}, xtol={self.xtol:g})"
        return msg

    def report(self) -> str:
        """Which start won, and why each of the others stopped."""
        n = len(self.value)
        lines = []
        if self.best >= 0:
            b = self.best
            lines.append(
                f"fit: {n} starts; start {b} won with objective {self.value[b]:.6g} after {int(self.steps[b])} steps "
                f"({self.message(b)})"
            )
            lines.append("  " + ", ".join(f"{k} = {v:.10g}" for k, v in self.best_params.items()))
        else:
            lines.append(f"fit: {n} starts; none produced a feasible design")
        lines.append(f"{'start':>5}  {'objective':>14}  {'steps':>5}  why it stopped")
        for i in range(n):
            tag = "  <- winner" if i == self.best else ""
            lost = ""
            if i != self.best and self.best >= 0 and np.isfinite(self.value[i]):
                lost = f"; lost by {self.value[i] - self.value[self.best]:.3g}"
            lines.append(f"{i:>5}  {self.value[i]:>14.6g}  {int(self.steps[i]):>5}  {self.message(i)}{lost}{tag}")
        return "\n".join(lines)


def fit(
    objective: Callable,
    p0: Mapping,
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    optimizer=None,
    steps: int = 200,
    tol: float = 1e-12,
    xtol: float = 1e-9,
    penalty: Callable | None = None,
    penalty_weight: float = 1e3,
    diverge: float = 1e8,
) -> FitResult:
    """Minimise an objective from a batch of starting designs at once (multi-start, optax).

    Every start runs the same optimiser, vmapped, in one compiled loop; each start stops
    on its own (converged, infeasible, diverged) while the others go on.

    **Arguments**

    - `objective`: ``f(p) -> value`` or ``-> (value, ok)`` for one design, ``p`` a mapping
      name -> scalar (e.g. a ``scene_figure``).  Not finite, or ``ok`` False: infeasible.
      It must mask the inputs of its own computations where it fails (see
      ``scene_figure``) so that no NaN reaches a gradient.
    - `p0`: ``{name: (S,)}`` the starting designs (scalars broadcast).
    - `bounds`: ``{name: (low, high)}``, enforced by projection: after every step the
      parameters are clipped into the box.  (A line search may still evaluate outside
      the box; it sees ``inf`` where that is infeasible.)
    - `optimizer`: an ``optax`` transformation; default ``optax.lbfgs()`` (with its zoom
      line search, which receives the objective as ``value_fn``).  The compiled loop is
      keyed on the objective and optimizer objects: reuse them to avoid recompiling.
    - `steps`: iteration budget per start.
    - `tol`, `xtol`: a start has converged when one step changes the objective by at most
      ``tol * max(|f|, tiny)`` and every parameter by at most ``xtol * max(|p|, tiny)``.
    - `penalty`: general constraints ``g(p) <= 0`` as ``penalty(p) -> array g``; added to
      the objective as ``penalty_weight * sum(max(g, 0)^2)`` (a quadratic exterior
      penalty: the optimum violates a constraint by ``O(1/penalty_weight)``).
    - `diverge`: a start whose objective exceeds ``diverge * max(|f0|, 1)`` diverged.

    **Returns** a ``FitResult``: the winner, each start's final design and stop reason,
    and ``report()`` in words.
    """
    batch, s = _as_batch(p0, "fit")
    names = tuple(batch)
    bounds = dict(bounds or {})
    unknown = [k for k in bounds if k not in batch]
    if unknown:
        raise ValueError(f"fit: bounds for unknown parameter(s) {unknown}; parameters are {list(names)}")
    lo, hi = {}, {}
    for k in names:
        a, b = bounds.get(k, (-np.inf, np.inf))
        if not float(a) <= float(b):
            raise ValueError(f"fit: bounds of {k!r} must satisfy low <= high, got {bounds[k]}")
        lo[k], hi[k] = float(a), float(b)
    if steps < 1:
        raise ValueError(f"fit: steps must be at least 1, got {steps}")
    opt = _default_optimizer() if optimizer is None else optax.with_extra_args_support(optimizer)
    p_start = {k: jnp.clip(v, lo[k], hi[k]) for k, v in batch.items()}
    params, value, reason, nsteps, history = _fit_loop(
        objective, opt, penalty, float(penalty_weight), float(diverge), float(tol), float(xtol), int(steps),
        tuple(sorted(lo.items())), tuple(sorted(hi.items())), p_start,
    )
    value = np.asarray(value)
    reason = np.asarray(reason)
    usable = np.isfinite(value) & (reason != StopReason.DIVERGED)
    best = int(np.argmin(np.where(usable, value, np.inf))) if np.any(usable) else -1
    return FitResult(
        params={k: np.asarray(v) for k, v in params.items()},
        value=value,
        reason=reason,
        steps=np.asarray(nsteps),
        history=np.asarray(history),
        best=best,
        tol=tol,
        xtol=xtol,
    )


@functools.lru_cache(maxsize=1)
def _default_optimizer():
    # One object for every call: the compiled fit loop is keyed on the optimizer's identity.
    return optax.with_extra_args_support(optax.lbfgs())


@functools.partial(jit, static_argnums=tuple(range(10)))
def _fit_loop(objective, opt, penalty, weight, diverge, tol, xtol, steps, lo, hi, p0):
    lo, hi = dict(lo), dict(hi)
    tiny = jnp.finfo(jnp.result_type(float)).tiny

    def total(p):
        value, ok = _split(objective(p))
        if penalty is not None:
            g = jnp.ravel(jnp.asarray(penalty(p)))
            value = value + weight * jnp.sum(jnp.square(jnp.maximum(g, 0.0)))
        ok = ok & jnp.isfinite(value)
        # inf tells the line search "outside the domain"; the gradient of the masked
        # value is zero there (the objective masks its own inputs).
        return jnp.where(ok, value, jnp.inf), ok

    value_and_grad = jax.value_and_grad(total, has_aux=True)
    value_fn = lambda p: total(p)[0]  # noqa: E731

    def clip(p):
        return {k: jnp.clip(v, lo[k], hi[k]) for k, v in p.items()}

    def finite(tree):
        return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]))

    def start(p):
        (v, ok), g = value_and_grad(p)
        state = opt.init(p)
        reason = jnp.where(ok, StopReason.MAX_STEPS, StopReason.INFEASIBLE).astype(jnp.int32)
        return p, state, v, g, ok, reason, jnp.abs(v)

    def step(p, state, v, g, active, reason, v0):
        updates, new_state = opt.update(g, state, p, value=v, grad=g, value_fn=value_fn)
        p_new = clip(optax.apply_updates(p, updates))
        (v_new, ok_new), g_new = value_and_grad(p_new)
        diverged = ~finite(p_new) | (ok_new & (~finite(g_new) | (v_new > diverge * jnp.maximum(v0, 1.0))))
        infeasible = ~ok_new & ~diverged
        small_f = jnp.abs(v_new - v) <= tol * jnp.maximum(jnp.abs(v_new), tiny)
        small_x = jnp.all(jnp.stack([
            jnp.abs(p_new[k] - p[k]) <= xtol * jnp.maximum(jnp.abs(p_new[k]), tiny) for k in p
        ]))
        converged = ok_new & ~diverged & small_f & small_x
        accept = active & ok_new & ~diverged
        sel = lambda a, b: jax.tree_util.tree_map(lambda x, y: jnp.where(accept, x, y), a, b)  # noqa: E731
        p, state, v, g = sel(p_new, p), sel(new_state, state), sel(v_new, v), sel(g_new, g)
        reason = jnp.where(
            active,
            jnp.where(diverged, StopReason.DIVERGED, jnp.where(infeasible, StopReason.INFEASIBLE,
                      jnp.where(converged, StopReason.CONVERGED, StopReason.MAX_STEPS))),
            reason,
        ).astype(jnp.int32)
        return p, state, v, g, active & ~(diverged | infeasible | converged), reason

    p, state, v, g, active, reason, v0 = jax.vmap(start)(p0)
    s = v.shape[0]
    history = jnp.full((steps + 1, s), jnp.inf, v.dtype).at[0].set(v)
    nsteps = jnp.zeros((s,), jnp.int32)

    def cond(carry):
        k, *_, active, _reason, _n, _h = carry
        return (k < steps) & jnp.any(active)

    def body(carry):
        k, p, state, v, g, active, reason, nsteps, history = carry
        p, state, v, g, active_new, reason = jax.vmap(step)(p, state, v, g, active, reason, v0)
        nsteps = nsteps + active.astype(jnp.int32)
        history = history.at[k + 1].set(v)
        return k + 1, p, state, v, g, active_new, reason, nsteps, history

    k, p, state, v, g, active, reason, nsteps, history = jax.lax.while_loop(
        cond, body, (0, p, state, v, g, active, reason, nsteps, history)
    )
    # Rows after the loop ended repeat the final values.
    rows = jnp.arange(steps + 1)[:, None]
    history = jnp.where(rows <= k, history, v[None, :])
    return p, v, reason, nsteps, history
