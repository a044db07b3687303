"""Scenes declare their outputs' units and column order (``scenes.Outputs``); one naming of
the columns serves every table.  Checked: every registered scene's declaration against what
its outputs function returns, the declaration read without tracing, a plain function of
``(values, unit)`` pairs giving the declared scene's table to the bit, mismatches named."""

import jax

jax.config.update("jax_enable_x64", True)

import dataclasses  # noqa: E402
from pathlib import Path  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech.scenes import Outputs, get_scene, run_scene, scene_names  # noqa: E402
from jaxmech.scenes.classic import FOURBAR  # noqa: E402
from jaxmech.scenes.columns import column_names  # noqa: E402
from jaxmech.scenes.evaluation import StrokePart, scene_stroke  # noqa: E402
from jaxmech.scenes.linkage_scene import scene_from_file  # noqa: E402
from jaxmech.scenes.outputs import abstract_motion, output_units  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _scenes():
    out = [get_scene(n) for n in scene_names()]
    return out + [scene_from_file(f) for f in sorted((ROOT / "examples" / "linkages").glob("*.toml"))]


def test_every_scene_declares_what_its_outputs_return():
    """The declaration is checked against the function itself, traced (shapes only) on one
    design's motion: every declared name returned, nothing undeclared, each a (N,) array."""
    for scene in _scenes():
        if scene.outputs is None:
            assert output_units(scene) == {}
            continue
        assert isinstance(scene.outputs, Outputs), scene.name
        p = {k: jax.ShapeDtypeStruct((), jnp.float64) for k in scene.defaults}
        out = jax.eval_shape(lambda p, mo, s=scene: {k: jnp.asarray(v) for k, (v, _) in s.outputs(p, mo).items()},
                             p, abstract_motion(scene, 7))
        assert sorted(out) == sorted(scene.outputs.units), scene.name  # (eval_shape sorts its keys)
        assert all(v.shape in ((7,), ()) for v in out.values()), (scene.name, out)


def _transmission_pairs(p, mo):
    mu = jnp.arccos(jnp.abs(jnp.cos(mo.q[:, 1] - mo.q[:, 0])))
    return {"transmission_angle": (mu, "rad")}


def _must_not_run(p, mo):
    raise AssertionError("the declaration is read without calling the outputs")


def test_declaration_is_read_without_tracing_and_names_the_columns():
    scene = dataclasses.replace(FOURBAR, outputs=Outputs(_must_not_run, {"mu": "rad", "k": "N/m"}))
    assert output_units(scene) == {"mu": "rad", "k": "N/m"}
    assert column_names(scene)[-2:] == ["mu[rad]", "k[N/m]"]


def test_plain_function_of_pairs_gives_the_declared_scenes_table_to_the_bit():
    """A user's scene written before declarations (outputs returning (values, unit)) runs as
    before: its units are found by tracing once, its table equals the declared scene's."""
    plain = dataclasses.replace(FOURBAR, outputs=_transmission_pairs)
    assert output_units(plain) == {"transmission_angle": "rad"}
    a, b = run_scene(FOURBAR, points=9).table(), run_scene(plain, points=9).table()
    assert list(a) == list(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])


def test_outputs_that_do_not_match_their_declaration_are_named():
    wrong = dataclasses.replace(FOURBAR, outputs=Outputs(lambda p, mo: {"mu": mo.t, "extra": mo.t}, {"mu": "rad", "k": "N"}))
    with pytest.raises(ValueError, match=r"declared but not returned \['k'\], returned but not declared \['extra'\]"):
        run_scene(wrong, points=5)
    with pytest.raises(ValueError, match="unit string"):
        Outputs(_transmission_pairs, {"mu": 1.0})


def test_scene_stroke_is_a_named_record():
    p = {k: jnp.full((2,), v) for k, v in FOURBAR.defaults.items()}
    part = scene_stroke(FOURBAR, 5, p)
    assert isinstance(part, StrokePart)
    assert part.solution.q.shape == (2, 5, 2) and part.dq_du.shape == (2, 5, 2, 1) and part.t.shape == (2, 5)
    np.testing.assert_allclose(part.t[:, -1], 2 * np.pi, rtol=1e-15)  # one crank turn at 1 rad/s


def test_the_old_output_units_warns_and_reads_the_declaration():
    from jaxmech.scenes.evaluation import output_units as old

    with pytest.warns(DeprecationWarning, match="scenes.outputs.output_units"):
        assert old(FOURBAR, 11, None, {}) == {"transmission_angle": "rad"}


def test_design_does_not_import_the_sweeps():
    """The evaluators design needs live with the scene evaluation (``scenes.columns``): no
    module of ``jaxmech/design`` imports ``jaxmech.sweep``."""
    import ast

    found = []
    for f in sorted((ROOT / "jaxmech" / "design").glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                mod = "." * node.level + (node.module or "")
                if mod.lstrip(".").split(".")[0] == "sweep" or mod.startswith("jaxmech.sweep"):
                    found.append(f"{f.name}:{node.lineno} {mod}")
            elif isinstance(node, ast.Import):
                found += [f"{f.name}:{node.lineno} {a.name}" for a in node.names if a.name.startswith("jaxmech.sweep")]
    assert not found, found
