"""The command line's values: ``--set``, ``--grid``, ``--range``, ``--figure`` and counts
parsed and checked, and destinations checked before anything is computed.

Every mistake raises ``UsageError``, which ``jaxmech.cli`` prints as one line on stderr
with exit status 2 (no traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["UsageError", "parse_set", "overrides", "parse_grid", "positive", "points", "check_writable_dir",
           "check_writable_file", "parse_ranges", "figure_functions"]


class UsageError(Exception):
    """A user's mistake: reported as one line on stderr, exit status 2."""


def parse_set(items) -> dict[str, str]:
    """``["a=1.5", "b=20deg"]`` -> ``{"a": "1.5", "b": "20deg"}``, the syntax checked (a
    number first, finite; each name once); ``UsageError`` for a bad item.  Names and
    units are checked against the scene by ``overrides``."""
    from ..units import split_quantity

    out: dict[str, str] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise UsageError(f"--set expects NAME=VALUE, got {item!r}")
        try:
            v, _ = split_quantity(value)
        except ValueError:
            raise UsageError(f"--set {name}: {value!r} is not a number (SI units: m, rad, s, kg, N; or a number with its unit, e.g. 65deg)") from None
        if not np.isfinite(v):
            raise UsageError(f"--set {name}: value must be finite, got {value!r}")
        if name in out:
            raise UsageError(f"--set {name} is given twice")
        out[name] = value
    return out


def overrides(scene, raw: dict[str, str]) -> dict[str, float]:
    """``--set`` values in SI for ``scene``: every name a parameter of it (else the closest
    valid name), every unit one that fits the parameter's."""
    from ..units import to_si

    out = {}
    for name, text in raw.items():
        try:
            out[name] = to_si(text, scene.unit(name))
        except ValueError as e:
            raise UsageError(f"--set {name}: {e}" if name in scene.defaults else str(e)) from None
    return out


def parse_grid(items) -> dict[str, np.ndarray]:
    """``["a=0.5:1.5:11"]`` -> ``{"a": linspace(0.5, 1.5, 11)}``; ``UsageError`` if malformed."""
    grid: dict[str, np.ndarray] = {}
    for item in items or ():
        name, sep, rng = item.partition("=")
        name = name.strip()
        parts = rng.split(":")
        if not sep or not name or len(parts) != 3:
            raise UsageError(f"--grid expects NAME=START:STOP:N, got {item!r}")
        try:
            start, stop = float(parts[0]), float(parts[1])
        except ValueError:
            raise UsageError(f"--grid {name}: START and STOP must be numbers, got {rng!r}") from None
        try:
            n = int(parts[2])
        except ValueError:
            raise UsageError(f"--grid {name}: N must be a whole number of values, got {parts[2]!r}") from None
        if n < 1:
            raise UsageError(f"--grid {name}: N must be at least 1, got {n}")
        if not (np.isfinite(start) and np.isfinite(stop)):
            raise UsageError(f"--grid {name}: START and STOP must be finite, got {rng!r}")
        if name in grid:
            raise UsageError(f"--grid {name} is given twice")
        grid[name] = np.linspace(start, stop, n)
    return grid


def positive(what):
    def conv(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what} must be a whole number, got {text!r}") from None
        if v < 1:
            raise argparse.ArgumentTypeError(f"{what} must be at least 1, got {v}")
        return v

    return conv


def points(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--points must be a whole number, got {text!r}") from None
    if v < 2:  # a stroke has two ends
        raise argparse.ArgumentTypeError(f"--points must be at least 2, got {v}")
    return v


def check_writable_dir(path: Path, what: str) -> None:
    """``UsageError`` (one line) unless ``path`` is a folder that can be written, or one that
    can be made in a folder that exists: checked by writing (and removing) a file there before
    anything is computed.  The rule: the command makes the folder named, never the folders
    above it (a missing one is more often a typo than a wish)."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a file, not a folder; give a folder name")
    _in_a_folder(path, path.parent, what)
    _writable(path, path, what)


def check_writable_file(path: Path, what: str) -> None:
    """``UsageError`` (one line) unless a file can be written at ``path``: not a folder, in a
    folder that exists (none is made for a file) and can be written; checked before computing."""
    if path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a folder; give a file name")
    folder = path.parent if str(path.parent) else Path(".")
    _in_a_folder(path, folder, what)
    _writable(path, folder, what)


def _in_a_folder(path: Path, folder: Path, what: str) -> None:
    """``UsageError`` unless `folder`, where `path` goes, is a folder that exists."""
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{what} {str(path)!r} cannot be written: {str(folder)!r} is a file, not a folder")
    if not folder.is_dir():
        raise UsageError(f"{what} {str(path)!r}: the folder {str(folder)!r} does not exist; create it first")


def _writable(path: Path, folder: Path, what: str) -> None:
    """``UsageError`` unless a file can be made in `folder` (made, and removed, when missing)
    and `path`, if it is a file already, may be written: the file system is asked, since a
    permission bit does not tell (root passes ``os.access`` in ``/proc``, ``/sys`` and on a
    read-only disk's folders)."""
    made = not folder.exists()
    try:
        if path.is_file() and not os.access(path, os.W_OK):
            raise PermissionError(13, "no write permission")
        if made:
            folder.mkdir()
        with tempfile.TemporaryFile(dir=folder, prefix=".jaxmech-probe-"):
            pass
    except OSError as e:
        raise UsageError(f"{what} {str(path)!r} cannot be written: {e.strerror or e}") from None
    finally:
        if made and folder.exists():
            folder.rmdir()


def parse_ranges(items) -> dict[str, tuple[float, float]]:
    """``["a=0.9:1.1"]`` -> ``{"a": (0.9, 1.1)}``; ``UsageError`` if malformed."""
    out: dict[str, tuple[float, float]] = {}
    for item in items or ():
        name, sep, rng = item.partition("=")
        name, parts = name.strip(), rng.split(":")
        if not sep or not name or len(parts) != 2:
            raise UsageError(f"--range expects NAME=LOW:HIGH, got {item!r}")
        try:
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise UsageError(f"--range {name}: LOW and HIGH must be numbers, got {rng!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and hi >= lo):
            raise UsageError(f"--range {name}: need finite LOW <= HIGH, got {rng!r}")
        if name in out:
            raise UsageError(f"--range {name} is given twice")
        out[name] = (lo, hi)
    return out


def figure_functions(items) -> dict:
    """``["peak[N m]=mymod:peak"]`` -> ``{"peak[N m]": mymod.peak}``, the module imported from
    the current folder too (as ``python`` would; the installed command's own path does not
    hold it); ``UsageError`` if it cannot be imported."""
    out = {}
    for item in items or ():
        name, sep, ref = item.partition("=")
        mod, colon, fn = ref.partition(":")
        if not sep or not name.strip() or not colon or not mod or not fn:
            raise UsageError(f"--figure expects NAME=MODULE:FUNCTION, got {item!r}")
        try:
            obj = getattr(_import_here(mod), fn)
        except Exception as e:  # noqa: BLE001 - the user's module: any failure is one line
            raise UsageError(f"--figure {name}: cannot import {ref!r} ({type(e).__name__}: {' '.join(str(e).split())})") from None
        if not callable(obj):
            raise UsageError(f"--figure {name}: {ref!r} is not a function")
        out[name.strip()] = obj
    return out


def _import_here(module: str):
    """``importlib.import_module(module)`` with the current folder on the import path for
    the import (and only for it)."""
    import importlib

    here = os.getcwd()
    added = here not in sys.path and "" not in sys.path
    if added:
        sys.path.insert(0, here)
    try:
        return importlib.import_module(module)
    finally:
        if added:
            sys.path.remove(here)
