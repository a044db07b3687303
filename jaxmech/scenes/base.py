"""What a scene is: a mechanism with its parameters, stroke, drive and outputs, and how
one is run over its stroke (the engine behind ``jaxmech run``)."""

from __future__ import annotations

import dataclasses
import difflib
import functools
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.inputs import own_params
from ..kinematics import Motion
from ..mechanism.mechanism import Mechanism
from ..solver.status import Status, status_counts
from ..units import for_reading
from .columns import mask_failed, table_columns
from .evaluation import evaluate

__all__ = ["Scene", "SceneResult", "run_scene", "as_scene"]


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
    - `outputs`: optional extra outputs (torque, voltage, reactions...) of one design,
      declared: ``Outputs(fn, {name: unit, ...})`` with ``fn(p, motion) -> {name: values
      (N,)}``, the units in the order the table shows them; or a plain function
      ``(p, motion) -> {name: (values (N,), unit)}``, whose names and units are then found
      once by tracing it (``scenes.outputs``).
    - `validate`: optional ``p -> None`` raising ``ValueError`` that says what to change.
    - `plots`: optional ``(result, outdir) -> list of PNG paths``.
    - `drawing`: optional ``p -> dict`` describing how to draw the mechanism from its named
      points (see ``jaxmech.viz.drawing``): links, ground pivots, slots, chords, traced points.
    - `document`: the seed document and where its corrections are written down.
    - `parameters`: ``{name: (SI unit, meaning)}`` for every name in `defaults` (what
      ``jaxmech scenes SCENE`` lists, and the unit ``--set`` checks); empty for a scene
      that does not describe itself.
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
    parameters: Mapping[str, tuple[str, str]] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        if self.parameters:
            missing = [k for k in self.defaults if k not in self.parameters]
            extra = [k for k in self.parameters if k not in self.defaults]
            if missing or extra:
                raise ValueError(
                    f"scene {self.name!r}: parameters must describe exactly the defaults; "
                    f"undescribed {missing}, not a default {extra}"
                )

    @functools.cached_property
    def program_key(self) -> str | None:
        """What identifies this scene in a stored program: its registry name when it is the
        registry's scene of that name (its code is the package's, which the stored programs'
        key covers); None for any other scene (then nothing is stored for it).  Looked up
        once per scene object (a frozen scene cannot become another)."""
        from . import get_scene, scene_names  # the registry imports this module

        return f"scene {self.name}" if self.name in scene_names() and get_scene(self.name) is self else None

    def check_name(self, name: str) -> None:
        """``ValueError`` (one line, naming the closest valid name) unless ``name`` is a
        parameter of this scene."""
        if name in self.defaults:
            return
        close = difflib.get_close_matches(name, list(self.defaults), n=1, cutoff=0.5)
        hint = f"did you mean {close[0]!r}?" if close else f"its parameters are: {', '.join(self.defaults)}"
        raise ValueError(f"scene {self.name!r} has no parameter {name!r}; {hint}")

    def unit(self, name: str) -> str:
        """The SI unit of parameter ``name`` (``""`` when the scene does not say)."""
        self.check_name(name)
        return self.parameters.get(name, ("", ""))[0]

    def describe(self) -> str:
        """Text table of the parameters: name, SI unit, default (angles also in degrees)
        and meaning, one line each, under the scene's name and summary."""
        rows = []
        for k, v in self.defaults.items():
            unit, meaning = self.parameters.get(k, ("?", "(not described)"))
            shown = f"{float(v):.6g}"
            deg, dunit = for_reading(float(v), unit)
            if dunit != unit:
                shown += f" ({deg:.6g} {dunit})"
            rows.append((k, unit, shown, meaning))
        w = [max([len(h)] + [len(r[i]) for r in rows]) for i, h in enumerate(("name", "unit", "default"))]
        lines = [f"{self.name}: {self.summary}", ""]
        if self.document:
            lines += [f"document: {self.document}", ""]
        lines.append(f"{'name':<{w[0]}}  {'unit':<{w[1]}}  {'default':<{w[2]}}  meaning")
        lines += [f"{n:<{w[0]}}  {u:<{w[1]}}  {d:<{w[2]}}  {m}" for n, u, d, m in rows]
        return "\n".join(lines)

    def params(self, **overrides) -> dict:
        """Default parameters with overrides, checked (unknown name, bad value: ValueError)."""
        for k in overrides:
            self.check_name(k)
        p = {**self.defaults, **{k: float(v) for k, v in overrides.items()}}
        self.mechanism.check_params(own_params(self.mechanism, p))
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
        status = np.asarray(self.motion.status)
        cols = mask_failed(self.scene, table_columns(self.scene, self.motion, self.outputs, xp=np), status, xp=np)
        cols = {k: np.asarray(v) for k, v in cols.items()}
        cols["status[-]"] = status
        return cols

    def summary(self) -> str:
        """Short text table: min and max of every column (angles in degrees; the CSV of
        ``table()`` stays SI), the parameters changed from the scene's defaults, and the
        status counts."""
        sc = self.scene
        lines = [f"scene {sc.name}: {sc.summary}"]
        changed = [k for k, v in self.params.items() if float(v) != float(sc.defaults[k])]
        if changed:
            shown = (for_reading(float(self.params[k]), sc.parameters.get(k, ("", ""))[0]) for k in changed)
            lines.append("changed from the defaults: " + ", ".join(f"{k} = {v:.6g} {u}".rstrip() for k, (v, u) in zip(changed, shown)))
        lines.append(f"{'column':<28}{'min':>16}{'max':>16}")
        for k, v in self.table().items():
            if k == "status[-]":
                continue
            name, _, unit = k[:-1].partition("[")
            v, unit = for_reading(np.asarray(v, float), unit)
            k = f"{name}[{unit}]"
            lo, hi = (np.nanmin(v), np.nanmax(v)) if np.any(np.isfinite(v)) else (np.nan, np.nan)
            lines.append(f"{k:<28}{lo:>16.6g}{hi:>16.6g}")
        lines.append(f"status: {status_counts(self.motion.status)}")
        return "\n".join(lines)


def as_scene(scene, who: str = "scene") -> Scene:
    """``scene`` as a ``Scene``: a scene, a registered scene's name, or a ``Linkage``
    (``Linkage.scene()``: a crank's whole turn from the drawing at 1 rad/s); ``ValueError``
    naming `who` otherwise."""
    if isinstance(scene, str):
        from . import get_scene

        return get_scene(scene)
    if isinstance(scene, Scene):
        return scene
    if hasattr(scene, "scene") and hasattr(scene, "mechanism") and callable(scene.scene):
        return scene.scene()
    raise ValueError(f"{who}: scene must be a Scene, a scene name or a Linkage, got {type(scene).__name__}")


def run_scene(scene: Scene, points: int = 101, **overrides) -> SceneResult:
    """Run a scene over its stroke at ``points`` evenly spaced inputs (both ends included),
    under its default constant-speed drive.  Raises ``ValueError`` for bad parameters or a
    design that cannot be assembled over the stroke.  `scene`: a ``Scene``, a registered
    scene's name or a ``Linkage`` (``as_scene``).

    The stroke is solved with ``evaluation.SCENE_OPTIONS`` by ``evaluation.evaluate``, the
    program a sweep runs: ``run_scene`` and a one-design sweep give the same columns, bit
    for bit.  (It runs two copies of the design: XLA compiles a batch of one as scalar code
    whose last-bit rounding differs, and a sweep's chunk holds at least two.)"""
    if points < 2:
        raise ValueError(f"points must be at least 2, got {points}")
    scene = as_scene(scene, "run_scene")
    p = scene.params(**overrides)
    dtype = jnp.result_type(float)
    batch = {k: np.full(2, v, dtype) for k, v in p.items()}
    mo2, outs2 = evaluate(scene, int(points), batch)
    status = np.asarray(mo2.status)[0]
    ok = status == Status.CONVERGED
    mo = jax.tree_util.tree_map(lambda x: np.asarray(x)[0], mo2)
    # failed samples: NaN in every field but the drive's (the program holds placeholders there)
    nan = lambda x: np.where(ok.reshape(ok.shape + (1,) * (x.ndim - 1)), x, np.nan)  # noqa: E731
    mo = dataclasses.replace(
        mo, q=nan(mo.q), q_dot=nan(mo.q_dot), q_ddot=nan(mo.q_ddot), dq_du=nan(mo.dq_du), d2q_du2=nan(mo.d2q_du2),
        points=jax.tree_util.tree_map(nan, mo.points),
    )
    if np.any(status == Status.INFEASIBLE) or np.any(status == Status.NONFINITE):
        bad = np.flatnonzero((status == Status.INFEASIBLE) | (status == Status.NONFINITE))
        uname = scene.mechanism.inputs[0]
        raise ValueError(
            f"scene {scene.name!r} cannot be assembled over its stroke with these parameters: "
            f"{len(bad)} of {points} positions fail, first at {uname} = {float(mo.u[bad[0], 0]):.6g} "
            f"{scene.units[uname]} ({status_counts(status)}); change the link lengths or the stroke"
        )
    if outs2 is None:  # outputs that do not trace: evaluated here, on this design's motion
        outs = {k: (np.asarray(v), unit) for k, (v, unit) in scene.outputs(p, mo).items()}
    else:
        outs = {k: (np.asarray(v)[0], unit) for k, (v, unit) in outs2.items()}
    return SceneResult(scene=scene, params=p, motion=mo, outputs=outs)
