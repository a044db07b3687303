"""Joint friction in linkage files (``[friction]`` in TOML, ``"friction"`` in JSON):

- a TOML and a JSON file with friction (``all``, a pin's own entry with damping, a slider
  by its joint's full name or its block; units in strings; ``width``) are the linkage built
  in Python with ``friction=``: the same parameters and friction, and the same crank torque
  and friction loads along a reversing drive, bit for bit;
- a misspelt or bad friction entry is refused in one line naming the file, the key and the
  fix;
- ``jaxmech scenes`` on a file with friction lists the friction parameters with their units
  and ``jaxmech export`` draws it; a scene made of the file's linkage by ``linkage_scene``
  has them as parameters (``tests/test_friction_scenes.py`` runs such files).
"""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.cli.commands import main  # noqa: E402
from jaxmech.scenes.linkage_scene import linkage_scene  # noqa: E402

DRAWING = """name = "press"
ground = "O"
driver = "crank"
gravity = 9.81

[points]
O = [0.0, 0.0]
A = ["0mm", "100mm"]
B = [0.335410196625, 0.0]

[links]
crank = "O A"
rod = "A B"
piston = "B"

[sliders]
piston = { on = "ground", angle = "0deg" }

[mass]
crank = "300g"
rod = 0.8
piston = 0.5

[forces]
B = { force = [-200.0, 0.0], on = "piston" }
"""

FRICTION_TOML = """
[friction]
width = 2e-3

[friction.all]
mu = 0.1
radius = "5 mm"

[friction.A]
mu = 0.12
radius = "8 mm"
damping = "0.5 N m s/rad"

[friction."piston on ground"]
mu = 0.15
damping = "40 N s/m"
"""

FRICTION_JSON = {"all": {"mu": 0.1, "radius": "5 mm"}, "A": {"mu": 0.12, "radius": 0.008, "damping": 0.5},
                 "piston": {"mu": 0.15, "damping": 40.0}, "width": 0.002}


def in_python(**kw):
    """The file's linkage built in Python."""
    return jm.Linkage(points={"O": (0.0, 0.0), "A": (0.0, 0.1), "B": (0.335410196625, 0.0)},
                      links={"crank": "O A", "rod": "A B", "piston": "B"}, ground="O", driver="crank",
                      sliders={"piston": {"on": "ground", "angle": 0.0}}, mass={"crank": 0.3, "rod": 0.8, "piston": 0.5},
                      gravity=9.81, forces={"B": {"force": (-200.0, 0.0), "on": "piston"}}, name="press", **kw)


def rocking():
    t = np.linspace(0.0, np.pi, 31)
    th0 = np.pi / 2  # the drawing's crank angle
    return jm.Samples(th0 + 1.0 * np.sin(2 * t), 2.0 * np.cos(2 * t), -4.0 * np.sin(2 * t), t)


def json_text(friction) -> str:
    data = {"name": "press", "ground": "O", "driver": "crank", "gravity": 9.81,
            "points": {"O": [0.0, 0.0], "A": [0.0, 0.1], "B": [0.335410196625, 0.0]},
            "links": {"crank": "O A", "rod": "A B", "piston": "B"}, "sliders": {"piston": {"on": "ground", "angle": 0.0}},
            "mass": {"crank": 0.3, "rod": 0.8, "piston": 0.5}, "forces": {"B": {"force": [-200.0, 0.0], "on": "piston"}},
            "friction": friction}
    return json.dumps(data)


@pytest.mark.parametrize("kind", ["toml", "json"])
def test_a_file_with_friction_is_the_linkage_built_in_python(kind, tmp_path):
    path = tmp_path / f"press.{kind}"
    path.write_text(DRAWING + FRICTION_TOML if kind == "toml" else json_text(FRICTION_JSON))
    lk = jm.load_linkage(path)
    py = in_python(friction={"all": {"mu": 0.1, "radius": 0.005}, "A": {"mu": 0.12, "radius": 0.008, "damping": 0.5},
                             "piston on ground": {"mu": 0.15, "damping": 40.0}, "width": 2e-3})
    assert lk.friction == py.friction and lk.friction.width == 2e-3 and len(lk.friction.joints) == 4
    assert lk.params == py.params
    assert {k: lk.params[k] for k in ("mu_O", "rpin_O", "rpin_A", "cv_A", "mu_piston", "cv_piston")} == \
        {"mu_O": 0.1, "rpin_O": 0.005, "rpin_A": 0.008, "cv_A": 0.5, "mu_piston": 0.15, "cv_piston": 40.0}
    a, b = lk.inverse_dynamics(rocking()), py.inverse_dynamics(rocking())
    assert np.all(np.asarray(a.status) == jm.Status.CONVERGED)
    assert np.array_equal(np.asarray(a.tau), np.asarray(b.tau))
    for j in py.joints:
        assert np.array_equal(np.asarray(a.joints[j]), np.asarray(b.joints[j])), j
    for j in b.joint_friction:
        assert np.array_equal(np.asarray(a.joint_friction[j]), np.asarray(b.joint_friction[j])), j
    # the friction takes part: without it the torque differs
    bare = in_python().inverse_dynamics(rocking())
    assert np.max(np.abs(np.asarray(a.tau - bare.tau))) > 1e-2 * np.max(np.abs(np.asarray(bare.tau)))


BAD = {  # the friction part of a TOML file -> what its one line says (after "press.toml: ")
    "misspelt key": ('[friction.all]\nmu = 0.1\nraduis = "5 mm"\n',
                     "friction['all']: unknown key(s) ['raduis']; the keys are ['mu', 'radius', 'damping']; did you mean 'radius'?"),
    "misspelt joint": ('[friction.AA]\nmu = 0.1\nradius = "5 mm"\n', "friction: 'AA' is not a pin, slider or slot"),
    "misspelt table": ('[fricton.all]\nmu = 0.1\n', "unknown key(s) ['fricton']"),
    "not a table": ("[friction]\nall = 0.1\n", "friction['all'] must be a table like"),
    "a number": ("", "friction must be a table like"),
    "no radius": ("[friction.A]\nmu = 0.1\n", "friction at pin 'A' needs its radius="),
    "a slider's radius": ('[friction.piston]\nmu = 0.1\nradius = "5 mm"\n', "'piston on ground' is a slider or slot: it has no pin radius"),
    "negative": ('[friction.all]\nmu = -0.1\nradius = "5 mm"\n', "friction['all'].mu must not be negative"),
    "wrong unit": ('[friction.all]\nmu = 0.1\nradius = "5 s"\n', "friction['all'].radius"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_friction_in_a_file_is_one_line_naming_the_file_and_the_key(case, tmp_path):
    text, says = BAD[case]
    head = DRAWING.replace('gravity = 9.81\n', 'gravity = 9.81\nfriction = 0.1\n') if case == "a number" else DRAWING
    (tmp_path / "press.toml").write_text(head + text)
    with pytest.raises(ValueError) as err:
        jm.load_linkage(tmp_path / "press.toml")
    msg = str(err.value)
    assert msg.startswith("press.toml: ") and says in msg and "\n" not in msg, msg
    if case == "misspelt joint":
        assert "did you mean 'A'?" in msg
    if case == "misspelt table":
        assert "did you mean 'friction'?" in msg


def test_bad_friction_in_json_names_the_file_and_the_key(tmp_path):
    (tmp_path / "press.json").write_text(json_text({"all": {"mu": 0.1, "radus": 0.005}}))
    with pytest.raises(ValueError, match=r"^press\.json: press: friction\['all'\]: unknown key\(s\) \['radus'\].*did you mean 'radius'\?$"):
        jm.load_linkage(tmp_path / "press.json")


def test_the_command_line_takes_a_file_with_friction(tmp_path, monkeypatch, capsys):
    (tmp_path / "press.toml").write_text(DRAWING + FRICTION_TOML)
    monkeypatch.chdir(tmp_path)
    assert main(["scenes", "press.toml"]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[2:] if line.strip()}
    for name, unit in (("mu_O", "-"), ("rpin_A", "m"), ("cv_A", "N m s/rad"), ("cv_piston", "N s/m")):
        assert rows[name].split(None, 1)[1].startswith(unit + " ") and rows[name].endswith("joint friction"), rows[name]
    assert main(["export", "press.toml", "--out", "p.svg"]) == 0
    assert (tmp_path / "p.svg").stat().st_size > 0


def test_a_scene_of_a_linkage_with_friction_has_its_parameters():
    scene = linkage_scene(in_python(friction=FRICTION_JSON))
    lk = in_python(friction=FRICTION_JSON)
    assert {k: scene.defaults[k] for k in lk.friction.parameters} == {k: lk.params[k] for k in lk.friction.parameters}
    assert scene.parameters["cv_A"][0] == "N m s/rad" and scene.parameters["cv_piston"][0] == "N s/m"
    assert linkage_scene(in_python()).name == "press"
