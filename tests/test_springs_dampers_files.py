"""Springs and dampers from a linkage file, without elements, and from bad input:

- a linkage with no springs or dampers (or empty tables of them) computes what it computed
  before, bit for bit; elements with zero stiffness, force and damping change nothing;
- a TOML and a JSON file with every kind of element (values with their units) are the
  linkage built in Python; the example file ``examples/linkages/counterbalanced_flap.toml``
  is the flap of ``docs/springs_and_dampers.md``, built in Python, and gives the page's numbers;
- bad input is refused at construction, in one message naming the element and the fix.
"""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402
import re  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from test_springs_dampers import CT, FREE_T, GAS_F, GAS_LG, GAS_N, SM, C, F0, K, KT, L0, LOAD, MOMENT, slider_crank, samples  # noqa: E402

import jaxmech as jm  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
NONE = dict(springs={}, torsion_springs={}, gas_springs={}, dampers={}, rotary_dampers={})


def assert_same_dynamics(a, b, rtol):
    """Torque and every joint's reaction of two linkages along the test's drive, within
    `rtol` of each quantity's largest value (0: bit for bit)."""
    ra, rb = a.inverse_dynamics(samples()), b.inverse_dynamics(samples())
    assert np.all(np.asarray(ra.status) == jm.Status.CONVERGED)
    pairs = [(ra.tau, rb.tau), (ra.q, rb.q)] + [(ra.joints[j], rb.joints[j]) for j in a.joints]
    for x, y in pairs:
        x, y = np.asarray(x), np.asarray(y)
        if rtol == 0:
            assert np.array_equal(x, y)
        else:
            np.testing.assert_allclose(x, y, rtol=0, atol=rtol * np.max(np.abs(y)))


def test_no_elements_is_unchanged_bit_for_bit():
    bare = slider_crank(springs=None, dampers=None)
    empty = slider_crank(**NONE)
    assert bare.topology == empty.topology and bare.topology.elements == ()
    assert bare.params == empty.params
    assert not [k for k in bare.params if k.split("_")[0] in ("k", "L0", "F0", "kt", "phi0", "Lg", "n", "c", "ct")]
    assert_same_dynamics(bare, empty, 0)
    # elements that carry nothing (zero stiffness, preload, force and damping) change nothing
    idle = slider_crank(every=True, forces={}, moments={})
    zero = {k: 0.0 for k in idle.params if k.split("_")[0] in ("k", "F0", "kt", "c", "ct")}
    ra, rb = idle.inverse_dynamics(samples(), p=zero), bare.inverse_dynamics(samples())
    for x, y in [(ra.tau, rb.tau)] + [(ra.joints[j], rb.joints[j]) for j in bare.joints]:
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=0, atol=1e-13 * np.max(np.abs(np.asarray(y))))


def _toml(lk) -> str:
    """The slider-crank with every element as a TOML file, its elements' values with units."""
    pts = "\n".join(f"{k} = [{z.real!r}, {z.imag!r}]" for k, z in lk.points.items())
    return f"""name = "every_element"
ground = ["O", "S", "D", "S2"]
driver = "crank"
gravity = "9.81 m/s^2"

[points]
{pts}

[links]
crank = "O A"
rod = "A B"

[sliders]
B = {{ angle = "0deg" }}

[mass]
crank = {SM['crank']!r}
rod = "{SM['rod'] * 1000!r} g"
block_B = {SM['block_B']!r}

[forces]
B = {{ force = ["{LOAD.real / 1000!r} kN", {LOAD.imag!r}], on = "block_B" }}

[moments]
rod = "{MOMENT!r} N m"

[springs.s1]
between = ["S", "B"]
on = ["ground", "block_B"]
k = "{K / 1000!r} kN/m"
free_length = "{L0 * 1000!r} mm"
preload = "{F0!r} N"

[dampers.d1]
between = "D A"
on = "ground crank"
c = "{C!r} N s/m"

[gas_springs.g1]
between = ["S2", "B"]
on = ["ground", "block_B"]
force = "{GAS_F!r} N"
gas_length = "{GAS_LG * 100!r} cm"
n = {GAS_N!r}

[torsion_springs.t1]
at = "A"
k = "{KT!r} N m/rad"
free_angle = "10 deg"

[rotary_dampers.r1]
at = "B"
c = "{CT * 1000!r} N mm s/rad"
"""


def _json(lk) -> str:
    """The same in JSON, SI numbers."""
    data = {"name": "every_element", "ground": "O S D S2", "driver": "crank", "gravity": 9.81,
            "points": {k: [z.real, z.imag] for k, z in lk.points.items()}, "links": {"crank": "O A", "rod": "A B"},
            "sliders": {"B": {"angle": 0.0}}, "mass": SM, "forces": {"B": {"force": [LOAD.real, LOAD.imag], "on": "block_B"}},
            "moments": {"rod": MOMENT},
            "springs": {"s1": {"between": ["S", "B"], "on": ["ground", "block_B"], "k": K, "free_length": L0, "preload": F0}},
            "dampers": {"d1": {"between": ["D", "A"], "on": ["ground", "crank"], "c": C}},
            "gas_springs": {"g1": {"between": ["S2", "B"], "on": ["ground", "block_B"], "force": GAS_F, "gas_length": GAS_LG, "n": GAS_N}},
            "torsion_springs": {"t1": {"at": "A", "k": KT, "free_angle": FREE_T}}, "rotary_dampers": {"r1": {"at": "B", "c": CT}}}
    return json.dumps(data)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_a_file_with_every_element_is_the_linkage_built_in_python(tmp_path, suffix):
    built = slider_crank(every=True)
    path = tmp_path / f"every_element{suffix}"
    path.write_text(_toml(built) if suffix == ".toml" else _json(built))
    read = jm.load_linkage(path)
    assert read.topology == built.topology
    assert list(read.params) == list(built.params)
    for k, v in built.params.items():
        assert read.params[k] == pytest.approx(v, rel=1e-15, abs=1e-15), k
    assert_same_dynamics(read, built, 1e-13)


FLAP = dict(points={"H": (0, 0), "P": (0.30, 0), "Q": (0.35, 0), "T": (1.20, 0), "C": (0.25, -0.30), "G": (0.05, -0.35)},
            links={"flap": "H P Q T"}, ground="H C G", driver="act", actuators={"act": ("C", "P")}, mass={"flap": 20.0},
            centre={"flap": (0.6, 0.0)}, inertia={"flap": 2.4}, gravity=9.81, moments={"flap": -40.0},
            gas_springs={"strut": {"between": ("G", "Q"), "force": 350.0, "gas_length": 0.25, "n": 1.0}},
            rotary_dampers={"hinge": {"at": "H", "c": 5.0}}, name="counterbalanced_flap")


def test_the_example_flap_is_the_flap_built_in_python_and_gives_the_pages_numbers():
    read, stroke = jm.linkage.read_linkage_file(ROOT / "examples" / "linkages" / "counterbalanced_flap.toml")
    built = jm.Linkage(**FLAP)
    assert read.topology == built.topology and read.params == built.params
    t = np.linspace(0.0, (stroke["to"] - stroke["from"]) / stroke["speed"], 60)
    drive = jm.ConstantSpeed(stroke["from"], stroke["speed"])
    strut = read.inverse_dynamics(drive, t)
    without = read.inverse_dynamics(drive, t, p={"F0_strut": 0.0})
    pw = read.power(drive, t)
    assert np.max(np.abs(np.asarray(pw.residual))) <= 1e-10 * np.max(np.abs(np.asarray(pw.input)))
    # the page's table: peak actuator force without and with the strut, the stroke's
    # efficiency (the energy delivered to the wind's moment over the energy put in)
    page = (ROOT / "docs" / "springs_and_dampers.md").read_text()
    found = re.search(r"peak actuator force: (\d+) N without the strut, (\d+) N with it; efficiency ([\d.]+) %", page)
    assert found, "the page states the peak forces and the efficiency"
    assert int(found.group(1)) == round(float(np.max(without.tau)))
    assert int(found.group(2)) == round(float(np.max(strut.tau)))
    assert float(found.group(3)) == round(100 * float(pw.efficiency), 1)


BAD = {
    "an end on two links": (dict(springs={"s": {"between": ["S", "B"], "k": 100.0}}), r"springs\['s'\]: point 'B' is on \['rod', 'block_B'\]; say which carries the end: on ="),
    "a misspelt key": (dict(springs={"s": {"between": ["S", "A"], "on": "ground crank", "kk": 1.0}}), r"springs\['s'\]: unknown key\(s\) \['kk'\].*did you mean 'k'\?"),
    "no stiffness": (dict(springs={"s": {"between": ["S", "A"], "on": "ground crank"}}), r"springs\['s'\] needs k \(in N/m\)"),
    "a negative stiffness": (dict(torsion_springs={"t": {"at": "A", "k": -1.0}}), r"torsion_springs\['t'\]\.k must not be negative"),
    "a unit that does not fit": (dict(springs={"s": {"between": ["S", "A"], "on": "ground crank", "k": "2 kN"}}),
                                 r"springs\['s'\]\.k: '2 kN' is not a number in N/m \(unit 'kN' does not fit"),
    "an unknown point": (dict(dampers={"d": {"between": ["S", "AA"], "c": 1.0}}), r"dampers\['d'\]\.between names two different points.*did you mean 'A'\?"),
    "a name twice": (dict(springs={"x": {"between": "S A", "on": "ground crank", "k": 1.0}}, dampers={"x": {"between": "D A", "on": "ground crank", "c": 1.0}}),
                     r"dampers\['x'\]: the name 'x' is taken by springs\['x'\]"),
    "a name that is not one": (dict(dampers={"my damper": {"between": "D A", "on": "ground crank", "c": 1.0}}), r"Python identifier"),
    "a pin of one body": (dict(torsion_springs={"t": {"at": "S", "k": 1.0}}), r"torsion_springs\['t'\]\.at: the point 'S' joins \['ground'\], not two bodies; give the two it acts between: links = \[a, b\]"),
    "at and links": (dict(rotary_dampers={"r": {"at": "A", "links": ["crank", "rod"], "c": 1.0}}), r"rotary_dampers\['r'\] needs at = a pin .* or links = \[a, b\] .* one of them"),
    "a misspelt link": (dict(torsion_springs={"t": {"links": ["ground", "crnk"], "k": 1.0}}), r"torsion_springs\['t'\]\.links: 'crnk' is not a link or 'ground'; did you mean 'crank'\?"),
    "an end on a body without it": (dict(springs={"s": {"between": "S B", "on": "ground crank", "k": 1.0}}), r"springs\['s'\]\.on: 'crank' does not carry point 'B'"),
    "n without a gas column": (dict(gas_springs={"g": {"between": "S2 A", "on": "ground crank", "force": 10.0, "n": 1.4}}), r"gas_springs\['g'\]: \['n'\] need gas_length"),
    "a gas column used up": (dict(gas_springs={"g": {"between": "S2 A", "on": "ground crank", "force": 10.0, "gas_length": 0.1, "length": 1.0}}),
                             r"gas_springs\['g'\]: the drawing compresses the gas spring past its gas_length"),
    "not a table": (dict(dampers={"d": 3.0}), r"dampers\['d'\]: give a table of keys \(between, on, c\)"),
}


@pytest.mark.parametrize("case", list(BAD), ids=list(BAD))
def test_bad_input_is_refused_naming_the_element_and_the_fix(case):
    kw, message = BAD[case]
    args = dict(NONE)
    args.update(kw)
    with pytest.raises(ValueError, match=message) as err:
        slider_crank(**args)
    assert str(err.value).startswith("linkage: ")


def test_a_misspelt_file_table_is_named(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('ground = "O"\ndriver = "crank"\n[points]\nO = [0, 0]\nA = [1, 0]\n[links]\ncrank = "O A"\n'
                    '[sprngs.s]\nbetween = "O A"\nk = 1.0\n')
    with pytest.raises(ValueError, match=r"bad.toml: unknown key\(s\) \['sprngs'\].*did you mean 'springs'\?"):
        jm.load_linkage(path)
