"""The house rules a reader can check mechanically: modules of one concept (about 500 lines
at most), no private name imported from another module of the package, no absolute path of
any machine in the repository."""

import ast
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "jaxmech"
MAX_LINES = 500


def _modules():
    return sorted(PACKAGE.rglob("*.py"))


def test_no_module_over_about_500_lines():
    long = {str(f.relative_to(ROOT)): n for f in _modules() if (n := len(f.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_no_private_name_crosses_a_module_boundary():
    """``from .x import _name`` and ``module._name`` of a package module are refused (a
    private name of the module itself, or a dunder, is fine)."""
    crossings = []
    for f in _modules():
        tree = ast.parse(f.read_text())
        modules = set()  # names bound to jaxmech modules by `from . import x` / `import jaxmech.x as y`
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("jaxmech")):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        crossings.append(f"{f.relative_to(ROOT)}:{node.lineno} imports {a.name}")
                    if node.module is None:
                        modules.add(a.asname or a.name)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                crossings.append(f"{f.relative_to(ROOT)}:{node.lineno} uses {node.value.id}.{node.attr}")
    assert not crossings, crossings


def test_no_absolute_machine_path_in_the_repository():
    try:
        files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    # home and work folders of Linux, macOS and Windows machines (written so that this line
    # does not match itself)
    roots = ["/" + "work/", "/" + "home/\\w", "/" + "root/", "/" + "Users/\\w", "[A-Z]:\\\\" + "Users\\\\"]
    pattern = re.compile(r"(?<![\w.])(" + "|".join(roots) + ")")
    found = []
    for name in files:
        path = ROOT / name
        if path.suffix in {".png", ".gif", ".parquet", ".npz"} or not path.is_file():
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        found += [f"{name}:{i}" for i, line in enumerate(text.splitlines(), 1) if pattern.search(line)]
    assert not found, found
