"""XLA's C++ log held back while a compiled program is loaded from disk.

jaxlib 0.10.1's CPU loader logs an ERROR line for every executable it loads, on the machine
that compiled it ("Target machine feature +prefer-no-gather is not supported on the host
machine ... could lead to execution errors such as SIGILL"): ``prefer-no-gather`` and
``prefer-no-scatter`` are tuning flags the compile records and the host check does not list
(jaxlib 0.10.2 does not log it; that release miscompiles, ``xla.WRONG_JAXLIB``).  The
library's store keys each program by this machine's processor flags
(``stored._processor``), so a program it loads was compiled on a machine like this one, and
the line is noise: two lines of it in a notebook cell, and a command line's one-line
answer (``jaxmech``) buried under them.  ``quiet_loads`` holds XLA's C++ log to FATAL for
the length of a load and then puts back the level JAX's own settings give
(``jax_logging_level``, else ``TF_CPP_MIN_LOG_LEVEL``, else 0).
"""

from __future__ import annotations

import contextlib
import os
import threading

import jax

__all__ = ["quiet_loads"]

_LOCK = threading.Lock()
_DEPTH = [0]  # holds open now, all threads

#: absl's levels: 0 INFO, 1 WARNING, 2 ERROR, 3 FATAL (jax._src.logging_config's map).
_LEVELS = {"CRITICAL": 3, "FATAL": 3, "ERROR": 2, "WARN": 1, "WARNING": 1, "INFO": 0, "DEBUG": 0}


def _setter():
    try:
        from jax._src.lib import utils  # jaxlib's absl binding (no public name for it)

        return utils.absl_set_min_log_level
    except (ImportError, AttributeError):  # another jaxlib: nothing to hold back
        return None


def _level_now() -> int:
    """The C++ log level JAX's settings give this process."""
    named = getattr(jax.config, "jax_logging_level", None)
    if named not in (None, "NOTSET") and named in _LEVELS:
        return _LEVELS[named]
    try:
        return int(os.environ.get("TF_CPP_MIN_LOG_LEVEL", "0") or 0)
    except ValueError:
        return 0


@contextlib.contextmanager
def quiet_loads():
    """XLA's C++ log at FATAL inside, JAX's level again after (see the module docstring)."""
    set_level = _setter()
    if set_level is None:
        yield
        return
    # nested (a store load inside the command's own hold): only the outermost one restores
    with _LOCK:
        _DEPTH[0] += 1
        set_level(3)
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH[0] -= 1
            if _DEPTH[0] == 0:
                set_level(_level_now())
