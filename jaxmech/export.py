"""CAD export: a pose of a mechanism, or its stroke, as DXF (ezdxf) or SVG, to take a
linkage from a study into a CAD tool.

What is drawn comes from the scene's drawing spec (``jaxmech.drawing``): every link, plate
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
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .drawing import check_point, check_spec, spec_points
from .units import for_reading, to_si

__all__ = ["Pose", "solve_pose", "export_pose", "write_pose", "export_stroke", "input_value", "link_names", "SUFFIXES"]

#: The file types written, by suffix.
SUFFIXES = (".dxf", ".svg")

#: XDATA application name of the joint circles in a DXF.
APPID = "JAXMECH"

#: Samples on the way from the stroke's start to the pose, per stroke length (as dense as
#: a 101-point run of the stroke).
PATH_SAMPLES = 101
#: At most this many stroke lengths from the stroke's start are walked to a pose.
MAX_STROKES = 64

_UNITS = {"m": 1.0, "mm": 1000.0}


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


def _resolve(obj, params):
    """``(scene, params, names, result)`` of a ``Scene``, ``SceneResult``, ``Linkage``, a scene
    name or a linkage file's path."""
    from .linkage import Linkage
    from .scenes import SceneResult, get_scene
    from .scenes.base import Scene
    from .scenes.linkage_scene import linkage_scene, scene_from_file

    names, result = {}, None
    if isinstance(obj, (str, Path)):
        if str(obj).lower().endswith((".toml", ".json")):
            from .linkage.files import read_linkage_file

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
    return scene, p, names, result


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

    from .continuation import solve_stroke
    from .scenes.evaluation import SCENE_OPTIONS
    from .status import Status, status_message

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


# --------------------------------------------------------------------------- a drawing in model coordinates
class _Sheet:
    """Layers and entities in model coordinates (m), written by ``_write_dxf`` / ``_write_svg``."""

    def __init__(self):
        self.layers: dict[str, tuple[str, int]] = {}  # name -> (kind, ACI colour)
        self.items: list[tuple] = []

    def layer(self, name: str, kind: str, color: int) -> str:
        """The layer ``name`` of this kind (created on first use); a name taken by another
        kind, or differing only in case (DXF layer names are not case-sensitive), gets a
        suffix ``_2``, ``_3``..."""
        taken = {n.lower(): (n, k) for n, (k, _) in self.layers.items()}
        key, n = name, 2
        while key.lower() in taken and taken[key.lower()] != (key, kind):
            key, n = f"{name}_{n}", n + 1
        self.layers.setdefault(key, (kind, color))
        return key

    def polyline(self, layer, zs, closed=False):
        zs = [complex(z) for z in zs]
        if len(zs) >= 2 and all(np.isfinite(z) for z in zs):
            self.items.append(("polyline", layer, zs, closed))

    def circle(self, layer, c, r, point=None):
        if np.isfinite(c):
            self.items.append(("circle", layer, complex(c), float(r), point))

    def arc(self, layer, c, r, a0, a1):
        if a1 - a0 >= 2 * math.pi - 1e-12:
            self.circle(layer, c, r)
        elif np.isfinite(c):
            self.items.append(("arc", layer, complex(c), float(r), float(a0), float(a1)))

    def text(self, layer, z, s, h):
        if np.isfinite(z):
            self.items.append(("text", layer, complex(z), str(s), float(h)))

    def extent(self):
        zs = []
        for it in self.items:
            if it[0] == "polyline":
                zs += it[2]
            elif it[0] in ("circle", "arc"):
                zs += [it[2] - it[3] * (1 + 1j), it[2] + it[3] * (1 + 1j)]
            elif it[0] == "text":
                zs.append(it[2])
        z = np.array(zs or [0j])
        return z.real.min(), z.imag.min(), z.real.max(), z.imag.max()


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
    sweeps over the stroke plus a margin (as ``jaxmech.drawing``); else the whole circle."""
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


def _draw_pose(sheet: _Sheet, pose: Pose, r: float, *, paths=None, labels=True):
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
def _fmt(x: float) -> str:
    return repr(float(x))


def _meta(pose: Pose, units: str) -> dict:
    return {"jaxmech_scene": pose.scene.name, "jaxmech_input": pose.input_name, "jaxmech_value_si": repr(pose.at),
            "jaxmech_input_unit": pose.scene.units.get(pose.input_name, ""), "jaxmech_units": units}


def _write_dxf(sheet: _Sheet, path: Path, units: str, meta: dict):
    import ezdxf
    from ezdxf import units as dxf_units

    f = _UNITS[units]
    doc = ezdxf.new("R2010", setup=True)
    doc.units = dxf_units.M if units == "m" else dxf_units.MM
    doc.header["$MEASUREMENT"] = 1
    doc.appids.add(APPID)
    for k, v in meta.items():
        doc.header.custom_vars.append(k, str(v))
    for name, (kind, color) in sheet.layers.items():
        doc.layers.add(name, color=color)
    msp = doc.modelspace()
    xy = lambda z: (z.real * f, z.imag * f)  # noqa: E731
    for it in sheet.items:
        kind, layer = it[0], it[1]
        attrs = {"layer": layer}
        if kind == "polyline":
            msp.add_lwpolyline([xy(z) for z in it[2]], format="xy", close=it[3], dxfattribs=attrs)
        elif kind == "circle":
            c = msp.add_circle(xy(it[2]), it[3] * f, dxfattribs=attrs)
            if it[4] is not None:
                c.set_xdata(APPID, [(1000, "joint"), (1000, it[4])])
        elif kind == "arc":
            msp.add_arc(xy(it[2]), it[3] * f, math.degrees(it[4]), math.degrees(it[5]), dxfattribs=attrs)
        elif kind == "text":
            msp.add_text(it[3], height=it[4] * f, dxfattribs={**attrs, "insert": xy(it[2])})
    doc.saveas(path)


_SVG_NS = "http://www.w3.org/2000/svg"


def _write_svg(sheet: _Sheet, path: Path, units: str, meta: dict, title: str):
    f = _UNITS[units]
    x0, y0, x1, y1 = sheet.extent()
    m = 0.05 * max(x1 - x0, y1 - y0, 1e-9)
    x0, y0, x1, y1 = (x0 - m) * f, (y0 - m) * f, (x1 + m) * f, (y1 + m) * f
    w, h = x1 - x0, y1 - y0
    mm = 1000.0 / f  # mm per user unit: the drawing is 1:1
    ET.register_namespace("", _SVG_NS)
    root = ET.Element("svg", {"xmlns": _SVG_NS, "version": "1.1", "width": f"{_fmt(w * mm)}mm", "height": f"{_fmt(h * mm)}mm",
                              "viewBox": " ".join(_fmt(v) for v in (x0, -y1, w, h)),
                              **{f"data-{k.replace('_', '-')}": str(v) for k, v in meta.items()}})
    ET.SubElement(root, "title").text = title
    ET.SubElement(root, "desc").text = (f"jaxmech export: model coordinates in {units}, y up (the group 'model' flips y); "
                                        "one group per layer (id), joints are circles with data-point")
    lw = 0.004 * max(w, h)
    css = [f"g#model {{ fill: none; stroke-linecap: round; stroke-linejoin: round; stroke-width: {_fmt(lw)}; }}",
           ".link, .chord { stroke: #222; }", ".chord { stroke: #1f77b4; }",
           ".plate polygon { fill: #bbb; fill-opacity: 0.6; stroke: #444; }", ".ground { stroke: #555; }",
           ".slot { stroke: #ff7f0e; }", ".points { stroke: #d62728; }", ".path { stroke: #2ca02c; stroke-dasharray: none; }",
           f".sweep {{ stroke: #999; stroke-opacity: 0.5; stroke-width: {_fmt(0.5 * lw)}; }}",
           ".joint { fill: #fff; }", ".labels { fill: #333; stroke: none; font-family: sans-serif; }"]
    ET.SubElement(root, "style").text = "\n".join(css)
    model = ET.SubElement(root, "g", {"id": "model", "transform": "scale(1 -1)"})
    groups = {name: ET.SubElement(model, "g", {"id": name, "class": kind}) for name, (kind, _) in sheet.layers.items()}
    xy = lambda z: (_fmt(z.real * f), _fmt(z.imag * f))  # noqa: E731
    for it in sheet.items:
        kind, g = it[0], groups[it[1]]
        if kind == "polyline":
            pts = " ".join(",".join(xy(z)) for z in it[2])
            ET.SubElement(g, "polygon" if it[3] else "polyline", {"points": pts})
        elif kind == "circle":
            cx, cy = xy(it[2])
            attrs = {"cx": cx, "cy": cy, "r": _fmt(it[3] * f)}
            if it[4] is not None:
                attrs.update({"class": "joint", "data-point": it[4]})
            ET.SubElement(g, "circle", attrs)
        elif kind == "arc":
            c, r, a0, a1 = it[2], it[3], it[4], it[5]
            p0, p1 = c + r * complex(math.cos(a0), math.sin(a0)), c + r * complex(math.cos(a1), math.sin(a1))
            large = 1 if a1 - a0 > math.pi else 0
            d = f"M {' '.join(xy(p0))} A {_fmt(r * f)} {_fmt(r * f)} 0 {large} 1 {' '.join(xy(p1))}"
            ET.SubElement(g, "path", {"d": d})
        elif kind == "text":
            x, y = xy(it[2])
            t = ET.SubElement(g, "text", {"x": "0", "y": "0", "font-size": _fmt(it[4] * f),
                                          "transform": f"translate({x} {y}) scale(1 -1)"})
            t.text = it[3]
    tree = ET.ElementTree(root)
    ET.indent(tree)
    tree.write(path, encoding="utf-8", xml_declaration=True)


def _write(sheet: _Sheet, pose: Pose, path, units: str, what: str) -> Path:
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(f"export path must end in {' or '.join(SUFFIXES)}, got {str(path)!r}")
    if units not in _UNITS:
        raise ValueError(f"units must be one of {list(_UNITS)}, got {units!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = _meta(pose, units)
    if suffix == ".dxf":
        _write_dxf(sheet, path, units, meta)
    else:
        _write_svg(sheet, path, units, meta, f"{what}: {pose.describe()}")
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

    **Returns** the path.  **Raises** ``ValueError`` (one line) for a bad suffix or value, or
    a pose the mechanism cannot reach (``solve_pose``).
    """
    if Path(path).suffix.lower() not in SUFFIXES:
        raise ValueError(f"export path must end in {' or '.join(SUFFIXES)}, got {str(path)!r}")
    pose = solve_pose(obj, at, params=params)
    return write_pose(pose, path, units=units, joint_radius=joint_radius, labels=labels)


def write_pose(pose: Pose, path, *, units: str = "m", joint_radius: float | None = None, labels: bool = True) -> Path:
    """Write a solved ``Pose`` (``solve_pose``) to ``path`` (``.dxf`` or ``.svg``)."""
    zs = [pose.point(x) for x in spec_points(pose.spec)]
    sheet = _Sheet()
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
    stroke that cannot be assembled (``run_scene``) or a pose that cannot be reached.
    """
    from .scenes import run_scene

    if Path(path).suffix.lower() not in SUFFIXES:
        raise ValueError(f"export path must end in {' or '.join(SUFFIXES)}, got {str(path)!r}")
    if int(swept) < 0:
        raise ValueError(f"swept must be a number of poses >= 0, got {swept}")
    scene, p, names, result = _resolve(obj, params)
    if result is None:
        result = run_scene(scene, points=points, **dict(params or {}))
    spec = _spec(scene, result.params)
    trace = list(spec.get("trace", ())) if trace is None else ([trace] if isinstance(trace, str) else list(trace))
    for t in trace:
        check_point(scene, t)
    from .drawing import point_positions

    paths = point_positions(result, spec_points(spec) + trace)
    pose = _pose_of_result(result, 0, names) if at is None else solve_pose(scene, at, params=result.params)
    pose = dataclasses.replace(pose, names=names)
    sheet = _Sheet()
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
