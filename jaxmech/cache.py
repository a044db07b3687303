"""The persistent compilation cache, on by default for the library.

A mechanism's compiled programs are written to disk the first time (JAX's persistent
compilation cache), so the next Python process that solves the same mechanism skips XLA's
compile.  jaxmech switches it on when imported, unless

- ``JAXMECH_COMPILE_CACHE=0`` (or ``off``/``false``) is set in the environment: no cache;
- the user configured JAX's own cache already (``JAX_COMPILATION_CACHE_DIR`` or
  ``jax.config.update("jax_compilation_cache_dir", ...)``): theirs is used, untouched.

Where: ``JAXMECH_COMPILE_CACHE=/some/dir`` if given, else ``$XDG_CACHE_HOME/jaxmech/xla``
(``~/.cache/jaxmech/xla``).  Clear it by deleting that folder.  Programs that took at
least ``min_compile_s`` (0.1 s) to compile are stored; JAX's own default, 1 s, would miss
most of jaxmech's, which are kept small on purpose.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

__all__ = ["default_cache_dir", "enable_compile_cache", "enable_default_cache", "compile_cache_dir", "switched_off"]

_OFF = {"0", "off", "false", "no", ""}


def default_cache_dir() -> Path:
    """``$JAXMECH_COMPILE_CACHE`` if it names a folder, else ``$XDG_CACHE_HOME/jaxmech/xla``."""
    env = os.environ.get("JAXMECH_COMPILE_CACHE")
    if env and env.strip().lower() not in _OFF and env.strip().lower() not in {"1", "on", "true", "yes"}:
        return Path(env).expanduser()
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "jaxmech" / "xla"


def compile_cache_dir() -> str | None:
    """The folder JAX's persistent compilation cache writes to now (None: off)."""
    return jax.config.jax_compilation_cache_dir


def enable_compile_cache(path: str | os.PathLike | None = None, *, min_compile_s: float = 0.0) -> str | None:
    """Switch JAX's persistent compilation cache on at ``path`` (default ``default_cache_dir()``).

    Returns the folder in use, or None when it cannot be created (a read-only home: the
    library then runs without the cache).  Called by ``import jaxmech`` unless switched off
    (see the module docstring); call it yourself to choose another folder.
    """
    folder = Path(path).expanduser() if path is not None else default_cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_s))
    return str(folder)


def switched_off() -> bool:
    """True when ``JAXMECH_COMPILE_CACHE`` says no cache (``0``, ``off``, ``false``, ``no``)."""
    env = os.environ.get("JAXMECH_COMPILE_CACHE")
    return env is not None and env.strip().lower() in _OFF


def enable_default_cache() -> None:
    """What ``import jaxmech`` does: respect an opt-out and the user's own JAX cache."""
    if switched_off():
        return
    if os.environ.get("JAX_COMPILATION_CACHE_DIR") or jax.config.jax_compilation_cache_dir:
        return
    enable_compile_cache()
