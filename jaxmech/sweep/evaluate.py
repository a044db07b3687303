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

from ..continuation import stroke
from ..kinematics import ConstantSpeed, Motion, sample_kinematics
from ..scenes.base import Scene
from ..scenes.columns import is_drive_column, mask_failed, table_columns
from ..options import SolverOptions
from ..status import Status

__all__ = [
    "Figures",
    "design_columns",
    "design_motion",
    "design_status",
    "is_drive_column",
    "mask_failed",
    "stroke_figures",
    "table_columns",
]


def stroke_drive(scene: Scene, p, dtype):
    """Drive law of ``run_scene``: constant speed from the stroke start to its end;
    returns ``(drive, duration in s)``."""
    u0, u1 = (jnp.asarray(x, dtype) for x in scene.stroke(p))
    w = jnp.where(u1 >= u0, scene.speed, -scene.speed).astype(dtype)
    return ConstantSpeed(u0, w), (u1 - u0) / w


def design_motion(scene: Scene, points: int, p, *, options: SolverOptions = SolverOptions(), anchors: int = 256):
    """One design's ``Motion`` over its stroke, traceable (works under ``jit``/``vmap``/``grad``).

    The same computation as ``run_scene`` (its stroke, drive and continuation), but the
    values at failed samples are finite placeholders (the coordinates of
    ``scene.guess(p)``, zero derivatives), so that any function of the motion stays
    finite and differentiable; ``status`` says which samples are real.

    **Arguments**

    - `scene`: the scene; `points`: samples along the stroke (both ends included).
    - `p`: ``{name: scalar}``, every parameter of the scene (SI units).

    **Returns** ``(motion, ok)``: a ``Motion`` with ``N = points`` samples and the boolean
    ``(N,)`` mask of converged samples.
    """
    mech = scene.mechanism
    dtype = jnp.result_type(*[jnp.asarray(v) for v in p.values()], float)
    p = {k: jnp.asarray(p[k], dtype) for k in mech.params}
    drive, duration = stroke_drive(scene, p, dtype)
    t = jnp.linspace(0.0, duration, points)
    us = jax.vmap(drive)(t)
    guess = jnp.asarray(scene.guess(p), dtype)
    # one compiled pass: positions, dq/du and d2q/du2 (differentiable by the implicit rule)
    sol, e1, e2 = stroke(mech, us, p, guess, options, derivs=True, anchors=anchors)
    ok = sol.status == Status.CONVERGED
    # Mask the *inputs* of everything downstream: no NaN, not even in a branch not taken
    # (failed samples have zero derivatives).
    q = jnp.where(ok[:, None], sol.q, guess[None, :])
    d1 = jnp.where(ok[:, None, None], e1, 0.0)
    d2 = jnp.where(ok[:, None, None, None], e2, 0.0)
    u, ud, udd, qd, qdd, pts = jax.vmap(lambda t_, q_, a_, b_: sample_kinematics(mech, tuple(mech.points), drive, p, t_, q_, a_, b_))(t, q, d1, d2)
    mo = Motion(
        t=t, u=u, u_dot=ud, u_ddot=udd, q=q, q_dot=qd, q_ddot=qdd, dq_du=d1, d2q_du2=d2,
        points=pts, status=sol.status, coords=mech.coords, inputs=mech.inputs,
    )
    return mo, ok


def design_columns(scene: Scene, points: int, p, *, options: SolverOptions = SolverOptions(), anchors: int = 256):
    """One design's table columns, traceable: ``({NAME[UNIT]: (N,)}, status (N,))``.

    Columns are those of ``SceneResult.table`` (without ``status[-]``), and at failed
    samples they hold finite placeholders (see ``design_motion``): mask them with the
    status.  Used by the sweep kernels and by ``jaxmech.design.scene_figure``.
    """
    mo, _ = design_motion(scene, points, p, options=options, anchors=anchors)
    p = {k: jnp.asarray(v, mo.q.dtype) for k, v in p.items()}
    outs = scene.outputs(p, mo) if scene.outputs is not None else None
    return table_columns(scene, mo, outs), mo.status


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
