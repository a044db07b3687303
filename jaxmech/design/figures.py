"""Figures of merit from scenes, and peaks over a stroke whose gradients are right.

A *figure of merit* is any scalar function of one design's parameters, ``f(p)``, for example
the peak motor torque or the final flap angle; ``scene_figure`` builds one from a scene and
a reduction of its table columns (``scenes.evaluation``, the path of ``run_scene``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.options import SolverOptions
from ..scenes.base import Scene, as_scene
from ..scenes.evaluation import SCENE_OPTIONS
from ..scenes.columns import LazyColumns, design_motion
from ..solver.status import Status

__all__ = ["SceneFigure", "as_batch", "figure_value", "peak", "scene_figure"]


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
class _Finite(Mapping):
    """A columns mapping read through ``where(isfinite, value, 0)``: finite placeholders at
    failed samples (the figure is NaN there anyway), so no NaN reaches a gradient."""

    def __init__(self, columns: Mapping):
        self._columns = columns

    def __getitem__(self, name):
        v = self._columns[name]
        return jnp.where(jnp.isfinite(v), v, 0.0)

    def __iter__(self):
        return iter(self._columns)

    def __len__(self):
        return len(self._columns)


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
        mo, converged = design_motion(self.scene, self.points, full, options=self.options)
        ok = jnp.all(converged)
        # read lazily: a figure of the effort alone never traces every joint's reaction
        lazy = LazyColumns(self.scene, full, mo)
        value = jnp.asarray(self.reduce(_Finite(lazy), full))
        if value.shape != ():
            raise ValueError(f"figure {self.name!r}: reduce must return a scalar, got shape {value.shape}")
        ok = ok & jnp.isfinite(value)
        if lazy.outputs_status is not None:  # outputs with a status of their own: a sample jammed by joint friction
            ok = ok & jnp.all(lazy.outputs_status == Status.CONVERGED)
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

    - `scene`: the scene (its stroke, drive, guess and outputs are used as in ``run_scene``),
      a registered scene's name or a ``Linkage`` (``Linkage.scene()``).
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
    scene = as_scene(scene, "scene_figure")
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


def figure_value(out):
    """``(value, ok)`` from a figure's output (a bare value: ok where finite)."""
    if isinstance(out, tuple):
        value, ok = out
        value = jnp.asarray(value)
        return value, jnp.asarray(ok, bool) & jnp.isfinite(value)
    value = jnp.asarray(out)
    return value, jnp.isfinite(value)


def as_batch(params: Mapping, what: str) -> tuple[dict[str, jax.Array], int]:
    """``({name: (D,)}, D)``: parameters given as scalars or 1-D batches, broadcast to one
    batch size; ``ValueError`` naming `what` and the parameter otherwise."""
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


