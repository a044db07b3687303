"""From a sweep to refined designs in one call: the best designs of a sweep as the starts of
an exact-Hessian SQP over a scene's stroke.

A design sweep (``jaxmech.sweep``) finds where designs work and ranks them by a figure; the
step after it refines the best few under the same statement, stated once:

- ``scene_problem(scene, bounds, peak=..., limits=...)``: the ``StrokeProblem`` of a scene
  (or a ``Linkage``): the design variables are the names of `bounds`, every other parameter
  keeps the scene's default; the stroke is the scene's, sampled at `points` inputs and
  followed by continuation from the scene's guess (so the assembly mode is the scene's);
  `peak` and `limits` read the scene's table columns (``NAME[UNIT]``, as ``run_scene`` and
  sweeps name them) at every sample.
- ``refine(scene, designs, bounds, peak=..., limits=..., best=K, rank=FIGURE)``: the `best`
  designs of a sweep result, a sweep's Parquet dataset (``read_dataset(folder)``) or a
  table (those that converged, within `where`, least `rank` first) refined in one ``minimize_second_order`` call (every
  start in one vmapped program, the Lagrangian's Hessian by the second-order adjoint).

A trial design whose stroke does not close at every sample is not assembled: the SQP
shortens its step.  Nothing here repairs gaps: a refined design assembles over its whole
stroke on the scene's branch, or its start says why not.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..scenes.base import as_scene
from ..scenes.columns import LazyColumns, column_names
from ..scenes.evaluation import SCENE_OPTIONS
from ..solver.status import Status
from .constrained import Stated
from .second_order import SecondOrderResult, minimize_second_order
from .sqp import SQPOptions
from .stroke_problem import StrokeProblem

__all__ = ["scene_problem", "refine", "best_designs"]


def _reader(scene, what, label: str) -> Callable:
    """``fn(columns, p) -> array`` for a column name or a function (checked by name now)."""
    if callable(what):
        return what
    if isinstance(what, str):
        names = column_names(scene)
        if what not in names:
            raise ValueError(f"{label}: scene {scene.name!r} has no column {what!r}; its columns are: {', '.join(names)}")
        return lambda columns, p: columns[what]
    raise ValueError(f"{label}: give a column name NAME[UNIT] or a function fn(columns, p) -> values, got {what!r}")


def _limit_rows(scene, limits: Mapping) -> list:
    """``[(fn, low, high)]`` of ``limits = {name: (what, low, high)}`` (None: no bound)."""
    out = []
    for name, spec in (limits or {}).items():
        if not (isinstance(spec, (tuple, list)) and len(spec) == 3):
            raise ValueError(f"limits[{name!r}]: give (column or fn(columns, p), low, high) with None for an open side, got {spec!r}")
        what, low, high = spec
        if low is None and high is None:
            raise ValueError(f"limits[{name!r}]: give at least one of low and high")
        out.append((_reader(scene, what, f"limits[{name!r}]"), low, high))
    return out


def _stroke(scene, base: dict, bounds: Mapping, points: int):
    """The scene's stroke ``{us, u_dot, u_ddot, t}`` (inputs, rates, times) at the base
    design; ``ValueError`` if the stroke moves with a design variable (a corner of the box)."""
    u0, u1 = (float(v) for v in scene.stroke(base))
    for corner in ({k: lo for k, (lo, _) in bounds.items()}, {k: hi for k, (_, hi) in bounds.items()}):
        c0, c1 = (float(v) for v in scene.stroke({**base, **corner}))
        if not np.allclose([c0, c1], [u0, u1], rtol=1e-12, atol=1e-12):
            raise ValueError(f"scene_problem: scene {scene.name!r}'s stroke moves with the design variables "
                             f"({u0:.6g}..{u1:.6g} at the defaults, {c0:.6g}..{c1:.6g} at a corner of the bounds); "
                             "a refined stroke problem needs a fixed stroke")
    w = abs(float(scene.speed)) * (1.0 if u1 >= u0 else -1.0)
    t = np.linspace(0.0, (u1 - u0) / w, points)
    return {"us": u0 + w * t, "u_dot": np.full(points, w), "u_ddot": np.zeros(points), "t": t}


def scene_problem(scene, bounds: Mapping[str, tuple[float, float]], *, peak, limits: Mapping | None = None,
                  points: int = 37, options=SCENE_OPTIONS) -> StrokeProblem:
    """The ``StrokeProblem`` of a scene: least peak of `peak` over the stroke, `limits` at
    every sample.

    **Arguments**

    - `scene`: a ``Scene``, a scene name or a ``Linkage`` (``Linkage.scene()`` sets its
      stroke and speed).
    - `bounds`: ``{name: (low, high)}``: the design variables (parameters of the scene, SI
      units) and their box; every other parameter keeps the scene's default (a
      ``Linkage``'s centres of mass and inertias follow its lengths).
    - `peak`: a table column ``NAME[UNIT]`` whose largest absolute value over the stroke is
      minimised (``"effort_theta_crank[N m]"``: the peak crank torque), or ``fn(columns,
      p) -> values`` whose largest entry is (``columns``: ``{NAME[UNIT]: (points,)}`` at
      the stroke's samples, ``p``: every parameter).
    - `limits`: ``{name: (column or fn, low, high)}``: ``low <= values <= high`` at every
      sample (None: an open side), e.g. ``{"transmission": (sin_mu, 0.5, None)}``.
    - `points`: samples along the stroke, both ends included.

    **Returns** a ``StrokeProblem`` (its stroke followed by continuation from the scene's
    guess) for ``minimize_second_order``.
    """
    scene = as_scene(scene, "scene_problem")
    if scene.mechanism.dof != 1:
        raise ValueError(f"scene_problem: scene {scene.name!r} has {scene.mechanism.dof} inputs; a scene's stroke has one")
    if not isinstance(bounds, Mapping) or not bounds:
        raise ValueError("scene_problem: bounds must be a non-empty mapping {name: (low, high)} of the design variables")
    unknown = [k for k in bounds if k not in scene.defaults]
    if unknown:
        raise ValueError(f"scene_problem: scene {scene.name!r} has no parameter(s) {unknown}; its parameters are: {', '.join(scene.defaults)}")
    if int(points) < 2:
        raise ValueError(f"scene_problem: points must be at least 2 (both ends of the stroke), got {points}")
    base = {k: float(v) for k, v in scene.defaults.items()}
    stroke = _stroke(scene, base, bounds, int(points))
    if isinstance(peak, str):
        col = _reader(scene, peak, "peak")
        peak_fn = lambda c, p: jnp.stack([col(c, p), -col(c, p)])  # noqa: E731 - |x| as two smooth rows
    else:
        peak_fn = _reader(scene, peak, "peak")
    rows_le = _limit_rows(scene, limits)

    def rows(p, mo):
        cols = LazyColumns(scene, p, mo)
        le = []
        for fn, low, high in rows_le:
            v = jnp.ravel(fn(cols, p))
            if low is not None:
                le.append(low - v)
            if high is not None:
                le.append(v - high)
        stated = Stated(peak=jnp.ravel(peak_fn(cols, p)), le=jnp.concatenate(le) if le else None)
        if cols.outputs_status is not None:  # a sample jammed by joint friction: no finite row, so the design is not ok
            held = jnp.all(cols.outputs_status == Status.CONVERGED)
            rows_ = {f: jnp.where(held, v, jnp.nan) for f, v in zip(stated._fields, stated) if f in ("peak", "le") and v is not None}
            stated = stated._replace(**rows_, ok=held)
        return stated

    return StrokeProblem(mechanism=scene.mechanism, names=tuple(bounds), params=lambda x: {**base, **x}, **stroke,
                         guess=lambda p, u: jnp.asarray(scene.guess(p)), rows=rows, options=options, continuation=True)


def _table(designs) -> dict:
    """``{column: (D,) numpy}`` of a sweep's designs: a ``SweepResult`` (its parameters and
    per-point statuses), a table read from a dataset (``jaxmech.sweep.read_dataset``: a
    ``pyarrow.Table``; or a pandas ``DataFrame``), or ``{column: (D,)}``.  (The design layer
    reads what a sweep returns; it does not import the sweeps.)"""
    if hasattr(designs, "params") and hasattr(designs, "status") and hasattr(designs, "columns"):  # a SweepResult
        return {**{k: np.asarray(v) for k, v in designs.params.items()}, "status": np.asarray(designs.status)}
    if hasattr(designs, "column_names") and hasattr(designs, "column"):  # a pyarrow Table
        return {k: designs.column(k).to_numpy(zero_copy_only=False) for k in designs.column_names}
    if hasattr(designs, "to_dict") and hasattr(designs, "columns"):  # a pandas DataFrame
        return {k: designs[k].to_numpy() for k in designs.columns}
    if isinstance(designs, Mapping):
        return {k: np.asarray(v) for k, v in designs.items()}
    raise ValueError("designs: give a sweep's result (sweep_scene), its dataset as a table (jaxmech.sweep.read_dataset(folder)) "
                     f"or a mapping {{column: (D,) values}}, got {type(designs).__name__}")


def best_designs(designs, names, *, best: int = 256, rank: str | None = None, where: Mapping | None = None) -> dict:
    """The `best` rows of a sweep (a ``SweepResult``, a dataset read by ``read_dataset``, or
    ``{column: (D,)}``)
    as ``{name: (K,)}`` plus ``"row"`` (their row numbers): rows that converged
    at every sample (``status``: a dataset's per design, a ``SweepResult``'s per point),
    within every ``where = {column: (low, high)}`` (None: open), least `rank` first (the
    table's order without one)."""
    return _pick(_table(designs), tuple(names), best, rank, where)


def _pick(table: dict, names: tuple, best: int, rank, where) -> dict:
    if int(best) < 1:
        raise ValueError(f"best_designs: best must be at least 1 (how many designs to take), got {best}")
    missing = [k for k in (*names, *(where or {}), *([rank] if rank else [])) if k not in table]
    if missing:
        raise ValueError(f"best_designs: the designs have no column(s) {missing}; their columns are: {', '.join(table)}")
    n = len(next(iter(table.values())))
    keep = np.ones(n, bool)
    if "status" in table:
        status = np.asarray(table["status"])
        ok = (status == Status.CONVERGED) if status.dtype.kind in "iu" else (status == Status.CONVERGED.name)
        keep &= np.all(ok.reshape(n, -1), axis=1)  # a sweep result's (D, N) points, a dataset's (D,)
    for col, (low, high) in (where or {}).items():
        v = np.asarray(table[col], float)
        keep &= np.isfinite(v) & (v >= (-np.inf if low is None else low)) & (v <= (np.inf if high is None else high))
    rows = np.flatnonzero(keep)
    if rank is not None:
        v = np.asarray(table[rank], float)[rows]
        rows = rows[np.argsort(np.where(np.isfinite(v), v, np.inf), kind="stable")]
    rows = rows[: int(best)]
    if rows.size == 0:
        raise ValueError("best_designs: no design converged within `where`; widen the sweep or the filter")
    picked = {k: np.asarray(table[k], float)[rows] for k in names}
    if rank is not None:
        picked[rank] = np.asarray(table[rank], float)[rows]
    return {**picked, "row": rows}


def refine(scene, designs, bounds: Mapping[str, tuple[float, float]], *, peak, limits: Mapping | None = None, best: int = 256,
           rank: str | None = None, where: Mapping | None = None, points: int = 37, peak_scale: float | None = None,
           options: SQPOptions = SQPOptions()) -> SecondOrderResult:
    """Refine the `best` designs of a sweep under a stated objective and limits, in one call.

    `designs`: a ``SweepResult``, a sweep's dataset as a table (``read_dataset(folder)``, a
    pandas ``DataFrame`` of it) or ``{column: (D,)}``, holding the design variables (the
    names of `bounds`), `rank` and the `where` columns (and ``status``, where given).

    ``best_designs(designs, bounds, best=, rank=, where=)`` picks the starts (converged
    rows, least `rank` first); ``scene_problem(scene, bounds, peak=, limits=, points=)``
    states the problem; ``minimize_second_order`` solves it from every start at once.
    `peak_scale` (the peak's typical size; default the median ``|rank|`` of the starts, or
    1) scales the objective for the SQP's tolerance.

    **Returns** the ``SecondOrderResult``: each start's refined design (``params``), peak
    (``value``), ``status``, KKT residual, the winner (``best_params``), and in ``origin``
    the sweep row each start came from.
    """
    problem = scene_problem(scene, bounds, peak=peak, limits=limits, points=points)
    starts = _pick(_table(designs), tuple(bounds), best, rank, where)
    origin = starts.pop("row")
    if peak_scale is None:
        typical = float(np.median(np.abs(starts.pop(rank)))) if rank is not None and rank not in bounds else 1.0
        peak_scale = typical if np.isfinite(typical) and typical > 0 else 1.0
    starts = {k: starts[k] for k in bounds}
    res = minimize_second_order(problem, starts, bounds, peak_scale=peak_scale, options=options)
    return dataclasses.replace(res, origin=origin)
