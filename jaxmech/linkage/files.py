"""A linkage in a plain file (TOML or JSON), the format documented in ``docs/linkage_files.md``.

The keys are ``Linkage``'s arguments (``points``, ``links``, ``ground``, ``driver``,
``sliders``, ``slots``, ``actuators``, ``mass``, ``inertia``, ``centre``, ``gravity``,
``forces``, ``moments``, the springs and dampers ``springs``, ``torsion_springs``,
``gas_springs``, ``dampers``, ``rotary_dampers``, the joints' ``friction``, ``name``) plus an optional ``[stroke]``
table for the command line: ``from``, ``to`` (the driven input's range, SI or with a unit:
``"0deg"``), ``speed`` (rad/s or m/s), ``summary``, and for a reversing or given drive
``law = "rock"`` with ``cycles`` and ``period``, or ``samples`` (``linkage.stroke_file``), and an optional
``[simulate]`` table for ``jaxmech simulate`` (forward dynamics: ``linkage.simulate_file``).  Numbers are SI; a string may carry a unit (``"280mm"``, ``"30deg"``).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from ..names import near_hint
from .elements import ARGUMENTS
from .spec import Linkage
from .stroke_file import STROKE_KEYS

__all__ = ["read_linkage_file", "read_linkage_tables", "load_linkage", "TABLES"]

LINKAGE_KEYS = ("name", "points", "links", "ground", "driver", "sliders", "slots", "actuators", "mass", "inertia",
                "centre", "gravity", "forces", "moments", *ARGUMENTS, "friction")
#: The command line's tables beside the linkage's keys: ``[stroke]`` and ``[simulate]``.
TABLES = ("stroke", "simulate")


def _toml(text: str) -> dict:
    """The TOML table of `text`; ``ValueError`` naming the key or table given twice."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ValueError(_toml_twice(str(err), text) or f"not valid TOML: {err}") from None


def _toml_twice(message: str, text: str) -> str | None:
    """What a TOML parser's "Cannot overwrite a value" / "Cannot declare ... twice" means,
    naming the key given twice (tomllib says only where); None for any other error."""
    at = re.search(r"\(at line (\d+), column \d+\)$", message)
    if at is None:
        return None
    n = int(at.group(1))
    table = re.match(r"Cannot declare \((.*?),?\) twice", message)
    if table:
        return f"table [{'.'.join(x.strip().strip(chr(39)) for x in table.group(1).split(','))}] is given twice (line {n}); give it once"
    if not message.startswith("Cannot overwrite a value"):
        return None
    lines = text.splitlines()[:n]
    key_line = next((ln for ln in reversed(lines) if "=" in ln), "")
    key = key_line.partition("=")[0].strip().strip("\"'")
    header = next((m.group(1) for ln in reversed(lines) if (m := re.match(r"\s*\[+\s*([^\]]+?)\s*\]", ln))), None)
    return f"{key!r} is given twice{f' in [{header}]' if header else ''} (line {n}); give each name once"


def _json(text: str) -> dict:
    """The JSON object of `text`; ``ValueError`` naming a key given twice in one object
    and the object (Python's json would keep the last one silently)."""
    try:
        data = json.loads(text, object_pairs_hook=_Object)
    except ValueError as err:  # json.JSONDecodeError
        raise ValueError(f"not valid JSON: {err}") from None
    twice = _given_twice(data, ())
    if twice is not None:
        where, key = twice
        raise ValueError(f"{key!r} is given twice{' in ' + '.'.join(map(str, where)) if where else ''}; give each name once")
    return data


class _Object(dict):
    """A JSON object read by ``_json``, with the first key it gives twice (`twice`, or None)."""

    def __init__(self, pairs):
        super().__init__(pairs)
        keys = [k for k, _ in pairs]
        self.twice = next((k for i, k in enumerate(keys) if k in keys[:i]), None)


def _given_twice(obj, where: tuple):
    """``(path, key)`` of the outermost key given twice in a JSON value read by ``_json``, or None."""
    if getattr(obj, "twice", None) is not None:
        return where, obj.twice
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    for k, v in items:
        if (found := _given_twice(v, (*where, k))) is not None:
            return found
    return None


def read_linkage_file(path) -> tuple[Linkage, dict]:
    """``(linkage, stroke)`` from a TOML (``.toml``) or JSON (``.json``) file; `stroke` is its
    ``[stroke]`` table (empty when it has none).

    **Raises** ``ValueError`` naming the file and what is wrong (an unknown key, a bad value,
    a linkage that does not close); ``OSError`` when it cannot be read."""
    linkage, stroke, _ = read_linkage_tables(path)
    return linkage, stroke


def read_linkage_tables(path) -> tuple[Linkage, dict, dict | None]:
    """``(linkage, stroke, simulate)`` from a linkage file: ``read_linkage_file``'s pair and
    its ``[simulate]`` table as written (None when it has none; ``linkage.simulate_file``
    reads it)."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    try:
        data = _json(text) if path.suffix.lower() == ".json" else _toml(text)
        linkage, stroke = _linkage(data, path.stem)
    except ValueError as err:
        raise ValueError(f"{path.name}: {err}") from None
    simulate = data.get("simulate")
    if simulate is not None and not isinstance(simulate, dict):
        raise ValueError(f"{path.name}: simulate must be a table ([simulate] with duration, step, ...), got {simulate!r}")
    return linkage, stroke, simulate


def _linkage(data, stem: str) -> tuple[Linkage, dict]:
    """``(linkage, stroke)`` from a file's table; ``ValueError`` saying what is wrong."""
    if not isinstance(data, dict):
        raise ValueError("the file must hold a table of keys")
    unknown = [k for k in data if k not in LINKAGE_KEYS + TABLES]
    if unknown:
        raise ValueError(f"unknown key(s) {unknown}; a linkage file has {list(LINKAGE_KEYS)} and [stroke], [simulate]"
                         f"{near_hint(unknown, LINKAGE_KEYS + TABLES)}")
    for k in ("points", "links"):
        if k not in data:
            raise ValueError(f"a linkage file needs [{k}]")
    stroke = dict(data.get("stroke", {}))
    bad = [k for k in stroke if k not in STROKE_KEYS]
    if bad:
        raise ValueError(f"unknown [stroke] key(s) {bad}; it takes {', '.join(STROKE_KEYS)}{near_hint(bad, STROKE_KEYS)}")
    args = {k: v for k, v in data.items() if k in LINKAGE_KEYS}
    args.setdefault("name", stem)
    linkage = Linkage(**args)
    _check_lengths(linkage)
    return linkage, stroke


def _check_lengths(linkage: Linkage) -> None:
    """``ValueError`` naming the two points of a link that the drawing puts at one place (a
    zero length, which no mechanism can run with)."""
    values = linkage.params
    for name, recipe in linkage.built.recipes.items():
        if recipe[0] == "len" and not values[name] > 0.0:
            a, b = recipe[1:3]
            raise ValueError(f"points {a!r} and {b!r} of one link are both at {_xy(linkage.points[a])} "
                             f"(length {name} = 0); draw them apart")


def _xy(z: complex) -> str:
    return f"({z.real:.6g}, {z.imag:.6g})"


def load_linkage(path) -> Linkage:
    """The ``Linkage`` a TOML or JSON file describes (``read_linkage_file`` without its stroke)."""
    return read_linkage_file(path)[0]
