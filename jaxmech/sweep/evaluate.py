"""One design, traceable: its motion over the stroke, its table columns, and the figures
(per-design reductions over the stroke) that a figures sweep keeps instead of the table.

Everything here works under ``jit``/``vmap``/``grad``; the sweep kernels vmap it over a
chunk of designs, and ``jaxmech.design`` differentiates it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp

from ..options import SolverOptions
from ..scenes.base import Scene
from ..scenes.columns import is_drive_column, mask_failed, table_columns
from ..scenes.evaluation import SCENE_OPTIONS, motion_and_outputs, output_units, scene_motion
from ..status import Status

__all__ = [
    "Figures",
    "batch_columns",
    "design_columns",
    "design_motion",
    "design_status",
    "is_drive_column",
    "mask_failed",
    "stroke_figures",
    "table_columns",
]


def design_motion(scene: Scene, points: int, p, *, options: SolverOptions = SCENE_OPTIONS):
    """One design's ``Motion`` over its stroke, traceable (works under ``jit``/``vmap``/``grad``):
    ``scenes.evaluation.scene_motion`` for a batch of one.

    **Arguments**

    - `scene`: the scene; `points`: samples along the stroke (both ends included).
    - `p`: ``{name: scalar}``, every parameter of the scene (SI units).

    **Returns** ``(motion, ok)``: a ``Motion`` with ``N = points`` samples (finite
    placeholders at failed samples, as ``scene_motion`` says) and the boolean ``(N,)`` mask
    of converged samples.
    """
    mo, ok = scene_motion(scene, points, {k: jnp.asarray(v)[None] for k, v in p.items()}, options)
    return jax.tree_util.tree_map(lambda x: x[0], mo), ok[0]


def design_columns(scene: Scene, points: int, p, *, options: SolverOptions = SCENE_OPTIONS):
    """One design's table columns, traceable: ``({NAME[UNIT]: (N,)}, status (N,))``.

    Columns are those of ``SceneResult.table`` (without ``status[-]``), and at failed
    samples they hold finite placeholders (see ``design_motion``): mask them with the
    status.  Used by ``jaxmech.design.scene_figure``.
    """
    cols, status = batch_columns(scene, points, {k: jnp.asarray(v)[None] for k, v in p.items()}, options)
    return {k: v[0] for k, v in cols.items()}, status[0]


def batch_columns(scene: Scene, points: int, p, options: SolverOptions = SCENE_OPTIONS):
    """The table columns of D designs (``p`` leaves ``(D,)``), traceable: ``({NAME[UNIT]:
    (D, N)}, status (D, N))``, unmasked (finite placeholders at failed samples), from
    ``motion_and_outputs``: the sweep kernels' columns, and ``run_scene``'s."""
    mo, values = motion_and_outputs(scene, points, options, scene.outputs is not None, p)
    units = output_units(scene, points, options, p) if values else {}
    return table_columns(scene, mo, {k: (values[k], u) for k, u in units.items()}), mo.status


def design_status(status, xp=jnp):
    """A design's status from its samples' ``(..., N)``: ``CONVERGED`` when every sample
    converged, else the status of the first sample along the stroke that did not (where
    the design broke).  Returns ``(...,)`` int32."""
    bad = status != Status.CONVERGED
    first = xp.argmax(bad, axis=-1)
    code = xp.take_along_axis(status, first[..., None], axis=-1)[..., 0]
    return xp.where(xp.any(bad, axis=-1), code, int(Status.CONVERGED)).astype(xp.int32)


# =========================================================================== figures
REDUCTIONS = ("max", "max_at", "min", "min_at", "travel")


@dataclasses.dataclass(frozen=True, init=False)
class Figures:
    """What a figures sweep keeps of each design: a few numbers instead of its table.

    - `columns`: table columns ``NAME[UNIT]`` to reduce over the stroke; ``None``: every
      column but the drive (time and the input with its rates).
    - `reductions`: any of ``"max"``, ``"max_at"`` (the input value at the maximum, in the
      input's unit), ``"min"``, ``"min_at"``, ``"travel"`` (max - min).  Column
      ``NAME[UNIT]`` gives ``NAME_max[UNIT]``, ``NAME_max_at[INPUT UNIT]``, ... .
    - `functions`: ``{column name: fn(columns, p) -> scalar}``, user figures written in
      ``jax.numpy`` (traced into the kernel), with the signature of
      ``jaxmech.design.scene_figure``'s `reduce`: `columns` maps ``NAME[UNIT]`` to
      ``(points,)`` arrays (finite placeholders at failed samples), `p` every parameter.

    Reductions take the sampled values (a maximum between samples is not interpolated).
    Every figure is NaN for a design that did not converge at every sample; its
    ``status[-]`` (the first failing sample's status) and ``failed_points[-]`` say why.
    Equal specifications share one compiled kernel; give user functions as module-level
    functions (an equal lambda made twice is a new kernel).
    """

    columns: tuple[str, ...] | None = None
    reductions: tuple[str, ...] = REDUCTIONS
    functions: tuple[tuple[str, Callable], ...] = ()

    def __init__(self, columns: Sequence[str] | None = None, reductions: Sequence[str] = REDUCTIONS,
                 functions: Mapping[str, Callable] | Sequence[tuple[str, Callable]] = ()):
        if isinstance(columns, str):
            raise ValueError(f"Figures: columns must be a sequence of column names, got the string {columns!r}")
        bad = [r for r in reductions if r not in REDUCTIONS]
        if bad or not reductions and not functions:
            raise ValueError(f"Figures: reductions must be among {REDUCTIONS} (at least one, or a function), got {tuple(reductions)}")
        items = tuple(functions.items()) if isinstance(functions, Mapping) else tuple(functions)
        for name, fn in items:
            if not isinstance(name, str) or not callable(fn):
                raise ValueError(f"Figures: functions must map a column name to fn(columns, p), got {name!r}: {fn!r}")
        object.__setattr__(self, "columns", None if columns is None else tuple(columns))
        object.__setattr__(self, "reductions", tuple(reductions))
        object.__setattr__(self, "functions", items)

    def check(self, scene: Scene, column_names: Sequence[str]) -> None:
        """``ValueError`` naming the unknown columns (raised while tracing, before XLA compiles)."""
        if self.columns is None:
            return
        unknown = [c for c in self.columns if c not in column_names]
        if unknown:
            raise ValueError(f"Figures: scene {scene.name!r} has no column(s) {unknown}; its columns are: {', '.join(column_names)}")


def _split(name: str) -> tuple[str, str]:
    base, _, unit = name.partition("[")
    return base, unit.rstrip("]")


def stroke_figures(scene: Scene, figures: Figures, cols: dict, status, p, xp=jnp) -> dict:
    """One design's figures: ``{name: scalar}`` with ``status[-]`` and ``failed_points[-]``.

    `cols` and `status` are one design's ``design_columns`` (finite placeholders at failed
    samples); every figure is NaN unless all samples converged.  `xp` is ``jax.numpy``
    (in the kernel) or ``numpy`` (outputs evaluated design by design).
    """
    figures.check(scene, list(cols))
    ok_all = xp.all(status == Status.CONVERGED)
    uname = scene.mechanism.inputs[0]
    u = cols[f"{uname}[{scene.units[uname]}]"]
    names = figures.columns if figures.columns is not None else [k for k in cols if not is_drive_column(scene, k)]
    out = {}
    for name in names:
        v = cols[name]
        base, unit = _split(name)
        i_max, i_min = xp.argmax(v), xp.argmin(v)
        values = {
            "max": (v[i_max], unit), "max_at": (u[i_max], scene.units[uname]),
            "min": (v[i_min], unit), "min_at": (u[i_min], scene.units[uname]),
            "travel": (v[i_max] - v[i_min], unit),
        }
        for r in figures.reductions:
            x, un = values[r]
            out[f"{base}_{r}[{un}]"] = x
    for name, fn in figures.functions:
        x = xp.asarray(fn(cols, p))
        if x.shape != ():
            raise ValueError(f"Figures: function {name!r} must return a scalar, got shape {x.shape}")
        out[name] = x
    out = {k: xp.where(ok_all, xp.asarray(v, dtype=u.dtype), xp.nan) for k, v in out.items()}
    out["status[-]"] = design_status(status, xp)
    out["failed_points[-]"] = xp.sum(status != Status.CONVERGED).astype(xp.int32)
    return out
