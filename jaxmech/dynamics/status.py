"""Result codes of a statics solve or a forward-dynamics run (``DynStatus``) and their messages."""

from __future__ import annotations

import enum

__all__ = ["DynStatus", "dyn_status_message"]


class DynStatus(enum.IntEnum):
    """Result code of a statics solve or a forward-dynamics run.

    - ``OK``: converged (statics) / integrated to the end (dynamics).
    - ``POSITION``: the loop could not be closed at some state: a singular (toggle, dead
      centre) or unassemblable position was reached.
    - ``STROKE_END``: the input left the given stroke range; the run stopped there.
    - ``NOT_CONVERGED``: a Newton iteration (statics, or an implicit step) did not converge.
    - ``NONFINITE``: a non-finite value appeared (mass matrix singular, NaN load...).
    - ``NO_EQUILIBRIUM``: statics: the generalized force does not change sign over the given
      range (no equilibrium in it, or an even number of them).
    - ``FRICTION``: forward dynamics with joint friction: at some state friction's Newton
      found no accelerations satisfying the friction law (friction jams the linkage).
    """

    OK = 0
    POSITION = 1
    STROKE_END = 2
    NOT_CONVERGED = 3
    NONFINITE = 4
    NO_EQUILIBRIUM = 5
    FRICTION = 6


_DYN_MESSAGES = {
    DynStatus.OK: "ok",
    DynStatus.POSITION: "the loop could not be closed: a singular (toggle) or unassemblable position was reached",
    DynStatus.STROKE_END: "the input reached the end of the stroke range; integration stopped",
    DynStatus.NOT_CONVERGED: "Newton did not converge (statics) or an implicit step failed (reduce the step)",
    DynStatus.NONFINITE: "a non-finite value appeared (singular mass matrix, NaN load or parameter)",
    DynStatus.NO_EQUILIBRIUM: "no equilibrium in the given range: the generalized force keeps one sign there",
    DynStatus.FRICTION: ("joint friction's Newton found no accelerations satisfying the friction law: friction jams the "
                         "linkage there (or a step too large for the sign's band: use a smaller h)"),
}


def dyn_status_message(code) -> str:
    """Readable message for a ``DynStatus`` code."""
    return _DYN_MESSAGES[DynStatus(int(code))]

