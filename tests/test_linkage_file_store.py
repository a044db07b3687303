"""``jaxmech run FILE.toml`` stores a linkage file's programs, keyed by the file's content,
and a second process loads them instead of compiling (issue 35, item 1)."""

import json
import os
import subprocess
import sys
from pathlib import Path

from jaxmech.scenes.linkage_scene import scene_from_file

ROOT = Path(__file__).resolve().parents[1]
FOURBAR = ROOT / "examples" / "linkages" / "fourbar.toml"

# The command line's own entry point, then what the store did in this process.
_RUN = """
import json, sys
from jaxmech.cli.commands import main
rc = main(sys.argv[1:])
from jaxmech._compile.stored import store_stats, wait_for_stores
wait_for_stores()
print(json.dumps({**store_stats(), "rc": rc}))
"""


def _run(store: Path, out: Path) -> dict:
    env = {**os.environ, "JAXMECH_COMPILE_CACHE": str(store), "PYTHONPATH": str(ROOT)}
    env.pop("JAXMECH_EXPORT_CACHE", None)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    args = ["run", str(FOURBAR), "--plots", "none", "--out", str(out)]
    proc = subprocess.run([sys.executable, "-c", _RUN, *args], env=env, capture_output=True, text=True, timeout=180, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _stored(store: Path) -> set:
    return {f.name for f in (store / "executables").glob("*.jaxexec")}


def test_a_second_run_of_a_linkage_file_loads_its_stored_programs(tmp_path):
    store = tmp_path / "store"
    first = _run(store, tmp_path / "a")
    after_first = _stored(store)
    second = _run(store, tmp_path / "b")
    assert first["rc"] == 0 and first["stored"] >= 2 and first["loaded"] == 0, first
    assert len(after_first) >= 2
    # the warm run compiles none of the scene's programs: it loads them and stores nothing
    assert second["loaded"] >= 2 and second["stored"] == 0 and second["fallback"] == 0, second
    assert _stored(store) == after_first
    csv = "fourbar.csv"
    assert (tmp_path / "b" / csv).read_text() == (tmp_path / "a" / csv).read_text()


def test_a_file_scene_is_keyed_by_its_content(tmp_path):
    same = tmp_path / "same.toml"
    same.write_text(FOURBAR.read_text())
    moved = tmp_path / "moved.toml"
    moved.write_text(FOURBAR.read_text().replace("P = [1.9, 1.2]", "P = [1.9, 1.3]"))
    key = scene_from_file(FOURBAR).program_key
    assert key is not None and key == scene_from_file(FOURBAR).program_key
    assert scene_from_file(same).program_key == key  # another path, the same bytes and name
    assert scene_from_file(moved).program_key != key  # another coupler point: another program
