"""The house rules a reader can check mechanically: a top level of few modules, the rest in
folders that name the architecture; modules of one concept (about 500 lines at most),
functions of named stages (80 lines at most), a named record for more than three results,
no private name imported from another module of the package, no absolute path of any
machine in the repository."""

import ast
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "jaxmech"
MAX_LINES = 500
MAX_FUNCTION_LINES = 80  # a stage a reader takes in at once
MAX_RESULTS = 3  # more values than this come back as a named record


def _modules():
    return sorted(PACKAGE.rglob("*.py"))


FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef)


def long_functions(source: str, where: str = "") -> list:
    """Every function or method (nested ones too) longer than ``MAX_FUNCTION_LINES``, from its
    ``def`` line to its last line (decorators not counted)."""
    return [f"{where}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)"
            for node in ast.walk(ast.parse(source))
            if isinstance(node, FUNCTIONS) and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]


def _own_returns(fn):
    """The return statements of `fn` itself, not of the functions, lambdas or classes it defines."""
    stack = list(ast.iter_child_nodes(fn))
    while stack:
        node = stack.pop()
        if isinstance(node, (*FUNCTIONS, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(node, ast.Return):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def long_tuple_returns(source: str, where: str = "") -> list:
    """Every module-level function or method (of a module-level class) that returns a tuple
    literal of more than ``MAX_RESULTS`` values.  A tuple with a starred element is a
    sequence of varying length (``(a, b, *rest)``), not a fixed group of results, and is
    not counted; nor are the returns of nested functions (a jitted body's carry)."""
    tree = ast.parse(source)
    top = [n for n in tree.body if isinstance(n, FUNCTIONS)]
    top += [m for c in tree.body if isinstance(c, ast.ClassDef) for m in c.body if isinstance(m, FUNCTIONS)]
    return [f"{where}:{r.lineno} {fn.name} returns {len(r.value.elts)} values"
            for fn in top for r in _own_returns(fn)
            if isinstance(r.value, ast.Tuple) and len(r.value.elts) > MAX_RESULTS
            and not any(isinstance(e, ast.Starred) for e in r.value.elts)]


#: The package's top level: at most this many plain modules; the rest in folders that name
#: the architecture (mechanism/, solver/, continuation/, viz/, export/, cli/, _compile/, ...).
MAX_TOP_MODULES = 8


def test_the_top_level_holds_few_modules():
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(top) <= MAX_TOP_MODULES, top


def test_no_module_over_about_500_lines():
    long = {str(f.relative_to(ROOT)): n for f in _modules() if (n := len(f.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_no_function_over_80_lines():
    long = [x for f in _modules() for x in long_functions(f.read_text(), str(f.relative_to(ROOT)))]
    assert not long, long


def test_no_function_returns_more_than_three_values():
    found = [x for f in _modules() for x in long_tuple_returns(f.read_text(), str(f.relative_to(ROOT)))]
    assert not found, found


def test_the_function_rules_see_what_they_should():
    """The two checks above on code written to break them, and on code that does not."""
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES - 2))
    fits = f"def f():\n{body}\n    return x0\n"  # exactly MAX_FUNCTION_LINES lines
    assert long_functions(fits) == []
    assert long_functions(fits.replace("return x0", "x = 1\n    return x0")) == [":1 f (81 lines)"]
    assert long_functions(f"class A:\n    def g(self):\n        def h():\n{body.replace('    ', '            ')}\n"
                          "            return 1\n            return 2\n        return h\n") == [":2 g (83 lines)", ":3 h (81 lines)"]
    four = "def f(a):\n    return a, a, a, a\n"
    assert long_tuple_returns(four) == [":2 f returns 4 values"]
    assert long_tuple_returns("class A:\n    def m(self):\n        if self:\n            return 1, 2, 3, 4, 5\n        return 1\n") \
        == [":4 m returns 5 values"]
    assert long_tuple_returns("def f(a):\n    return a, a, a\n") == []
    assert long_tuple_returns("def f(a):\n    def g():\n        return a, a, a, a\n    return g\n") == []
    assert long_tuple_returns("def f(a):\n    return (a, a, a, *a)\n") == []


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _is_package_module(dotted: str) -> bool:
    """``jaxmech.a.b`` names a module or a package of this checkout (not a function or a class)."""
    path = ROOT.joinpath(*dotted.split("."))
    return dotted.split(".")[0] == "jaxmech" and (path.with_suffix(".py").is_file() or (path / "__init__.py").is_file())


def _imported_from(node: ast.ImportFrom, package: str | None) -> str | None:
    """The dotted jaxmech module a ``from ... import`` reads from (a relative import resolved
    against `package`, the importing module's package), or None for another library."""
    if node.level > 0:
        if package is None:
            return None
        base = package.split(".")[: len(package.split(".")) - node.level + 1]
        return ".".join(base + ([node.module] if node.module else []))
    return node.module if (node.module or "").split(".")[0] == "jaxmech" else None


def private_crossings(source: str, where: str = "", package: str | None = None) -> list:
    """Every use of a private jaxmech name from outside its module: ``from jaxmech.x import
    _name`` (or ``from . import _name`` inside the package, `package` being the importing
    module's), and ``module._name`` / ``module._name.attr`` of a name bound to a jaxmech
    module (``from jaxmech.design import synthesis as syn``, ``import jaxmech.x as y``,
    ``from . import x``).  A private name of the module itself, or a dunder, is fine."""
    tree = ast.parse(source)
    found, modules = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (base := _imported_from(node, package)) is not None:
            for a in node.names:
                if _private(a.name):
                    found.append(f"{where}:{node.lineno} imports {a.name}")
                elif _is_package_module(f"{base}.{a.name}"):
                    modules.add(a.asname or a.name)
        elif isinstance(node, ast.Import):
            modules.update(a.asname or "jaxmech" for a in node.names if a.name.split(".")[0] == "jaxmech")
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            root = node.value
            while isinstance(root, ast.Attribute):
                root = root.value
            if isinstance(root, ast.Name) and root.id in modules:
                found.append(f"{where}:{node.lineno} uses {ast.unparse(node)}")
    return found


def test_no_private_name_crosses_a_module_boundary():
    """Inside the package: ``from .x import _name`` and ``module._name`` of a package module
    are refused."""
    crossings = []
    for f in _modules():
        rel = f.relative_to(ROOT).with_suffix("")
        package = ".".join(rel.parts[:-1])  # a module's package; an __init__'s own
        crossings += private_crossings(f.read_text(), str(f.relative_to(ROOT)), package)
    assert not crossings, crossings


def test_benchmarks_and_examples_use_public_names_only():
    """What a user runs (``benchmarks/*.py``, ``examples/*.py``) reaches jaxmech through its
    public names: a private one can be renamed at any time (``benchmarks/design.py`` once
    called a renamed ``synthesis._evaluator`` and its literature rows stopped running)."""
    files = sorted((ROOT / "benchmarks").glob("*.py")) + sorted((ROOT / "examples").glob("*.py"))
    assert len(files) > 10
    crossings = [x for f in files for x in private_crossings(f.read_text(), str(f.relative_to(ROOT)))]
    assert not crossings, crossings


def test_the_private_name_rule_sees_what_it_should():
    """The check above on code written to break it, and on code that does not."""
    assert private_crossings("from jaxmech.design.synthesis import _denormalise as d\n") == [":1 imports _denormalise"]
    assert private_crossings("from jaxmech.design import synthesis as syn\nsyn._evaluator.cache_clear()\n") == \
        [":2 uses syn._evaluator"]
    assert private_crossings("import jaxmech.design.synthesis as s\ns._x\n") == [":2 uses s._x"]
    assert private_crossings("import jaxmech\njaxmech.design._hidden\n") == [":2 uses jaxmech.design._hidden"]
    assert private_crossings("from ..solver import xla\nxla._cache\n", package="jaxmech.design") == [":2 uses xla._cache"]
    assert private_crossings("from .synthesis_lsq import _x\n", package="jaxmech.design") == [":1 imports _x"]
    # public names, dunders, another library's private names, a function (not a module) of jaxmech
    assert private_crossings("from jaxmech.design import synthesis as syn\nsyn.PARAMS, syn.__name__\n") == []
    assert private_crossings("import numpy as np\nnp._NoValue\nfrom numpy import _globals\n") == []
    assert private_crossings("from jaxmech.design.synthesis_lsq import evaluator\nevaluator.cache_clear()\n") == []
    assert private_crossings("from jaxmech.design import path_error as pe\npe._x\n") == []
    assert private_crossings("from ._x import y\n") == []  # a relative import outside the package: not jaxmech's


#: The numerical layers: they compute, and never name how their programs are compiled or kept
#: (the executable store, ``jaxmech._compile``, serves their top-level calls from the edge).
NUMERICAL = ("solver", "mechanism", "continuation", "dynamics", "linkage", "design", "actuators",
             "kinematics.py", "constrained.py", "tolerance.py", "units.py", "names.py")


def _jit_call(call: ast.Call) -> bool:
    """``jit(...)``, ``x.jit(...)`` or ``functools.partial(jit, ...)``."""
    name = lambda n: getattr(n, "id", getattr(n, "attr", ""))  # noqa: E731
    return name(call.func) == "jit" or (name(call.func) == "partial" and bool(call.args) and name(call.args[0]) == "jit")


def compile_at_the_core(source: str, where: str = "", package: str = "jaxmech") -> list:
    """Every import of ``jaxmech._compile`` (absolute or relative to `package`, the module's
    package) and every call passing ``stored=``: compile machinery inside a numerical module."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            base = _imported_from(node, package) or ""
            names = [f"{base}.{a.name}" for a in node.names]
            if any(n.split(".")[:2] == ["jaxmech", "_compile"] for n in [base] + names):
                found.append(f"{where}:{node.lineno} imports {base or node.module}")
        elif isinstance(node, ast.Import):
            found += [f"{where}:{node.lineno} imports {a.name}" for a in node.names if a.name.startswith("jaxmech._compile")]
        elif isinstance(node, ast.Call) and any(k.arg == "stored" for k in node.keywords) and _jit_call(node):
            found.append(f"{where}:{node.lineno} passes stored=")
    return found


def test_no_numerical_module_imports_the_compile_package():
    files = [f for name in NUMERICAL for f in ([PACKAGE / name] if name.endswith(".py") else sorted((PACKAGE / name).rglob("*.py")))]
    assert len(files) > 60
    found = []
    for f in files:
        rel = f.relative_to(ROOT).with_suffix("")
        found += compile_at_the_core(f.read_text(), str(f.relative_to(ROOT)), ".".join(rel.parts[:-1]))
    assert not found, found


def test_the_compile_rule_sees_what_it_should():
    assert compile_at_the_core("from .._compile.stored import cached_call\n", package="jaxmech.design") == [":1 imports jaxmech._compile.stored"]
    assert compile_at_the_core("from .. import _compile\n", package="jaxmech.design") == [":1 imports jaxmech"]
    assert compile_at_the_core("import jaxmech._compile.cache\n") == [":1 imports jaxmech._compile.cache"]
    assert compile_at_the_core("@functools.partial(jit, stored=True)\ndef f(x): ...\n") == [":1 passes stored="]
    assert compile_at_the_core("f = jit(g, stored=True)\n") == [":1 passes stored="]
    # the backend's jit; a package of another library; a physical keyword of the same name
    assert compile_at_the_core("from ..solver.xla import jit\nfrom ._compile import x\n", package="jaxmech.design") == []
    assert compile_at_the_core("power_balance(m, r, p, stored=names)\n") == []


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


CLOCKS = {"perf_counter", "time", "monotonic", "perf_counter_ns", "monotonic_ns"}
CLOCK_WORDS = ("elapsed", "seconds", "wall")


def _reads_a_clock(node) -> bool:
    return any(isinstance(n, ast.Call) and isinstance(n.func, (ast.Attribute, ast.Name))
               and (n.func.attr if isinstance(n.func, ast.Attribute) else n.func.id) in CLOCKS for n in ast.walk(node))


def wall_clock_asserts(source: str, where: str = "") -> list:
    """Every ``assert`` that reads a clock, a name assigned from one, or a name that says it
    holds a duration (``elapsed``, ``seconds``, ``wall``): timings belong in benchmarks (a
    loaded machine fails a wall-clock test)."""
    tree = ast.parse(source)
    timed = {t.id for n in ast.walk(tree) if isinstance(n, ast.Assign) and _reads_a_clock(n.value)
             for t in n.targets if isinstance(t, ast.Name)}
    found = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Assert):
            called = {id(x.func) for x in ast.walk(n.test) if isinstance(x, ast.Call)}
            names = {x.id for x in ast.walk(n.test) if isinstance(x, ast.Name) and id(x) not in called}
            if _reads_a_clock(n.test) or names & timed or any(w in x for x in names for w in CLOCK_WORDS):
                found.append(f"{where}:{n.lineno}")
    return found


def test_no_test_asserts_a_wall_clock_time():
    found = [f for path in sorted((ROOT / "tests").rglob("*.py")) for f in wall_clock_asserts(path.read_text(), path.name)]
    assert not found, found


def test_the_wall_clock_rule_sees_what_it_should():
    assert wall_clock_asserts("import time\nt0 = time.perf_counter()\nf()\nassert time.perf_counter() - t0 < 3\n")
    assert wall_clock_asserts("t = time.time()\nassert t < 5\n")
    assert wall_clock_asserts("elapsed = run()\nassert elapsed < 120\n")
    assert not wall_clock_asserts("x = f()\nassert x < 3\n")


def test_the_public_face_is_small_and_shows_no_internal_module():
    """``jaxmech.__all__``: at most 60 names, each there; ``dir(jaxmech)``: those, the
    documented packages and ``__version__``, no internal module and no stray import."""
    import types

    import jaxmech

    assert len(jaxmech.__all__) <= 60 and len(set(jaxmech.__all__)) == len(jaxmech.__all__)
    assert all(hasattr(jaxmech, n) for n in jaxmech.__all__)
    shown = [n for n in dir(jaxmech) if not n.startswith("__")]
    modules = {n for n in shown if isinstance(getattr(jaxmech, n), types.ModuleType)}
    assert modules == {"actuators", "design", "dynamics", "linkage", "scenes", "sweep"}, modules
    assert set(shown) - modules == set(jaxmech.__all__)


#: A loop's state position in ``jax.lax``'s loops: ``while_loop(cond, body, init)``,
#: ``fori_loop(lo, hi, body, init)``, ``scan(f, init, xs)``.
LOOP_INIT = {"while_loop": 2, "fori_loop": 3, "scan": 1}


def _tuple_size(node, bound: dict, depth: int = 0):
    """How many values the loop state `node` packs positionally: a tuple literal, a name
    bound to one in the same function, or either wrapped by ``per_lane(init, ...)``."""
    if depth > 5 or node is None:
        return None
    if isinstance(node, ast.Tuple):
        return len(node.elts)
    if isinstance(node, ast.Name) and node.id in bound:
        return _tuple_size(bound[node.id], bound, depth + 1)
    if isinstance(node, ast.Call) and node.args and getattr(node.func, "id", getattr(node.func, "attr", "")) == "per_lane":
        return _tuple_size(node.args[0], bound, depth + 1)
    return None


def tuple_carries(source: str, where: str = "") -> list:
    """Every ``while_loop``, ``fori_loop`` or ``scan`` whose state is a tuple of more than
    ``MAX_RESULTS`` values (a named record says what each field is, and a reordering
    cannot silently swap two of them)."""
    tree = ast.parse(source)
    found = set()
    for scope in ast.walk(tree):
        if not isinstance(scope, (*FUNCTIONS, ast.Module)):
            continue
        bound = {n.targets[0].id: n.value for n in ast.walk(scope)
                 if isinstance(n, ast.Assign) and len(n.targets) == 1 and isinstance(n.targets[0], ast.Name)}
        for call in ast.walk(scope):
            name = getattr(getattr(call, "func", None), "attr", getattr(getattr(call, "func", None), "id", ""))
            if not isinstance(call, ast.Call) or name not in LOOP_INIT:
                continue
            i = LOOP_INIT[name]
            init = call.args[i] if len(call.args) > i else next((k.value for k in call.keywords if k.arg in ("init", "init_val")), None)
            size = _tuple_size(init, bound)
            if size is not None and size > MAX_RESULTS:
                found.add(f"{where}:{call.lineno} {name} carries a tuple of {size}")
    return sorted(found)


def test_loop_carries_are_named():
    found = [f for path in _modules() for f in tuple_carries(path.read_text(), str(path.relative_to(ROOT)))]
    assert not found, found


def test_the_loop_carry_rule_sees_what_it_should():
    assert tuple_carries("def f():\n    return jax.lax.while_loop(c, b, (0, x, y, z))\n")
    assert tuple_carries("def f():\n    init = (0, x, y, z, w)\n    return lax.fori_loop(0, 3, b, per_lane(init, ok))\n")
    assert tuple_carries("def f():\n    return jax.lax.scan(g, (a, b, c, d), xs)\n")
    assert not tuple_carries("def f():\n    return jax.lax.while_loop(c, b, (0, x, y))\n")
    assert not tuple_carries("def f():\n    return jax.lax.while_loop(c, b, Carry(0, x, y, z))\n")


def _exported(source: str) -> list:
    """The names of a module's literal ``__all__`` (none without one)."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in node.targets):
            try:
                return list(ast.literal_eval(node.value))
            except ValueError:
                return []
    return []


def unused_exports(modules: dict, readers: list) -> list:
    """Every name in a module's ``__all__`` (`modules`: ``{where: source}``) that no other
    module and no reader (tests, benchmarks, examples, docs, notebooks, README) mentions: a
    name published for no one."""
    found = []
    for where, source in modules.items():
        for name in _exported(source):
            word = re.compile(rf"\b{re.escape(name)}\b")
            if not any(word.search(t) for w, t in modules.items() if w != where) and not any(word.search(t) for t in readers):
                found.append(f"{where}: {name}")
    return found


def test_every_exported_name_is_used_or_documented_outside_its_module():
    modules = {str(p.relative_to(ROOT)): p.read_text() for p in _modules()}
    readers = [p.read_text() for d in ("tests", "benchmarks", "examples", "docs", "notebooks") for p in sorted((ROOT / d).rglob("*"))
               if p.is_file() and p.suffix in (".py", ".md", ".ipynb")]
    readers += [(ROOT / f).read_text() for f in ("README.md", "ARCHITECTURE.md")]
    found = unused_exports(modules, readers)
    assert not found, found


def test_the_export_rule_sees_what_it_should():
    mods = {"a.py": '__all__ = ["used", "lonely"]\ndef used(): ...\ndef lonely(): ...\n', "b.py": "from a import used\n"}
    assert unused_exports(mods, []) == ["a.py: lonely"]
    assert unused_exports(mods, ["see `lonely` in the docs"]) == []
