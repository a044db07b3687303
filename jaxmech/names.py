"""Names a person types: the valid name closest to a misspelt one, for the "did you mean"
of every message that refuses a name (scenes, parameters, points, links, drivers, file keys)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["closest", "did_you_mean", "near_hint"]


def closest(name: str, choices: Iterable[str]) -> str | None:
    """The valid name most like `name` (``difflib.get_close_matches``, similarity at least
    0.5, compared without case so that ``FOURBAR`` finds ``fourbar``), or None."""
    by_lower: dict[str, str] = {}
    for c in map(str, choices):
        by_lower.setdefault(c.lower(), c)
    found = difflib.get_close_matches(str(name).lower(), list(by_lower), n=1, cutoff=0.5)
    return by_lower[found[0]] if found else None


def did_you_mean(name: str, choices: Iterable[str], what: str = "valid names") -> str:
    """The end of a message refusing `name`: ``"did you mean 'crank'?"`` when a valid name
    is close to it, else ``"<what>: a, b, c"`` (every valid name)."""
    choices = [str(c) for c in choices]
    near = closest(name, choices)
    return f"did you mean {near!r}?" if near is not None else f"{what}: {', '.join(choices) or '(none)'}"


def near_hint(names: Iterable, choices: Iterable[str]) -> str:
    """``"; did you mean 'X'?"`` for the first of `names` (None skipped) that is not among
    `choices` but close to one of them, else ``""``: the tail of a message that lists them."""
    choices = [str(c) for c in choices]
    for n in names:
        if n is not None and str(n) not in choices and (near := closest(str(n), choices)) is not None:
            return f"; did you mean {near!r}?"
    return ""
