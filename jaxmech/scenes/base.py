"""What a scene is: a mechanism with its parameters, stroke, drive and outputs, and how
one is run over its stroke (the engine behind ``jaxmech run``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

import jax.numpy as jnp
import numpy as np

from ..kinematics import ConstantSpeed, Motion, motion
from ..mechanism import Mechanism
from ..status import Status, status_counts
from .columns import table_columns

__all__ = ["Scene", "SceneResult", "run_scene"]


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """A validated mechanism scene.

    - `name`, `summary`: registry key and one-line description.
    - `mechanism`: the ``Mechanism``.
    - `defaults`: parameter values in SI units (every name in ``mechanism.params``).
    - `guess`: ``p -> q`` at the stroke start; it picks the assembly branch.
    - `stroke`: ``p -> (u_start, u_end)`` of the (single) input, SI units.
    - `speed`: magnitude of the default constant drive speed (rad/s or m/s); the time
      derivatives ``_dot``/``_ddot`` in reports are under this drive.
    - `units`: unit string for every coordinate and input (``"rad"``, ``"m"``).
    - `outputs`: optional ``(p, motion) -> {name: (values (N,), unit)}`` extra outputs
      (torque, voltage, reactions...).
    - `validate`: optional ``p -> None`` raising ``ValueError`` that says what to change.
    - `plots`: optional ``(result, outdir) -> list of PNG paths``.
    - `drawing`: optional ``p -> dict`` describing how to draw the mechanism from its named
      points (see ``jaxmech.plot``): links, ground pivots, slots, chords, traced points.
    - `document`: the seed document and where its corrections are written down.
    """

    name: str
    summary: str
    mechanism: Mechanism
    defaults: Mapping[str, float]
    guess: Callable
    stroke: Callable
    speed: float
    units: Mapping[str, str]
    outputs: Callable | None = None
    validate: Callable | None = None
    plots: Callable | None = None
    drawing: Callable | None = None
    document: str = ""

    def params(self, **overrides) -> dict:
        """Default parameters with overrides, checked (unknown name, bad value: ValueError)."""
        unknown = [k for k in overrides if k not in self.defaults]
        if unknown:
            raise ValueError(
                f"scene {self.name!r} has no parameter(s) {unknown}; its parameters are: {', '.join(self.defaults)}"
            )
        p = {**self.defaults, **{k: float(v) for k, v in overrides.items()}}
        self.mechanism.check_params(p)
        if self.validate is not None:
            self.validate(p)
        return p


@dataclasses.dataclass(frozen=True)
class SceneResult:
    """A scene run over its stroke: the motion, extra outputs and the parameters used."""

    scene: Scene
    params: dict
    motion: Motion
    outputs: dict

    @property
    def input_name(self) -> str:
        return self.scene.mechanism.inputs[0]

    def table(self) -> dict[str, np.ndarray]:
        """Columns ``NAME[UNIT]`` (SI): input, every coordinate with ``_dot``/``_ddot``, outputs
        (``columns.table_columns``, as a sweep writes them), and ``status[-]``."""
        cols = {k: np.asarray(v) for k, v in table_columns(self.scene, self.motion, self.outputs, xp=np).items()}
        cols["status[-]"] = np.asarray(self.motion.status)
        return cols

    def summary(self) -> str:
        """Short text table: min and max of every column, and the status counts."""
        lines = [f"scene {self.scene.name}: {self.scene.summary}", f"{'column':<28}{'min':>16}{'max':>16}"]
        for k, v in self.table().items():
            if k == "status[-]":
                continue
            v = np.asarray(v, float)
            lo, hi = (np.nanmin(v), np.nanmax(v)) if np.any(np.isfinite(v)) else (np.nan, np.nan)
            lines.append(f"{k:<28}{lo:>16.6g}{hi:>16.6g}")
        lines.append(f"status: {status_counts(self.motion.status)}")
        return "\n".join(lines)


def run_scene(scene: Scene, points: int = 101, **overrides) -> SceneResult:
    """Run a scene over its stroke at ``points`` evenly spaced inputs (both ends included),
    under its default constant-speed drive.  Raises ``ValueError`` for bad parameters or a
    design that cannot be assembled over the stroke."""
    if points < 2:
        raise ValueError(f"points must be at least 2, got {points}")
    p = scene.params(**overrides)
    u0, u1 = (float(x) for x in scene.stroke(p))
    w = scene.speed if u1 >= u0 else -scene.speed
    t = jnp.linspace(0.0, (u1 - u0) / w, points)
    mo = motion(scene.mechanism, ConstantSpeed(jnp.asarray(u0), jnp.asarray(w)), t, p, jnp.asarray(scene.guess(p)))
    status = np.asarray(mo.status)
    if np.any(status == Status.INFEASIBLE) or np.any(status == Status.NONFINITE):
        bad = np.flatnonzero((status == Status.INFEASIBLE) | (status == Status.NONFINITE))
        uname = scene.mechanism.inputs[0]
        raise ValueError(
            f"scene {scene.name!r} cannot be assembled over its stroke with these parameters: "
            f"{len(bad)} of {points} positions fail, first at {uname} = {float(mo.u[bad[0], 0]):.6g} "
            f"{scene.units[uname]} ({status_counts(status)}); change the link lengths or the stroke"
        )
    outs = scene.outputs(p, mo) if scene.outputs is not None else {}
    return SceneResult(scene=scene, params=p, motion=mo, outputs=dict(outs))
