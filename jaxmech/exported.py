"""Exported programs on disk: a new process runs a stored program without tracing Python.

JAX's persistent compilation cache (``jaxmech.cache``) skips XLA's compile in a new process,
but not the tracing and lowering that come before it: for a scene's stroke program those
take seconds of Python.  So the first process that runs a jitted program with concrete
arguments also stores its lowered form (``jax.export``, StableHLO), and a later process
loads it and calls it directly; its compile then hits the persistent compilation cache.

The stored program is used only where it is exactly what the jitted function would run:

- every argument is concrete (no tracer: under ``jax.grad``, ``jit`` or ``vmap`` the normal
  path runs, so custom derivative rules, which an exported program loses, are never needed);
- the key holds everything that determines the program: the function's name, its static
  arguments (a ``Mechanism`` by its traced-program fingerprint, a registry scene by its name,
  options and flags by value,
  pytree structures whose node types are jaxmech's or Python's own), the structure, shapes,
  dtypes and weak types of the arguments, the JAX flags that change tracing (x64, promotion
  and precision defaults), the backend, the jax and jaxlib versions, and a hash of every
  source file of the jaxmech package (an edited library never reuses a stale program);
  a static argument that cannot be put in such a key (a user's function, a mechanism whose
  functions do not trace) means no export, only the normal path;
- files are written atomically (a temporary file, then a rename); any failure to export,
  write, read or load falls back silently to the normal jitted call.

Where: ``jaxmech-exported/`` inside the compilation cache folder in use (see
``jaxmech.cache``); nothing is stored or read when that cache is off, and
``JAXMECH_COMPILE_CACHE=0`` turns both off (``JAXMECH_EXPORT_CACHE=0``: this one only, read
at every call).  Within a process, a loaded program serves every
later call with the same key (compiled once, like the jitted function it stands for).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import tempfile
from pathlib import Path

import jax
import jaxlib

from .cache import compile_cache_dir, switched_off
from .xla import jit

__all__ = ["cached_call", "cached_json", "export_dir", "export_stats", "source_hash", "static_token"]

# What ``cached_call`` did, per process: loaded (a stored program was used), exported (one
# was written), fallback (the normal path ran where a key existed but export failed).
_STATS = {"loaded": 0, "exported": 0, "fallback": 0}
# (folder, key) -> the callable that serves it in this process (None: export failed, use the jit path)
_PROGRAMS: dict[tuple[str, str], object] = {}
_FOLDER = "jaxmech-exported"
_OFF = {"0", "off", "false", "no"}
# JAX flags that change what a traced program is
_FLAGS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_numpy_dtype_promotion", "jax_numpy_rank_promotion")


def export_stats() -> dict[str, int]:
    """Counts for this process: ``loaded`` (stored programs used), ``exported`` (written), ``fallback``."""
    return dict(_STATS)


def export_dir() -> Path | None:
    """The folder of exported programs, or None when it or the compilation cache is off."""
    cache = compile_cache_dir()
    if cache is None or switched_off() or os.environ.get("JAXMECH_EXPORT_CACHE", "1").strip().lower() in _OFF:
        return None
    return Path(cache) / _FOLDER


@functools.cache
def source_hash() -> str:
    """SHA-256 of every ``.py`` file of the jaxmech package (relative path and bytes)."""
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        digest.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()


def _jaxmech_type(t: type) -> bool:
    return t.__module__ == "builtins" or t.__module__.split(".")[0] == "jaxmech"


def static_token(x):
    """A text that determines ``x`` as a static argument of a jaxmech program, or None when
    there is none (a user's function, a mechanism that does not trace, a foreign pytree)."""
    from .mechanism import Mechanism  # here: mechanism imports jax programs of its own

    if x is None or isinstance(x, (bool, int, float, str)):
        return repr(x)
    if isinstance(x, Mechanism) or hasattr(type(x), "program_key"):  # a mechanism, a scene
        key = x.program_key
        return None if key is None else f"{type(x).__name__}({key})"
    if isinstance(x, tuple):
        parts = [static_token(v) for v in x]
        return None if any(v is None for v in parts) else "(" + ",".join(parts) + ")"
    if dataclasses.is_dataclass(x) and not isinstance(x, type) and _jaxmech_type(type(x)):
        parts = [static_token(getattr(x, f.name)) for f in dataclasses.fields(x)]
        return None if any(v is None for v in parts) else f"{type(x).__qualname__}({','.join(parts)})"
    if isinstance(x, jax.tree_util.PyTreeDef):
        return repr(x) if _treedef_ours(x) else None
    return None


def _treedef_ours(treedef) -> bool:
    """Every node of ``treedef`` is a Python container or a jaxmech class (whose code the
    source hash covers)."""
    data = treedef.node_data()
    if data is not None and not _jaxmech_type(data[0]):
        return False
    return all(_treedef_ours(c) for c in treedef.children())


def _key(fn, static: tuple, args: tuple) -> str | None:
    tokens = [static_token(s) for s in static]
    if any(t is None for t in tokens):
        return None
    leaves, treedef = jax.tree_util.tree_flatten(args)
    avals = []
    for x in leaves:
        if isinstance(x, jax.core.Tracer):
            return None
        a = jax.typeof(x)
        avals.append((a.shape, str(a.dtype), a.weak_type))
    flags = tuple(getattr(jax.config, f, None) for f in _FLAGS)
    material = (
        f"{fn.__module__}.{fn.__qualname__}", tokens, repr(treedef), avals, flags,
        jax.default_backend(), jax.__version__, jaxlib.__version__, source_hash(),
    )
    return hashlib.sha256(repr(material).encode()).hexdigest()


def _write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _program(fn, static: tuple, args: tuple, key: str, folder: Path):
    """The callable for ``key``: the stored program if there is one, else a new export."""
    path = folder / f"{key}.jaxexport"
    try:
        exp = jax.export.deserialize(bytearray(path.read_bytes()))
        _STATS["loaded"] += 1
        return jit(exp.call)
    except Exception:  # absent, unreadable or from another version: export it anew
        pass
    try:
        exp = jax.export.export(fn)(*static, *args)
    except Exception:  # not exportable: the jitted function serves this key in this process
        return None
    try:
        _write(path, bytes(exp.serialize()))
        _STATS["exported"] += 1
    except Exception:  # no serializer (flatbuffers) or a read-only cache: used in this process only
        pass
    return jit(exp.call)


def cached_call(fn, static: tuple, args: tuple):
    """``fn(*static, *args)`` for a ``jit`` function whose static arguments come first,
    by its stored exported program where that is exactly equivalent (see the module
    docstring), else by ``fn`` itself."""
    folder = export_dir()
    if folder is None or jax.config.jax_disable_jit or jax.config.jax_debug_nans or jax.config.jax_debug_infs:
        return fn(*static, *args)
    key = _key(fn, static, args)
    if key is None:
        return fn(*static, *args)
    slot = (str(folder), key)  # a process may switch cache folders: each gets its own file
    if slot not in _PROGRAMS:
        _PROGRAMS[slot] = _program(fn, static, args, key, folder)
    prog = _PROGRAMS[slot]
    if prog is not None:
        try:
            return prog(*args)
        except Exception:  # e.g. a stored program the runtime rejects: never again this process
            _PROGRAMS[slot] = None
    _STATS["fallback"] += 1
    return fn(*static, *args)


def cached_json(label: str, static: tuple, compute):
    """``compute()`` (a JSON value determined by the static arguments ``static`` and the
    package's source, e.g. the units of a scene's outputs, which a stored program does not
    return), kept beside the stored programs so a new process need not trace to know it;
    ``compute()`` itself when nothing can be stored or read."""
    folder = export_dir()
    tokens = [static_token(x) for x in static]
    if folder is None or any(t is None for t in tokens):
        return compute()
    key = hashlib.sha256(repr((label, tokens, source_hash(), jax.__version__)).encode()).hexdigest()
    path = folder / f"{key}.json"
    try:
        return json.loads(path.read_text())
    except Exception:  # absent or unreadable: compute it and store it
        pass
    value = compute()
    try:
        _write(path, json.dumps(value).encode())
    except Exception:  # a read-only cache: computed again next time
        pass
    return value
