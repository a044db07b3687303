"""A linkage file's ``[stroke]`` table as a drive (``docs/linkage_files.md``, "Strokes").

Three laws of the driven input ``u``:

- ``law = "sweep"`` (the default): ``from`` to ``to`` at the constant ``speed``.
- ``law = "rock"``: ``cycles`` times from ``from`` to ``to`` and back, smoothly,
  ``u(t) = mid - amp cos(2 pi t / period)`` with ``mid = (from + to) / 2`` and
  ``amp = (to - from) / 2`` over ``0 <= t <= cycles * period``; ``period`` (s) defaults to
  ``2 |to - from| / speed`` (the sweep's mean speed).  ``rock_samples`` is the same motion
  as the ``jm.Samples`` a user writes in Python.
- ``samples``: the input, its speed and acceleration at each sample (and optionally its
  time), given as a table ``[stroke.samples]`` with ``u``, ``u_dot``, ``u_ddot`` (and ``t``)
  lists, or as a CSV file with those columns, its path relative to the linkage file.
"""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np

from ..kinematics import Samples
from ..names import near_hint
from ..units import to_si

__all__ = ["FileStroke", "STROKE_KEYS", "read_stroke", "stroke_samples"]

STROKE_KEYS = ("from", "to", "speed", "summary", "law", "cycles", "period", "samples")
LAWS = ("sweep", "rock")
SAMPLE_COLUMNS = ("u", "u_dot", "u_ddot", "t")


@dataclasses.dataclass(frozen=True)
class FileStroke:
    """A ``[stroke]`` table read: `law` (``"sweep"``, ``"rock"`` or ``"samples"``), the
    `range` ``(from, to)`` in SI (None: the scene's default), `speed`, `summary`, `cycles`,
    `period` (s) and the given `samples` (a ``Samples``, for ``"samples"``)."""

    law: str = "sweep"
    range: tuple[float, float] | None = None
    speed: float = 1.0
    summary: str | None = None
    cycles: float = 1.0
    period: float | None = None
    samples: Samples | None = None


def rock_samples(u0: float, u1: float, cycles: float, period: float, points: int) -> Samples:
    """``cycles`` smooth reversals from `u0` to `u1` and back, ``points`` samples (both ends
    included): ``u = mid - amp cos(w t)``, ``u_dot = amp w sin(w t)``, ``u_ddot = amp w^2
    cos(w t)`` with ``w = 2 pi / period``, at times ``t = linspace(0, cycles * period)``."""
    t = np.linspace(0.0, cycles * period, points)
    w = 2.0 * np.pi / period
    mid, amp = 0.5 * (u0 + u1), 0.5 * (u1 - u0)
    return Samples(mid - amp * np.cos(w * t), amp * w * np.sin(w * t), amp * w * w * np.cos(w * t), t)


def stroke_samples(stroke: FileStroke, points: int) -> Samples | None:
    """The drive's samples of a rocking or sampled stroke (`points` of them for a rock; a
    sampled stroke's own); None for a sweep (the scene's constant-speed stroke)."""
    if stroke.law == "rock":
        return rock_samples(*stroke.range, stroke.cycles, stroke.period, points)
    return stroke.samples


def read_stroke(table: dict, unit: str, folder: Path) -> FileStroke:
    """The ``[stroke]`` table of a linkage file whose driven input is in `unit` (``"rad"`` or
    ``"m"``); `folder`: the linkage file's, where a samples CSV path starts.  ``ValueError``
    naming the key and what to give instead."""
    bad = [k for k in table if k not in STROKE_KEYS]
    if bad:
        raise ValueError(f"unknown [stroke] key(s) {bad}; it takes {', '.join(STROKE_KEYS)}{near_hint(bad, STROKE_KEYS)}")
    speed = _positive(table, "speed", unit + "/s", 1.0)
    summary = table.get("summary")
    if "samples" in table:
        mixed = [k for k in ("from", "to", "law", "cycles", "period", "speed") if k in table]
        if mixed:
            raise ValueError(f"[stroke] samples give the whole drive; leave out {mixed}")
        s = _samples(table["samples"], unit, folder)
        u = np.asarray(s.u)
        far = u[int(np.argmax(np.abs(u - u[0])))]
        return FileStroke("samples", (float(u[0]), float(far)), speed, summary, samples=s)
    rng = None
    if "from" in table or "to" in table:
        if not ("from" in table and "to" in table):
            raise ValueError("[stroke] needs both from and to")
        rng = tuple(to_si(str(table[k]), unit) for k in ("from", "to"))
    law = str(table.get("law", "sweep"))
    if law not in LAWS:
        raise ValueError(f"[stroke] law = {law!r} is not one of {list(LAWS)} (or give samples){near_hint([law], LAWS)}")
    if law == "sweep":
        extra = [k for k in ("cycles", "period") if k in table]
        if extra:
            raise ValueError(f"[stroke] {extra} belong to law = \"rock\"; add it or leave them out")
        return FileStroke("sweep", rng, speed, summary)
    if rng is None or rng[0] == rng[1]:
        raise ValueError("[stroke] law = \"rock\" needs from and to, two different values to rock between")
    cycles = _positive(table, "cycles", "-", 1.0)
    period = _positive(table, "period", "s", 2.0 * abs(rng[1] - rng[0]) / speed)
    return FileStroke("rock", rng, speed, summary, cycles, period)


def _positive(table: dict, key: str, unit: str, default: float) -> float:
    """``table[key]`` in SI (`default` when absent); ``ValueError`` unless it is a positive number."""
    if key not in table:
        return default
    value = to_si(str(table[key]), unit)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"[stroke] {key} = {table[key]!r} must be a positive number ({unit})")
    return value


def _samples(value, unit: str, folder: Path) -> Samples:
    """``Samples`` from a ``[stroke.samples]`` table or a CSV file's path (relative to `folder`)."""
    if isinstance(value, str):
        columns = _csv_columns(folder / value, value)
    elif isinstance(value, dict):
        columns = {k: list(v) if isinstance(v, list) else v for k, v in value.items()}
    else:
        raise ValueError("[stroke] samples must be a table (u, u_dot, u_ddot lists) or a CSV file's path")
    bad = [k for k in columns if k not in SAMPLE_COLUMNS]
    missing = [k for k in SAMPLE_COLUMNS[:3] if k not in columns]
    if bad or missing:
        raise ValueError(f"[stroke] samples: unknown {bad}, missing {missing}; give u, u_dot, u_ddot "
                         f"(and t, s){near_hint(bad, SAMPLE_COLUMNS)}")
    units = {"u": unit, "u_dot": unit + "/s", "u_ddot": unit + "/s^2", "t": "s"}
    arrays = {k: _numbers(columns[k], k, units[k]) for k in columns}
    sizes = {k: len(v) for k, v in arrays.items()}
    if len(set(sizes.values())) != 1 or sizes["u"] < 2:
        raise ValueError(f"[stroke] samples: u, u_dot, u_ddot (and t) need one value per sample, at least 2, got {sizes}")
    return Samples(arrays["u"], arrays["u_dot"], arrays["u_ddot"], arrays.get("t"))


def _numbers(values, key: str, unit: str) -> np.ndarray:
    """A list of numbers (or of strings with a unit) in SI; ``ValueError`` naming `key`."""
    if not isinstance(values, list):
        raise ValueError(f"[stroke] samples: {key} must be a list of numbers ({unit})")
    out = np.array([to_si(str(v), unit) for v in values], float)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"[stroke] samples: {key} has a value that is not a finite number")
    return out


def _csv_columns(path: Path, given: str) -> dict:
    """``{column: [text, ...]}`` of a CSV file with a header row; ``ValueError`` naming it."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = [r for r in csv.reader(f) if r]
    except OSError as err:
        raise ValueError(f"[stroke] samples = {given!r}: cannot read {path.name} ({err.strerror or err}); "
                         "give a CSV path relative to the linkage file") from None
    if len(rows) < 2:
        raise ValueError(f"[stroke] samples = {given!r}: a header (u, u_dot, u_ddot, t) and one row per sample are needed")
    header = [h.strip() for h in rows[0]]
    if any(len(r) != len(header) for r in rows[1:]):
        raise ValueError(f"[stroke] samples = {given!r}: every row needs {len(header)} values, as its header")
    return {h: [r[i].strip() for r in rows[1:]] for i, h in enumerate(header)}
