"""A linkage in a plain file (TOML or JSON), the format documented in ``docs/linkage_files.md``.

The keys are ``Linkage``'s arguments (``points``, ``links``, ``ground``, ``driver``,
``sliders``, ``slots``, ``actuators``, ``mass``, ``inertia``, ``centre``, ``gravity``,
``forces``, ``moments``, ``name``) plus an optional ``[stroke]`` table for the command line:
``from``, ``to`` (the driven input's range, SI or with a unit: ``"0deg"``), ``speed`` (rad/s or
m/s) and ``summary``.  Numbers are SI; a string may carry a unit (``"280mm"``, ``"30deg"``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .spec import Linkage

__all__ = ["read_linkage_file", "load_linkage", "LINKAGE_KEYS"]

LINKAGE_KEYS = ("name", "points", "links", "ground", "driver", "sliders", "slots", "actuators", "mass", "inertia",
                "centre", "gravity", "forces", "moments")


def _toml(text: str) -> dict:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    return tomllib.loads(text)


def read_linkage_file(path) -> tuple[Linkage, dict]:
    """``(linkage, stroke)`` from a TOML (``.toml``) or JSON (``.json``) file; `stroke` is its
    ``[stroke]`` table (empty when it has none).

    **Raises** ``ValueError`` naming the file and what is wrong (an unknown key, a bad value,
    a linkage that does not close); ``OSError`` when it cannot be read."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else _toml(text)
    except ValueError as err:  # json.JSONDecodeError and tomllib.TOMLDecodeError are ValueErrors
        raise ValueError(f"{path.name}: not valid {'JSON' if path.suffix.lower() == '.json' else 'TOML'}: {err}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path.name}: the file must hold a table of keys")
    unknown = [k for k in data if k not in LINKAGE_KEYS + ("stroke",)]
    if unknown:
        raise ValueError(f"{path.name}: unknown key(s) {unknown}; a linkage file has {list(LINKAGE_KEYS)} and [stroke]")
    for k in ("points", "links"):
        if k not in data:
            raise ValueError(f"{path.name}: a linkage file needs [{k}]")
    args = {k: v for k, v in data.items() if k in LINKAGE_KEYS}
    args.setdefault("name", path.stem)
    try:
        linkage = Linkage(**args)
    except ValueError as err:
        raise ValueError(f"{path.name}: {err}") from None
    stroke = dict(data.get("stroke", {}))
    bad = [k for k in stroke if k not in ("from", "to", "speed", "summary")]
    if bad:
        raise ValueError(f"{path.name}: unknown [stroke] key(s) {bad}; it takes from, to, speed, summary")
    return linkage, stroke


def load_linkage(path) -> Linkage:
    """The ``Linkage`` a TOML or JSON file describes (``read_linkage_file`` without its stroke)."""
    return read_linkage_file(path)[0]
