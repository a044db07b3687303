"""Where jaxmech keeps compiled programs between processes; JAX's own cache as an opt-in.

``import jaxmech`` and every jaxmech call leave ``jax.config`` as the user set it.  Two
caches carry compiled programs from one Python process to the next:

- **the library's executable store** (``jaxmech._compile.stored``), on by default: the library's
  own programs (a stroke, a scene's two programs, inverse dynamics) stored whole, so a new
  process skips tracing, lowering and compiling them.  Its folder is ``executables_dir()``:
  ``$XDG_CACHE_HOME/jaxmech/executables`` (``~/.cache/jaxmech/executables``), or
  ``DIR/executables`` with ``JAXMECH_COMPILE_CACHE=DIR``; ``JAXMECH_COMPILE_CACHE=0`` (or
  ``off``/``false``/``no``) turns it off.  It does not need JAX's cache.
- **JAX's persistent compilation cache**: the user's to switch on, for every program of
  the process (a user's own ``jit``, a gradient through the library, small eager
  operations): ``jaxmech.enable_compile_cache()`` (at ``default_cache_dir()``, every
  program kept whatever its compile time) or ``jax.config.update("jax_compilation_cache_dir",
  ...)``.  The ``jaxmech`` command switches it on for its own process.

Clear either by deleting its folder.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import jax

__all__ = ["enable_compile_cache", "enable_default_cache", "executables_dir", "switched_off"]

_OFF = {"0", "off", "false", "no", ""}
_ON = {"1", "on", "true", "yes"}


def _chosen_dir() -> Path | None:
    """The folder named by ``JAXMECH_COMPILE_CACHE`` (None: not set, or a switch word)."""
    env = os.environ.get("JAXMECH_COMPILE_CACHE")
    if env and env.strip().lower() not in _OFF | _ON:
        return Path(env).expanduser()
    return None


def _base_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "jaxmech"


def default_cache_dir() -> Path:
    """The folder ``enable_compile_cache()`` gives JAX's persistent cache by default:
    ``$JAXMECH_COMPILE_CACHE`` if it names a folder, else ``$XDG_CACHE_HOME/jaxmech/xla``."""
    return _chosen_dir() or _base_dir() / "xla"


def executables_dir() -> Path | None:
    """The folder of the library's stored executables (``jaxmech._compile.stored``): ``executables``
    inside ``$JAXMECH_COMPILE_CACHE`` if it names a folder, else
    ``$XDG_CACHE_HOME/jaxmech/executables``; None when ``switched_off()``.  Read at every
    call; independent of JAX's ``jax_compilation_cache_dir``."""
    if switched_off():
        return None
    chosen = _chosen_dir()
    return chosen / "executables" if chosen is not None else _base_dir() / "executables"


def compile_cache_dir() -> str | None:
    """The folder JAX's persistent compilation cache writes to now (None: off)."""
    return jax.config.jax_compilation_cache_dir


def enable_compile_cache(path: str | os.PathLike | None = None, *, min_compile_s: float = 0.0) -> str | None:
    """Switch JAX's persistent compilation cache on at ``path`` (default ``default_cache_dir()``),
    for every program this process compiles from now on.

    An explicit opt-in: it changes two of the process's JAX settings,
    ``jax_compilation_cache_dir`` and ``jax_persistent_cache_min_compile_time_secs``
    (``min_compile_s``, in seconds: programs that took less to compile are not kept; JAX's
    own default, 1 s, misses most of jaxmech's, which are small on purpose).  The library
    itself never calls it; the ``jaxmech`` command does, for its own process.

    With jaxlib 0.10.2, processes that shared one cache folder while compiling at once (the
    test suite's workers) crashed inside JAX's cache read and write (three segfaults in
    ``compilation_cache.get_executable_and_time`` / ``put_executable_and_time``): give
    processes that run at the same time folders of their own.

    Returns the folder in use, or None when it cannot be created (a read-only home: nothing
    is changed).
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
    """Deprecated: what ``import jaxmech`` did up to 0.1.0 (switch JAX's persistent cache on
    unless ``JAXMECH_COMPILE_CACHE=0`` or a cache of the user's own).  Call
    ``enable_compile_cache()`` instead."""
    warnings.warn(
        "jaxmech.cache.enable_default_cache is deprecated: import jaxmech no longer switches JAX's "
        "persistent cache on; call jaxmech.enable_compile_cache() to switch it on yourself",
        DeprecationWarning, stacklevel=2,
    )  # fmt: skip
    if switched_off() or os.environ.get("JAX_COMPILATION_CACHE_DIR") or jax.config.jax_compilation_cache_dir:
        return
    enable_compile_cache()
