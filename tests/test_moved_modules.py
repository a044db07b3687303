"""The module paths before the package's folders (``jaxmech.positions``, ``jaxmech.plot``, ...)
still import for one release: the module at its new path, with a DeprecationWarning naming
that path."""

import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from jaxmech._moved import MOVED


@pytest.mark.parametrize("old", ["jaxmech.positions", "jaxmech.stroke_repair"])
def test_an_old_module_path_imports_the_new_module_and_warns(old):
    new = MOVED[old]
    sys.modules.pop(old, None)  # imported once already by another test: the warning comes at the first import
    with pytest.warns(DeprecationWarning, match=f"{old} moved to {new}"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)


def test_a_name_from_an_old_path_is_the_object_at_the_new_one():
    """``from jaxmech.plot import plot_coordinates`` (as the notebooks wrote it) in a fresh process:
    the warning names the new path, the function is the one there."""
    code = ("import warnings\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            "    warnings.simplefilter('always')\n"
            "    from jaxmech.plot import plot_coordinates\n"
            "    from jaxmech.kinematics import motion\n"
            "from jaxmech.viz.plot import plot_coordinates as new\n"
            "print(plot_coordinates is new, [str(x.message) for x in w if x.category is DeprecationWarning])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.startswith("True ") and "jaxmech.plot moved to jaxmech.viz.plot" in out, out
    assert "kinematics" not in out  # a module that did not move: no warning


def test_every_old_path_names_a_module_that_is_there():
    package = Path(__file__).resolve().parents[1] / "jaxmech"
    for old, new in MOVED.items():
        assert importlib.util.find_spec(new) is not None, new
        rest = old.split(".")[1:]
        assert not package.joinpath(*rest).with_suffix(".py").exists(), old  # no file left behind at the old path


def test_the_moved_names_stay_out_of_the_public_face():
    import jaxmech

    assert not {old.split(".")[1] for old in MOVED} & set(dir(jaxmech))
    assert "_compile" not in dir(jaxmech)


def test_no_package_face_hides_a_module_of_its_package():
    """A face that hands on a name which is also one of its package's modules (a function
    ``stroke`` beside a module ``stroke.py``) makes ``from package import stroke`` and
    ``import package.stroke as m`` give the function: in the packages the old modules went
    into, every module stays reachable as itself."""
    import types

    package = Path(__file__).resolve().parents[1] / "jaxmech"
    for dotted in sorted({new.rsplit(".", 1)[0] for new in MOVED.values()}):
        folder = package.joinpath(*dotted.split(".")[1:])
        for f in sorted(folder.glob("*.py")):
            if f.stem not in ("__init__", "__main__"):  # a __main__ runs when imported
                importlib.import_module(f"{dotted}.{f.stem}")
                assert isinstance(getattr(importlib.import_module(dotted), f.stem), types.ModuleType), f"{dotted}.{f.stem}"


def test_python_m_jaxmech_cli_still_runs_the_command():
    """``python -m jaxmech.cli`` (the command line was a module before it became a package)
    still runs the ``jaxmech`` command: its usage line."""
    out = subprocess.run([sys.executable, "-m", "jaxmech.cli", "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("usage: jaxmech")
