"""Drawings in model coordinates written as CAD files: a ``Sheet`` of layers and
entities (polylines, circles, arcs, text; positions complex, in m) and its DXF (ezdxf) and
SVG writers.

Coordinates are written in full float64 precision (Python's ``repr``, the shortest decimal
that reads back to the same double), so a point read back is the point written, to the last
bit in metres (``"mm"`` multiplies by 1000: one rounding).  What to draw is
``jaxmech.export``'s business; this module knows nothing of mechanisms.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import NamedTuple
from pathlib import Path

import numpy as np

__all__ = ["Sheet", "write_dxf", "write_svg", "UNIT_SCALE", "APPID"]

APPID = "JAXMECH"  # the DXF application id of the joints' XDATA
UNIT_SCALE = {"m": 1.0, "mm": 1000.0}  # drawing units per metre


class Extent(NamedTuple):
    """A sheet's bounding box (``Sheet.extent``), in the drawing's units."""

    x0: float
    y0: float
    x1: float
    y1: float


class Sheet:
    """Layers and entities in model coordinates (m), written by ``write_dxf`` / ``write_svg``.

    Items are tuples: ``("polyline", layer, points, closed)``, ``("circle", layer, centre, r,
    point name or None)``, ``("arc", layer, centre, r, start, end)`` (rad),
    ``("text", layer, position, text, height)``; positions are complex (x + iy, m)."""

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

    def extent(self) -> Extent:
        """The box around every item (circles and arcs whole; a text at its anchor)."""
        zs = []
        for it in self.items:
            if it[0] == "polyline":
                zs += it[2]
            elif it[0] in ("circle", "arc"):
                zs += [it[2] - it[3] * (1 + 1j), it[2] + it[3] * (1 + 1j)]
            elif it[0] == "text":
                zs.append(it[2])
        z = np.array(zs or [0j])
        return Extent(z.real.min(), z.imag.min(), z.real.max(), z.imag.max())


def _fmt(x: float) -> str:
    return repr(float(x))


def write_dxf(sheet: Sheet, path: Path, units: str, meta: dict):
    """Write ``sheet`` as DXF R2010 (ezdxf) in ``units`` ("m" or "mm"): one layer per sheet layer,
    LWPOLYLINE / CIRCLE (joints with XDATA ``JAXMECH``: "joint", name) / ARC / TEXT; ``meta`` as
    the header's custom properties."""
    import ezdxf
    from ezdxf import units as dxf_units

    f = UNIT_SCALE[units]
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


SVG_NS = "http://www.w3.org/2000/svg"


def write_svg(sheet: Sheet, path: Path, units: str, meta: dict, title: str):
    """Write ``sheet`` as a 1:1 SVG in ``units``: the model in ``<g id="model">`` flipped to y up,
    one ``<g>`` per layer, joints as ``<circle class="joint" data-point=...>``, ``meta`` as
    ``data-*`` attributes of the root."""
    f = UNIT_SCALE[units]
    x0, y0, x1, y1 = sheet.extent()
    m = 0.05 * max(x1 - x0, y1 - y0, 1e-9)
    x0, y0, x1, y1 = (x0 - m) * f, (y0 - m) * f, (x1 + m) * f, (y1 + m) * f
    w, h = x1 - x0, y1 - y0
    mm = 1000.0 / f  # mm per user unit: the drawing is 1:1
    ET.register_namespace("", SVG_NS)
    root = ET.Element("svg", {"xmlns": SVG_NS, "version": "1.1", "width": f"{_fmt(w * mm)}mm", "height": f"{_fmt(h * mm)}mm",
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
