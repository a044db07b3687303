"""CAD export: a pose of a mechanism, or its stroke, as DXF (ezdxf) or SVG, to take a
linkage from a study into a CAD tool.

What is drawn comes from the scene's drawing spec (``jaxmech.viz.drawing``): every link, plate
and chord on a layer of its own, named after the link (a ``Linkage``'s link names) or after
the spec's points (``link_O2-A``, ``plate_A-F-G-D``, ``chord_C-F``); joints as circles centred
exactly at the solved joints, on the layer of each link they join; ground pivots with a
ground mark (layer ``ground``); slots (``slot_1``, ...); traced points (``points``); the point
names as text (``labels``).  A stroke adds the path of every traced point over the stroke
(``path_P``) and the positions each link sweeps through (``sweep_link_O2-A``: the link drawn
at evenly spaced samples of the stroke, the envelope a clearance check keeps free).

Coordinates are written in full float64 precision: ezdxf writes a coordinate as the
shortest decimal that reads back to the same double (Python's ``repr``), and the SVG
numbers are written the same way, so a joint read back from either file is the solved
joint to the last bit (in ``units="m"``; ``"mm"`` multiplies by 1000, one rounding).

**DXF**: ``$INSUNITS`` metres (or millimetres), one layer per link, ``LWPOLYLINE`` for links
(open), plates and ground marks (closed) and paths, ``CIRCLE`` for joints, ``ARC`` for
circular slots, ``TEXT`` for labels.  Each joint circle carries XDATA (application
``JAXMECH``): ``"joint"`` and the point's name.  The header's custom properties name the scene,
the input, its value (SI) and the units.

**SVG**: the model is inside ``<g id="model" transform="scale(1 -1)">`` (y up, as in the
model); the numbers inside are model coordinates (m, or mm).  One ``<g>`` per layer with
``id`` the layer's name and ``class`` its kind (``link``, ``plate``, ``chord``, ``ground``,
``slot``, ``points``, ``labels``, ``path``, ``sweep``); joints are ``<circle class="joint"
data-point="A">``.  The drawing is 1:1 (``width``/``height`` in mm).

The pose at an input value is solved by the engine: the scene's stroke is continued from
its start (``scene.guess`` on its assembly branch) to the value, so the pose is the one the
mechanism reaches by moving; a value it cannot reach (it cannot be assembled there, or on
the way) is a ``ValueError`` in one line, never a wrong pose.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .cad import APPID, UNIT_SCALE, Sheet, write_dxf, write_svg
from ..viz.drawing import check_point, check_spec, spec_points
from ..units import for_reading, to_si

__all__ = ["Pose", "solve_pose", "export_pose", "write_pose", "export_stroke", "input_value", "APPID"]

#: The file types written, by suffix.
SUFFIXES = (".dxf", ".svg")

#: Samples on the way from the stroke's start to the pose, per stroke length (as dense as
#: a 101-point run of the stroke).
PATH_SAMPLES = 101
#: At most this many stroke lengths from the stroke's start are walked to a pose.
MAX_STROKES = 64


# --------------------------------------------------------------------------- what is exported
@dataclasses.dataclass(frozen=True)
class Pose:
    """One solved pose of a scene.

    - `scene`, `params` (SI): the design.
    - `input_name`, `at`: the input and its value (SI).
    - `positions`: ``{point: x + i y}`` (m) of every named point of the mechanism.
    - `spec`: the checked drawing spec; `names`: ``{points of a link (tuple): link name}``.
    """

    scene: object
    params: dict
    input_name: str
    at: float
    positions: dict
    spec: dict
    names: dict

    def point(self, p) -> complex:
        """Position of a spec point: a point name, or a fixed complex number (m)."""
        return self.positions[p] if isinstance(p, str) else complex(p)

    def describe(self) -> str:
        shown, unit = for_reading(self.at, self.scene.units.get(self.input_name, ""))
        return f"{self.scene.name} at {self.input_name} = {float(shown):.6g} {unit}".rstrip()


def link_names(linkage) -> dict:
    """``{tuple of points: link name}`` of a ``Linkage``'s links and actuators, as its
    scene's drawing spec lists them (the layers are then named after the links)."""
    out = {tuple(pts): name for name, pts in linkage.links.items()}
    out.update({tuple(pts): name for name, pts in linkage.topology.actuators})
    return out


class Resolved(NamedTuple):
    """What an export draws (``_resolve``): the `scene`, its parameter values `params`, the
    link `names` ``{tuple of points: link name}`` (empty unless a ``Linkage`` or a linkage
    file), and the `result` to draw from (None unless a ``SceneResult`` of this design)."""

    scene: object
    params: dict
    names: dict
    result: object


def _resolve(obj, params) -> Resolved:
    """``(scene, params, names, result)`` of a ``Scene``, ``SceneResult``, ``Linkage``, a scene
    name or a linkage file's path."""
    from ..linkage import Linkage
    from ..scenes import SceneResult, get_scene
    from ..scenes.base import Scene
    from ..scenes.linkage_scene import linkage_scene, scene_from_file

    names, result = {}, None
    if isinstance(obj, (str, Path)):
        if str(obj).lower().endswith((".toml", ".json")):
            from ..linkage.files import read_linkage_file

            names = link_names(read_linkage_file(obj)[0])
            obj = scene_from_file(obj)
        else:
            obj = get_scene(str(obj))
    if isinstance(obj, Linkage):
        names = link_names(obj)
        obj = linkage_scene(obj)
    if isinstance(obj, SceneResult):
        result = obj
        scene = obj.scene
        p = {**obj.params, **{k: float(v) for k, v in (params or {}).items()}}
        if params:
            p = scene.params(**p)
            result = None  # another design than the result's
    elif isinstance(obj, Scene):
        scene = obj
        p = scene.params(**dict(params or {}))
    else:
        raise TypeError(f"export takes a Scene, SceneResult, Linkage, scene name or linkage file; got {type(obj).__name__}")
    return Resolved(scene, p, names, result)


def _spec(scene, p) -> dict:
    if scene.drawing is None:
        return {"points": list(scene.mechanism.points), "trace": list(scene.mechanism.points)}
    return check_spec(scene, scene.drawing(p))


def input_value(scene, at) -> float:
    """The SI value of the scene's input from ``at``: a number (SI) or a string with a
    unit (``"60deg"``, ``"450mm"``).  ``ValueError`` (one line) for a bad value or unit."""
    name = scene.mechanism.inputs[0]
    unit = scene.units.get(name, "")
    if isinstance(at, str):
        try:
            value = to_si(at, unit)
        except ValueError as e:
            raise ValueError(f"{name}: {e}") from None
    else:
        try:
            value = float(at)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: give a number in {unit} (or a string with its unit), got {at!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {at!r}")
    return value


def solve_pose(obj, at=None, *, params: Mapping | None = None) -> Pose:
    """Solve the pose of a scene at input value `at` (SI, or a string with a unit; default
    the stroke's start).

    The mechanism is moved by the engine (``jaxmech.solve_stroke``, the scene's solver
    options) from the stroke's start, on the assembly branch of ``scene.guess``, to `at`;
    every named point is evaluated at the last sample.

    **Arguments**: `obj`: a ``Scene``, ``SceneResult`` (its parameters), ``Linkage``, scene
    name or linkage file; `params`: parameter overrides (SI).

    **Raises** ``ValueError`` (one line) when the mechanism cannot be assembled at `at`, or
    not on the way to it from the stroke's start.
    """
    import jax.numpy as jnp

    from ..continuation.solve import solve_stroke
    from ..scenes.evaluation import SCENE_OPTIONS
    from ..solver.status import Status, status_message

    scene, p, names, _ = _resolve(obj, params)
    mech = scene.mechanism
    if mech.dof != 1:
        raise ValueError(f"scene {scene.name!r} has {mech.dof} inputs; a pose is exported for one input")
    uname = mech.inputs[0]
    unit = scene.units.get(uname, "")
    u0, u1 = (float(x) for x in scene.stroke(p))
    at = u0 if at is None else input_value(scene, at)
    shown = lambda u: "{:.6g} {}".format(*for_reading(float(u), unit)).rstrip()  # noqa: E731
    # as dense as a run of the stroke: its 101 samples per stroke length (whole strokes, so
    # that every value within one stroke length of the start shares one compiled program)
    far = abs(at - u0) / (abs(u1 - u0) or 1.0)
    lengths = math.ceil(far - 1e-9)
    if lengths > MAX_STROKES:
        raise ValueError(f"scene {scene.name!r}: {uname} = {shown(at)} is {far:.6g} stroke lengths from the stroke's start "
                         f"({shown(u0)}); a pose is reached from the start by moving at most {MAX_STROKES} stroke lengths")
    n = PATH_SAMPLES * max(1, lengths)
    dtype = jnp.result_type(float)
    pj = {k: jnp.asarray(p[k], dtype) for k in mech.params}
    us = np.linspace(u0, at, n)
    sol = solve_stroke(mech, jnp.asarray(us, dtype), pj, jnp.asarray(scene.guess(p), dtype), options=SCENE_OPTIONS)
    status = np.asarray(sol.status)
    if status[-1] != Status.CONVERGED:
        why = status_message(status[-1]).removeprefix("cannot be assembled here: ")
        raise ValueError(f"scene {scene.name!r} cannot be assembled at {uname} = {shown(at)} ({why})")
    bad = np.flatnonzero(status != Status.CONVERGED)
    if bad.size:
        raise ValueError(
            f"scene {scene.name!r}: {uname} = {shown(at)} cannot be reached from the stroke's start "
            f"({shown(u0)}): the mechanism cannot be moved through {uname} = {shown(us[bad[0]])} "
            f"({status_message(status[bad[0]])})"
        )
    pts = _points_program(mech)(sol.q[-1], jnp.asarray([at], dtype), pj)
    positions = {k: complex(v) for k, v in pts.items()}
    return Pose(scene=scene, params=p, input_name=uname, at=float(at), positions=positions, spec=_spec(scene, p), names=names)


@functools.lru_cache(maxsize=32)
def _points_program(mech):
    """Every named point of ``mech`` at one pose, compiled once per mechanism."""
    import jax

    return jax.jit(lambda q, u, p: {k: mech.point(k, q, u, p) for k in mech.points})


def _pose_of_result(result, index: int, names) -> Pose:
    mo, scene = result.motion, result.scene
    positions = {k: complex(np.asarray(v[0])[index]) for k, v in mo.points.items()}
    return Pose(scene=scene, params=dict(result.params), input_name=result.input_name, at=float(mo.u[index, 0]),
                positions=positions, spec=_spec(scene, result.params), names=names)


def _label(p):
    return p if isinstance(p, str) else None


def _base_name(kind: str, pts, k: int, names: Mapping) -> str:
    if tuple(pts) in names:
        return f"link_{names[tuple(pts)]}"
    labels = [_label(p) for p in pts]
    return f"{kind}_{'-'.join(labels)}" if all(labels) else f"{kind}_{k + 1}"


def _members(spec, names):
    """``[(kind, layer name, points, closed)]``: the spec's links, plates and chords."""
    out = []
    for k, pts in enumerate(spec.get("polygons", ())):
        out.append(("plate", _base_name("plate", pts, k, names), tuple(pts), True))
    for k, pts in enumerate(spec.get("links", ())):
        out.append(("link", _base_name("link", pts, k, names), tuple(pts), False))
    for k, pts in enumerate(spec.get("chords", ())):
        out.append(("chord", _base_name("chord", pts, k, names), tuple(pts), False))
    return out


_COLORS = {"link": 7, "plate": 5, "chord": 4, "ground": 8, "slot": 30, "points": 1, "labels": 3, "sweep": 9}


def _span(zs) -> float:
    z = np.array([complex(v) for v in zs if np.isfinite(complex(v))] or [0j])
    return float(max(np.ptp(z.real), np.ptp(z.imag))) or 1.0


def _slot_angles(s, paths):
    """``(start, end)`` (rad) of a circular slot's arc: its ``angles``; or the arc its pin
    sweeps over the stroke plus a margin (as ``jaxmech.viz.drawing``); else the whole circle."""
    if "angles" in s:
        return tuple(float(v) for v in s["angles"])
    if "pin" not in s or paths is None:
        return 0.0, 2 * math.pi
    ang = np.unwrap(np.angle(np.asarray(paths[s["pin"]]) - np.asarray(paths[s["centre"]])))
    ang = ang[np.isfinite(ang)]
    if not ang.size:
        return 0.0, 2 * math.pi
    lo, hi = float(ang.min()), float(ang.max())
    margin = 0.1 * (hi - lo) + 0.02
    return lo - margin, hi + margin


def _draw_pose(sheet: Sheet, pose: Pose, r: float, *, paths=None, labels=True):
    spec = pose.spec
    drawn: dict = {}  # named points drawn as joints -> position
    for kind, name, pts, closed in _members(spec, pose.names):
        layer = sheet.layer(name, kind, _COLORS[kind])
        zs = [pose.point(x) for x in pts]
        sheet.polyline(layer, zs, closed)
        for x, z in zip(pts, zs):
            if isinstance(x, str):
                sheet.circle(layer, z, r, x)
                drawn[x] = z
    ground = list(spec.get("ground", ()))
    if ground:
        layer = sheet.layer("ground", "ground", _COLORS["ground"])
        for g in ground:
            z = pose.point(g)
            sheet.circle(layer, z, r, _label(g))
            # the ground mark: a triangle under the pivot, its base line and hatching
            h, w = 3.0 * r, 2.0 * r
            sheet.polyline(layer, [z - 1j * r, z - w - 1j * h, z + w - 1j * h], closed=True)
            sheet.polyline(layer, [z - 1.6 * w - 1j * h, z + 1.6 * w - 1j * h])
            for k in range(5):
                x0 = z - 1.6 * w + k * 0.8 * w - 1j * h
                sheet.polyline(layer, [x0, x0 - 0.6 * r - 1j * 0.8 * r])
            if isinstance(g, str):
                drawn[g] = z
    for k, s in enumerate(spec.get("slots", ())):
        layer = sheet.layer(f"slot_{k + 1}", "slot", _COLORS["slot"])
        if "line" in s:
            sheet.polyline(layer, [pose.point(x) for x in s["line"]])
        else:
            a0, a1 = _slot_angles(s, paths)
            sheet.arc(layer, pose.point(s["centre"]), float(s["radius"]), a0, a1)
    extra = [x for x in dict.fromkeys([*spec.get("points", ()), *spec.get("trace", ())]) if isinstance(x, str) and x not in drawn]
    if extra:
        layer = sheet.layer("points", "points", _COLORS["points"])
        for x in extra:
            sheet.circle(layer, pose.point(x), 0.5 * r, x)
            drawn[x] = pose.point(x)
    if labels and drawn:
        layer = sheet.layer("labels", "labels", _COLORS["labels"])
        for x, z in drawn.items():
            sheet.text(layer, z + 1.2 * r * (1 + 1j), x, 2.0 * r)
    return drawn


# --------------------------------------------------------------------------- writers
def _meta(pose: Pose, units: str) -> dict:
    return {"jaxmech_scene": pose.scene.name, "jaxmech_input": pose.input_name, "jaxmech_value_si": repr(pose.at),
            "jaxmech_input_unit": pose.scene.units.get(pose.input_name, ""), "jaxmech_units": units}


def _checked_path(path) -> Path:
    """`path` as a ``Path``; ``ValueError`` unless it ends in ``.dxf`` or ``.svg`` and its
    folder exists (no folder is made: a missing one is more often a typo than a wish)."""
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ValueError(f"export path must end in {' or '.join(SUFFIXES)}, got {str(path)!r}")
    folder = path.parent
    if not folder.is_dir():
        raise ValueError(f"export path {str(path)!r}: the folder {str(folder)!r} does not exist; create it first")
    return path


def _write(sheet: Sheet, pose: Pose, path, units: str, what: str) -> Path:
    path = _checked_path(path)
    if units not in UNIT_SCALE:
        raise ValueError(f"units must be one of {list(UNIT_SCALE)}, got {units!r}")
    meta = _meta(pose, units)
    if path.suffix.lower() == ".dxf":
        write_dxf(sheet, path, units, meta)
    else:
        write_svg(sheet, path, units, meta, f"{what}: {pose.describe()}")
    return path


def _radius(joint_radius, zs) -> float:
    if joint_radius is None:
        return 0.02 * _span(zs)
    r = float(joint_radius)
    if not (math.isfinite(r) and r > 0):
        raise ValueError(f"joint_radius must be a positive length in m, got {joint_radius!r}")
    return r


# --------------------------------------------------------------------------- the export
def export_pose(obj, at, path, *, params: Mapping | None = None, units: str = "m", joint_radius: float | None = None,
                labels: bool = True) -> Path:
    """Write the mechanism at input value `at` to ``path`` (``.dxf`` or ``.svg``).

    **Arguments**

    - `obj`: a ``Scene``, ``SceneResult`` (its parameters), ``Linkage``, scene name or
      linkage file.
    - `at`: the input's value, SI (rad, m) or a string with a unit (``"60deg"``); ``None``:
      the stroke's start.
    - `params`: parameter overrides (SI).
    - `units`: ``"m"`` (default) or ``"mm"``: the drawing's unit.
    - `joint_radius`: radius of the joint circles (m; default 2 % of the drawing's size).
    - `labels`: write the point names.

    **Returns** the path.  **Raises** ``ValueError`` (one line) for a bad suffix or value, a
    folder that does not exist (none is made), or a pose the mechanism cannot reach
    (``solve_pose``).
    """
    _checked_path(path)
    pose = solve_pose(obj, at, params=params)
    return write_pose(pose, path, units=units, joint_radius=joint_radius, labels=labels)


def write_pose(pose: Pose, path, *, units: str = "m", joint_radius: float | None = None, labels: bool = True) -> Path:
    """Write a solved ``Pose`` (``solve_pose``) to ``path`` (``.dxf`` or ``.svg``)."""
    zs = [pose.point(x) for x in spec_points(pose.spec)]
    sheet = Sheet()
    _draw_pose(sheet, pose, _radius(joint_radius, zs), labels=labels)
    return _write(sheet, pose, path, units, "pose")


def export_stroke(obj, path, *, at=None, params: Mapping | None = None, points: int = 101, trace=None, swept: int = 24,
                  units: str = "m", joint_radius: float | None = None, labels: bool = True) -> Path:
    """Write a stroke to ``path`` (``.dxf`` or ``.svg``): the mechanism at one pose, the
    path of every traced point over the stroke (layers ``path_<point>``, one polyline per
    stretch where it is assembled) and the positions each link sweeps through (layers
    ``sweep_<link layer>``: the link at `swept` evenly spaced samples).

    **Arguments**

    - `obj`: a ``SceneResult`` (its stroke as run), or a ``Scene``, ``Linkage``, scene name or
      linkage file (run over its stroke with ``run_scene`` at `points` inputs).
    - `at`: the pose drawn (the input's value, SI or with a unit); ``None``: the stroke's
      first sample.
    - `trace`: points whose paths are drawn (default: the drawing spec's ``trace``).
    - `swept`: number of poses in the swept envelope (0: none).
    - `params`, `units`, `joint_radius`, `labels`: as ``export_pose``.

    **Returns** the path.  **Raises** ``ValueError`` (one line) for a bad suffix or value, a
    folder that does not exist (none is made), a stroke that cannot be assembled
    (``run_scene``) or a pose that cannot be reached.
    """
    from ..scenes import run_scene

    _checked_path(path)
    if int(swept) < 0:
        raise ValueError(f"swept must be a number of poses >= 0, got {swept}")
    scene, p, names, result = _resolve(obj, params)
    if result is None:
        result = run_scene(scene, points=points, **dict(params or {}))
    spec = _spec(scene, result.params)
    trace = list(spec.get("trace", ())) if trace is None else ([trace] if isinstance(trace, str) else list(trace))
    for t in trace:
        check_point(scene, t)
    from ..viz.drawing import point_positions

    paths = point_positions(result, spec_points(spec) + trace)
    pose = _pose_of_result(result, 0, names) if at is None else solve_pose(scene, at, params=result.params)
    pose = dataclasses.replace(pose, names=names)
    sheet = Sheet()
    r = _radius(joint_radius, [z for v in paths.values() for z in np.ravel(v)])
    _draw_pose(sheet, pose, r, paths=paths, labels=labels)
    for k, t in enumerate(trace):
        layer = sheet.layer(f"path_{t}", "path", 1 + k % 6)
        z = np.asarray(paths[t])
        ok = np.isfinite(z)
        # one polyline per stretch of assembled samples (a gap is not bridged)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            sheet.polyline(layer, z[a:b])
    n = result.motion.q.shape[0]
    idx = np.unique(np.round(np.linspace(0, n - 1, int(swept))).astype(int)) if swept else []
    for kind, name, pts, closed in _members(spec, names):
        layer = sheet.layer(f"sweep_{name}", "sweep", _COLORS["sweep"])
        for i in idx:
            sheet.polyline(layer, [paths[x][i] for x in pts], closed)
    return _write(sheet, pose, path, units, "stroke")
