"""Room for compiled code: a process that compiles hundreds of programs dies unless some are
released.

Each executable maps its code pages (a few mappings for a small program, a few hundred for
a scene's), and a process whose mappings reach the kernel's limit (Linux
``vm.max_map_count``, 65,530 by default) dies in its next compile or load: LLVM reports
"Cannot allocate memory" and XLA then crashes with a segmentation fault (jaxlib 0.10.1;
reproduced with the limit lowered to 6,000: 900 small programs).  A notebook or a test worker
gets there (the test suite lost a worker in every run of 2026-11-28, at 80-87% of its
tests).  So before the library's store (``stored``) loads or compiles a program,
``make_room`` checks the count and, past ``ROOM`` of the limit, releases this process's
compiled programs: those the library holds (``on_release``) and JAX's in-memory caches (as
``jax.clear_caches()``).  Later calls load or compile them again: time, not a crash.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax

__all__ = ["make_room", "map_count", "on_release"]

#: The share of the kernel's limit on a process's memory mappings past which ``make_room``
#: releases the compiled programs (the margin holds dozens of a scene's programs).
ROOM = 0.75
#: Mappings one program may add, at most (a scene's largest program maps about 450): after a
#: count, the next ``(ROOM * limit - count) / PER_PROGRAM`` loads and compiles are not
#: counted again (counting 20,000 mappings reads /proc for 18 ms).
PER_PROGRAM = 2000
_RELEASERS: list = []
_UNCOUNTED = [0]  # calls of make_room left before the next count


def on_release(fn):
    """Register ``fn()``, which drops compiled programs a module of the library holds, to be
    called by ``make_room``; returns ``fn``."""
    _RELEASERS.append(fn)
    return fn


def map_count() -> int | None:
    """How many memory mappings this process has (Linux), or None where that is not known."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return None


@functools.cache
def _map_limit() -> int | None:
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return None


def make_room(limit: int | None = None, *, every: bool = False) -> bool:
    """Release this process's compiled programs (those registered with ``on_release``, and
    JAX's in-memory caches) where its memory mappings exceed ``ROOM`` of ``limit`` (default:
    the kernel's ``vm.max_map_count``).  Returns whether it released them; nothing happens
    where the counts are unknown (not Linux).  Called before each load or compile, it counts
    only once the room its last count found may be used up (``PER_PROGRAM``); ``every``
    (or a `limit` given): count now (a caller whose calls may each compile many programs)."""
    if not every and limit is None and _UNCOUNTED[0] > 0:
        _UNCOUNTED[0] -= 1
        return False
    limit = _map_limit() if limit is None else limit
    n = map_count() if limit is not None else None
    if n is None:
        return False
    _UNCOUNTED[0] = max(0, int((ROOM * limit - n) // PER_PROGRAM))
    if n <= ROOM * limit:
        return False
    for fn in _RELEASERS:
        fn()
    jax.clear_caches()
    return True
