"""Figures: the per-design reductions over the stroke that a figures sweep keeps instead
of the table, traceable (the kernels compute them in the compiled program).

One design's motion and columns (``design_motion``, ``design_columns``, ``batch_columns``,
``design_status``) live with the scene evaluation, in ``jaxmech.scenes.columns`` (so that
``jaxmech.design`` does not import the sweeps); they are re-exported here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import jax.numpy as jnp

from ..scenes.base import Scene
from ..scenes.columns import batch_columns as batch_columns
from ..scenes.columns import design_columns as design_columns
from ..scenes.columns import design_motion as design_motion
from ..scenes.columns import design_status as design_status
from ..scenes.columns import column_names, is_drive_column, mask_failed, table_columns
from ..solver.status import Status

__all__ = [
    "Figures",
    "batch_columns",
    "design_columns",
    "design_motion",
    "design_status",
    "figure_names",
    "is_drive_column",
    "mask_failed",
    "stroke_figures",
    "table_columns",
]


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


def _reduced(scene: Scene, figures: Figures, names) -> list[tuple[str, str, str]]:
    """``(figure name, column, reduction)`` of every reduction, in column order, for table
    columns ``names``."""
    uname = scene.mechanism.inputs[0]
    columns = figures.columns if figures.columns is not None else [k for k in names if not is_drive_column(scene, k)]
    out = []
    for name in columns:
        base, unit = _split(name)
        for r in figures.reductions:
            out.append((f"{base}_{r}[{scene.units[uname] if r.endswith('_at') else unit}]", name, r))
    return out


def figure_names(scene: Scene, figures: Figures) -> list[str]:
    """The columns of a figures sweep, in order (``status[-]`` excepted), from the scene's
    declared columns (``scenes.columns.column_names``) alone."""
    return [f for f, _, _ in _reduced(scene, figures, column_names(scene))] + [n for n, _ in figures.functions] + [
        "failed_points[-]"]


def stroke_figures(scene: Scene, figures: Figures, cols: dict, status, p, xp=jnp) -> dict:
    """One design's figures: ``{name: scalar}`` with ``status[-]`` and ``failed_points[-]``.

    `cols` and `status` are one design's ``design_columns`` (finite placeholders at failed
    samples); every figure is NaN unless all samples converged.  `xp` is ``jax.numpy``
    (in the kernel) or ``numpy`` (outputs evaluated design by design).
    """
    figures.check(scene, list(cols))
    ok_all = xp.all(status == Status.CONVERGED)
    u = cols[f"{scene.mechanism.inputs[0]}[{scene.units[scene.mechanism.inputs[0]]}]"]
    out = {}
    for fname, name, r in _reduced(scene, figures, list(cols)):
        v = cols[name]
        i = xp.argmax(v) if r.startswith("max") else xp.argmin(v)
        if r == "travel":
            out[fname] = v[xp.argmax(v)] - v[xp.argmin(v)]
        else:
            out[fname] = u[i] if r.endswith("_at") else v[i]
    for name, fn in figures.functions:
        x = xp.asarray(fn(cols, p))
        if x.shape != ():
            raise ValueError(f"Figures: function {name!r} must return a scalar, got shape {x.shape}")
        out[name] = x
    out = {k: xp.where(ok_all, xp.asarray(v, dtype=u.dtype), xp.nan) for k, v in out.items()}
    out["status[-]"] = design_status(status, xp)
    out["failed_points[-]"] = xp.sum(status != Status.CONVERGED).astype(xp.int32)
    return out
