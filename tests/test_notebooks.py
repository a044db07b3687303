"""Every notebook in ``notebooks/`` runs from top to bottom without an error.

Each notebook is executed by ``nbclient`` in a kernel of *this* interpreter (the native
``python3`` kernel, which jupyter_client starts with ``sys.executable``; checked below),
in a temporary working directory, on an in-memory copy: nothing is written into the
repository.  The kernel inherits the environment (``XLA_FLAGS`` from ``conftest.py``) and
shares the CLI tests' persistent XLA cache.  Timings are printed (``pytest -s``), never
asserted (a loaded machine would fail them: a wall-clock limit is a benchmark's, not a
test's); the per-cell timeout only catches a hang.
"""

import os
import sys
import time
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
TIMEOUT = 900  # s per cell: catches a hang, never a slow machine (the notebooks take seconds to a minute)
KERNEL = "python3"


def _execute(nb, cwd):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    client = NotebookClient(nb, timeout=TIMEOUT, kernel_name=KERNEL, resources={"metadata": {"path": str(cwd)}})
    start = time.perf_counter()
    client.execute(env=env)  # raises CellExecutionError (with the traceback) on any error
    return time.perf_counter() - start


def _stderr(nb) -> list[str]:
    return [o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
            if o.get("output_type") == "stream" and o.get("name") == "stderr"]


def test_there_are_notebooks():
    names = {p.stem for p in NOTEBOOKS}
    assert {"define_your_own_mechanism", "when_things_go_wrong", "sensitivities_and_fitting"} <= names


def test_kernel_is_this_interpreter(tmp_path):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("import sys; print(sys.executable)")])
    _execute(nb, tmp_path)
    printed = nb.cells[0].outputs[0]["text"].strip()
    assert Path(printed).resolve() == Path(sys.executable).resolve()


def _kinds(nb) -> list[list[str]]:
    """Per code cell, the kinds of its outputs: a stream's name, a result's mime types.
    Consecutive pieces of one stream count once (the kernel splits a stream by timing)."""
    out = []
    for c in nb.cells:
        if c.cell_type == "code":
            kinds = [o.get("name") or "+".join(sorted(o.get("data", {}))) or o["output_type"] for o in c.outputs]
            out.append([k for i, k in enumerate(kinds) if i == 0 or k != kinds[i - 1] or k not in ("stdout", "stderr")])
    return out


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, tmp_path):
    nb = nbformat.read(path, as_version=4)
    committed = _kinds(nb)  # the notebooks are committed executed, for the documentation site
    first = next(c for c in nb.cells if c.cell_type == "code")
    assert 'jax.config.update("jax_enable_x64", True)' in first.source, "x64 is switched on in the first code cell"
    elapsed = _execute(nb, tmp_path)
    print(f"\n{path.name}: {elapsed:.1f} s")
    assert _stderr(nb) == [], f"{path.name} wrote to stderr (a warning?): {_stderr(nb)}"
    assert list(tmp_path.iterdir()) == [], f"{path.name} wrote files: {list(tmp_path.iterdir())}"
    assert _kinds(nb) == committed, (
        f"{path.name}: the committed outputs are not what the notebook gives now (a plot or a print added or "
        f"lost); run 'python scripts/execute_notebooks.py {path.stem}'"
    )
