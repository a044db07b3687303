"""CAD export (jaxmech.export, ``jaxmech export``): DXF read back with ezdxf and SVG read
back with xml.etree; every joint circle against the pose solved independently of the
export (the four-bar's and the landing gear's closed forms) to 1e-9 m, the traced paths
against the run's points, layers and groups per link, and the command's one-line errors."""

import jax

jax.config.update("jax_enable_x64", True)

import math  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import xml.etree.ElementTree as ET  # noqa: E402
from pathlib import Path  # noqa: E402

import ezdxf  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from helpers import fourbar_closed  # noqa: E402

from jaxmech import load_linkage  # noqa: E402
from jaxmech.export.pose import APPID, export_pose, export_stroke, solve_pose, write_pose  # noqa: E402
from jaxmech.scenes import get_scene, run_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CACHE = Path(tempfile.gettempdir()) / "jaxmech-test-xla-cache"
TOL = 1e-9  # m: the acceptance bound for a joint read back from a file
SVG = "{http://www.w3.org/2000/svg}"


# ----------------------------------------------------------------------- independent poses
def fourbar_pose(theta2, a=1.0, b=3.0, c=2.5, d=3.5):
    """The four-bar's joints from its closed form (open assembly, the scene's branch)."""
    t3, t4 = (float(v) for v in fourbar_closed(theta2, a, b, c, d))
    A = a * complex(math.cos(theta2), math.sin(theta2))
    return {"O2": 0j, "O4": complex(d), "A": A, "B": d + c * complex(math.cos(t4), math.sin(t4)),
            "P": A + 0.5 * b * complex(math.cos(t3), math.sin(t3))}


def gear_pose(x, p):
    """The landing gear's joints from the law of cosines, x^2 = d^2 + h^2 - 2 d h cos(theta),
    on the scene's branch (sin theta > 0; the gear angle clockwise)."""
    d, h, AB, beta = p["d"], p["h"], p["AB"], p["beta"]
    th = math.acos((d * d + h * h - x * x) / (2 * d * h))
    cis = lambda a: complex(math.cos(a), math.sin(a))  # noqa: E731
    return {"B": 0j, "C": complex(h), "P": d * cis(-th), "A": AB * cis(-(th + beta))}


# ----------------------------------------------------------------------- reading the files back
def dxf_joints(path, scale=1.0):
    """``{name: [centres]}`` of the joint circles (XDATA ``JAXMECH``), the document, and
    ``{layer: [LWPOLYLINE vertices]}``."""
    doc = ezdxf.readfile(path)
    assert not doc.audit().has_errors
    joints, polylines = {}, {}
    for e in doc.modelspace():
        if e.dxftype() == "CIRCLE" and e.has_xdata(APPID):
            tags = [t.value for t in e.get_xdata(APPID)]
            assert tags[0] == "joint"
            c = e.dxf.center
            joints.setdefault(tags[1], []).append(complex(c.x, c.y) / scale)
        elif e.dxftype() == "LWPOLYLINE":
            polylines.setdefault(e.dxf.layer, []).append([complex(x, y) / scale for x, y in e.get_points("xy")])
    return joints, doc, polylines


def svg_joints(path):
    """``{name: [centres]}`` of the joint circles, ``{group id: class}`` and ``{group id:
    [polyline points]}``, in model coordinates (the y-flip checked)."""
    root = ET.parse(path).getroot()
    (model,) = [g for g in root.iter(f"{SVG}g") if g.get("id") == "model"]
    assert model.get("transform") == "scale(1 -1)"
    joints, groups, polylines = {}, {}, {}
    for g in model.findall(f"{SVG}g"):
        groups[g.get("id")] = g.get("class")
        for c in g.findall(f"{SVG}circle"):
            if c.get("class") == "joint":
                joints.setdefault(c.get("data-point"), []).append(complex(float(c.get("cx")), float(c.get("cy"))))
        for pl in [*g.findall(f"{SVG}polyline"), *g.findall(f"{SVG}polygon")]:
            pts = [complex(*map(float, xy.split(","))) for xy in pl.get("points").split()]
            polylines.setdefault(g.get("id"), []).append(pts)
    return joints, groups, polylines


def max_error(joints, truth):
    """Largest distance (m) of a joint circle from the true joint; every true joint drawn."""
    assert set(truth) <= set(joints), f"joints missing: {set(truth) - set(joints)}"
    return max(abs(z - truth[n]) for n, zs in joints.items() if n in truth for z in zs)


# ----------------------------------------------------------------------- poses
def test_fourbar_pose_dxf_and_svg(tmp_path):
    truth = fourbar_pose(1.0)
    pose = solve_pose("fourbar", 1.0)
    for suffix in (".dxf", ".svg"):
        path = export_pose("fourbar", 1.0, tmp_path / f"pose{suffix}")
        if suffix == ".dxf":
            joints, doc, lines = dxf_joints(path)
            layers = {layer.dxf.name for layer in doc.layers}
            assert doc.units == ezdxf.units.M
            assert doc.header.custom_vars.get("jaxmech_scene") == "fourbar"
            assert float(doc.header.custom_vars.get("jaxmech_value_si")) == 1.0
        else:
            joints, groups, lines = svg_joints(path)
            layers = set(groups)
            assert groups["link_O2-A"] == "link" and groups["ground"] == "ground"
        assert {"link_O2-A", "link_A-B", "link_O4-B", "ground", "labels"} <= layers
        assert set(joints) == {"O2", "A", "B", "O4", "P"}
        assert max_error(joints, truth) < TOL
        # the round trip itself is exact: the file holds the solved doubles
        assert all(z == pose.positions[n] for n, zs in joints.items() for z in zs)
        # each link is a polyline through its joints, on its own layer
        assert lines["link_A-B"] == [[pose.positions["A"], pose.positions["B"]]]
        assert len(joints["A"]) == 2  # on the crank's layer and the coupler's


def test_seed_pose_landing_gear(tmp_path):
    scene = get_scene("landing_gear")
    truth = gear_pose(0.45, scene.params())
    for suffix, at in ((".dxf", 0.45), (".svg", "450mm")):
        path = export_pose(scene, at, tmp_path / f"gear{suffix}")
        joints, layers = (dxf_joints(path)[0], None) if suffix == ".dxf" else svg_joints(path)[:2]
        assert set(joints) == {"A", "B", "C", "P"}
        assert max_error(joints, truth) < TOL
        if layers is not None:
            assert {"link_B-P", "link_B-A", "link_C-P"} <= set(layers)


def test_millimetres(tmp_path):
    pose = solve_pose("fourbar", "60deg")
    truth = fourbar_pose(math.radians(60.0))
    joints, doc, _ = dxf_joints(write_pose(pose, tmp_path / "mm.dxf", units="mm"), scale=1000.0)
    assert doc.units == ezdxf.units.MM
    assert max_error(joints, truth) < TOL
    root = ET.parse(write_pose(pose, tmp_path / "mm.svg", units="mm")).getroot()
    assert root.get("data-jaxmech-units") == "mm"
    joints = svg_joints(tmp_path / "mm.svg")[0]
    assert max_error({k: [z / 1000.0 for z in v] for k, v in joints.items()}, truth) < TOL


def test_linkage_layers_named_after_links(tmp_path):
    lk = load_linkage(ROOT / "examples" / "linkages" / "fourbar.toml")
    joints, groups, _ = svg_joints(export_pose(lk, 1.0, tmp_path / "lk.svg"))
    assert {"link_crank", "link_coupler", "link_rocker"} <= set(groups)
    assert groups["link_coupler"] == "plate"
    assert max_error(joints, fourbar_pose(1.0)) < TOL


# ----------------------------------------------------------------------- a stroke
def test_stroke_paths_and_sweep(tmp_path):
    scene = get_scene("landing_gear")
    result = run_scene(scene)
    points = {n: np.asarray(result.motion.points[n][0]) for n in ("A", "P")}
    xs = np.asarray(result.motion.u[:, 0])
    for suffix in (".dxf", ".svg"):
        path = export_stroke(result, tmp_path / f"stroke{suffix}", swept=5)
        joints, _, lines = dxf_joints(path) if suffix == ".dxf" else svg_joints(path)
        for n in ("A", "P"):
            (path_n,) = lines[f"path_{n}"]
            assert np.array_equal(np.array(path_n), points[n])  # the run's points, bit for bit
            truth = np.array([gear_pose(x, result.params)[n] for x in xs])
            assert np.max(np.abs(np.array(path_n) - truth)) < TOL
        assert len(lines["sweep_link_B-P"]) == 5
        # the pose drawn is the stroke's first sample
        assert max_error(joints, gear_pose(xs[0], result.params)) < TOL


# ----------------------------------------------------------------------- mistakes
def test_python_errors(tmp_path):
    with pytest.raises(ValueError, match=r"must end in \.dxf or \.svg"):
        export_pose("fourbar", 1.0, tmp_path / "pose.png")
    with pytest.raises(ValueError, match="cannot be assembled at x = 0.2 m"):
        solve_pose("landing_gear", 0.2)  # below h - d = 0.232 m
    # assembles at 4 rad, but a crank of 2.2 m cannot turn there from 0: no jump across the gap
    with pytest.raises(ValueError, match="cannot be reached from the stroke's start"):
        solve_pose("fourbar", 4.0, params={"a": 2.2})
    with pytest.raises(ValueError, match="does not fit"):
        solve_pose("landing_gear", "30deg")
    assert not (tmp_path / "pose.png").exists()


def jaxmech(*args, cwd):
    env = {**os.environ, "JAX_COMPILATION_CACHE_DIR": str(CACHE), "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "jaxmech", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=300)


def test_cli_as_typed(tmp_path):
    truth = fourbar_pose(1.0)
    for out in ("pose.dxf", "pose.svg"):
        proc = jaxmech("export", "fourbar", "--at", "1.0", "--out", out, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert f"wrote {out}" in proc.stdout
        joints = dxf_joints(tmp_path / out)[0] if out.endswith(".dxf") else svg_joints(tmp_path / out)[0]
        assert max_error(joints, truth) < TOL


@pytest.mark.parametrize("args, message", [
    (("fourbar", "--at", "1.0", "--out", "pose.png"), "--out must end in .dxf or .svg"),
    (("no_such_scene", "--at", "1.0", "--out", "pose.dxf"), "unknown scene 'no_such_scene'"),
    (("landing_gear", "--at", "200mm", "--out", "pose.dxf"), "cannot be assembled at x = 0.2 m"),
])  # fmt: skip
def test_cli_one_line_errors(tmp_path, args, message):
    proc = jaxmech("export", *args, cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.startswith("jaxmech: error: ") and message in proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []
