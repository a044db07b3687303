"""Execute the notebooks in place, so that they are committed with their outputs (plots
included) and the documentation site renders them as they ran.

    python scripts/execute_notebooks.py [NAME ...]      # default: every notebook

Each code cell is stamped with the SHA-256 of its source (``metadata.jaxmech.source_sha256``);
``tests/test_docs.py`` checks the stamps (a cell edited since it ran fails, in milliseconds),
and ``tests/test_notebooks.py``, which executes every notebook anyway, checks that a fresh
run gives the same kinds of output (text, images, widgets) in every cell.  The kernel is
this interpreter, run from the repository root's ``notebooks/`` folder.
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 300  # s per cell


def source_sha256(source: str) -> str:
    return hashlib.sha256(source.encode("utf-8")).hexdigest()


def execute(path: Path) -> float:
    nb = nbformat.read(path, as_version=4)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    client = NotebookClient(nb, timeout=TIMEOUT, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
    start = time.perf_counter()
    client.execute(env=env)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.metadata.pop("execution", None)  # timestamps: noise in a diff
            cell.metadata["jaxmech"] = {"source_sha256": source_sha256(cell.source)}
    nbformat.write(nb, path)
    return time.perf_counter() - start


def main(argv=None) -> int:
    names = (argv if argv is not None else sys.argv[1:]) or [p.stem for p in sorted((ROOT / "notebooks").glob("*.ipynb"))]
    for name in names:
        path = ROOT / "notebooks" / f"{Path(name).stem}.ipynb"
        print(f"{path.name}: {execute(path):.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
