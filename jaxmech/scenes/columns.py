"""The columns of a scene's table, one naming for every path: ``SceneResult.table``
(``run_scene``), the sweep kernels (trace and figures), their CSV and Parquet writers, and
``jaxmech.design`` all name and order them here; and the traceable evaluations of one
design, or a batch, as those columns (``design_columns``, ``batch_columns``: what
``jaxmech.design`` differentiates and the sweep kernels vmap).

Column names are ``NAME[UNIT]`` (SI): time, the input with its rates, every coordinate
with ``_dot``/``_ddot``, the scene's outputs in the order and units of
``outputs.output_units``; ``status[-]`` is added by the callers.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from ..kinematics import point_kinematics
from ..solver.options import SolverOptions
from ..solver.status import Status
from .evaluation import SCENE_OPTIONS, outputs_stage, scene_motion, stroke_stage
from .outputs import merged_status, output_units, sample_status

if TYPE_CHECKING:  # a Scene is only read here (its mechanism, units, outputs)
    from ..kinematics import Motion
    from .base import Scene

__all__ = [
    "LazyColumns",
    "batch_columns",
    "part_columns",
    "column_names",
    "design_columns",
    "design_motion",
    "design_status",
    "is_drive_column",
    "mask_failed",
    "table_columns",
]


def _names(scene: Scene, out_units: Mapping[str, str]) -> list[str]:
    """Every column name, in table order, for outputs ``{name: unit}``."""
    uname = scene.mechanism.inputs[0]
    uu = scene.units[uname]
    names = ["t[s]", f"{uname}[{uu}]", f"{uname}_dot[{uu}/s]", f"{uname}_ddot[{uu}/s^2]"]
    for n in scene.mechanism.coords:
        un = scene.units[n]
        names += [f"{n}[{un}]", f"{n}_dot[{un}/s]", f"{n}_ddot[{un}/s^2]"]
    return names + [f"{n}[{unit}]" for n, unit in out_units.items()]


def column_names(scene: Scene) -> list[str]:
    """The names ``NAME[UNIT]`` of ``SceneResult.table``'s columns (status excepted), in
    order, from the scene's declaration alone (nothing is evaluated)."""
    return _names(scene, output_units(scene))


def table_columns(scene: Scene, mo: Motion, outputs: Mapping | None, xp=jnp) -> dict:
    """Columns ``NAME[UNIT]`` of ``SceneResult.table`` (without status), unmasked, from a
    motion and the outputs ``{name: (values, unit)}`` (in column order); `xp` is
    ``jax.numpy`` (traced) or ``numpy`` (outputs evaluated design by design)."""
    outputs = outputs or {}
    values = [mo.t, mo.u[..., 0], mo.u_dot[..., 0], mo.u_ddot[..., 0]]
    for i in range(len(scene.mechanism.coords)):
        values += [mo.q[..., i], mo.q_dot[..., i], mo.q_ddot[..., i]]
    values += [xp.broadcast_to(xp.asarray(v), mo.t.shape) for v, _ in outputs.values()]
    return dict(zip(_names(scene, {k: unit for k, (_, unit) in outputs.items()}), values))


def is_drive_column(scene: Scene, name: str) -> bool:
    """Whether a column is defined at failed samples too (time and the input's drive)."""
    return name == "t[s]" or name.split("[")[0] in {
        f"{scene.mechanism.inputs[0]}{s}" for s in ("", "_dot", "_ddot")
    }


def mask_failed(scene: Scene, cols: dict, status, xp=jnp) -> dict:
    """``cols`` with NaN at the samples that did not converge (drive columns kept)."""
    ok = status == Status.CONVERGED
    return {k: v if is_drive_column(scene, k) else xp.where(ok, v, xp.nan) for k, v in cols.items()}


def design_motion(scene: Scene, points: int, p, *, options: SolverOptions = SCENE_OPTIONS):
    """One design's ``Motion`` over its stroke, traceable (works under ``jit``/``vmap``/``grad``):
    ``evaluation.scene_motion`` for a batch of one.

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
    (D, N)}, status (D, N))``, unmasked (finite placeholders at failed samples): the sweep
    kernels' columns, and ``run_scene``'s."""
    return part_columns(scene, points, p, stroke_stage(scene, points, options, True, p))


def part_columns(scene: Scene, points: int, p, part):
    """``batch_columns`` from the stroke stage's ``part`` (``evaluation.StrokePart``)."""
    mo, values = outputs_stage(scene, points, scene.outputs is not None, p, part)
    units = output_units(scene) if values else {}
    return table_columns(scene, mo, {k: (values[k], u) for k, u in units.items()}), mo.status


def design_status(status, xp=jnp):
    """A design's status from its samples' ``(..., N)``: ``CONVERGED`` when every sample
    converged, else the status of the first sample along the stroke that did not (where
    the design broke).  Returns ``(...,)`` int32."""
    bad = status != Status.CONVERGED
    first = xp.argmax(bad, axis=-1)
    code = xp.take_along_axis(status, first[..., None], axis=-1)[..., 0]
    return xp.where(xp.any(bad, axis=-1), code, int(Status.CONVERGED)).astype(xp.int32)


class LazyColumns(Mapping):
    """A scene's table columns ``{NAME[UNIT]: (N,)}`` at one design's motion (status
    excepted, unmasked), each computed when read: the motion's own columns directly, an
    output by its part's function where the scene gives one (``Outputs.parts``: a drive's
    effort without every joint's reaction), else with all outputs (the named points'
    kinematics computed first when the motion has none).  What a figure or a design
    statement does not read is never traced, so it stays out of its program and of its
    derivatives."""

    def __init__(self, scene, p, mo):
        self._scene, self._p, self._mo, self._names, self._read = scene, p, mo, column_names(scene), {}

    def __getitem__(self, name):
        if name not in self._read:
            if name not in self._names:
                raise KeyError(f"scene {self._scene.name!r} has no column {name!r}; its columns are: {', '.join(self._names)}")
            self._read[name] = self._column(name)
        return self._read[name]

    def _column(self, name: str):
        scene, mo = self._scene, self._mo
        motion = table_columns(scene, mo, {})
        if name in motion:
            return motion[name]
        out = name.partition("[")[0]
        if out in scene.outputs.parts:
            return scene.outputs.one(out, self._p, mo)
        if "outputs" not in self._read:  # every output at once, with the points they may read
            mech = scene.mechanism
            if not mo.points and mech.points:
                pts = jax.vmap(lambda q, qd, qdd, u, ud, udd: point_kinematics(mech, tuple(mech.points), self._p, q, qd, qdd, u, ud, udd))(
                    mo.q, mo.q_dot, mo.q_ddot, mo.u, mo.u_dot, mo.u_ddot)
                mo = dataclasses.replace(mo, points=pts)
            outs, own = sample_status(scene, self._p, mo)
            self._read["outputs"] = table_columns(scene, mo, outs)
            if own is not None:
                self._read["status"] = merged_status(self._mo.status, own)
        return self._read["outputs"][name]

    @property
    def outputs_status(self):
        """The samples' status with the outputs' own (``outputs.Outputs.status``: a linkage
        jammed by joint friction) where the outputs were read and declare one; None
        otherwise (the motion's status stands)."""
        return self._read.get("status")

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)
