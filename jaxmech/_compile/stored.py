"""Stored executables: a new process runs a library program without tracing, lowering or
compiling it.

The library's programs are jitted with ``solver.xla.jit``; this module installs
``cached_call`` as the runner of their top-level calls (``solver.xla.serve_top_level``: a
module-level function whose static arguments lead), and ``scenes.evaluation`` runs a
scene's two programs through ``cached_chain``.  Their top-level calls (concrete arguments) come here:
the first process that runs a program compiles it once (``lower().compile()``, the same
executable the jitted call would build), runs it, and stores that executable
(``jax.experimental.serialize_executable``) before the call returns; a later process loads
it and calls it directly.  Inside a trace the jitted function runs as usual: the store is consulted only at
the edge of a computation, never inside its numerical path.

The store needs no JAX setting and changes none (its folder: ``cache.executables_dir()``,
``$XDG_CACHE_HOME/jaxmech/executables`` by default; ``JAXMECH_COMPILE_CACHE=0`` turns it off,
``JAXMECH_EXPORT_CACHE=0`` this store only, both read at every call).  JAX's persistent
cache is the user's: where it is on and served a program (an executable JAX loaded from its
own cache loses kernels when serialised again, jaxlib 0.10), that program is used but not
stored; a listener of JAX's cache-hit events is registered for the length of such a
compile only, and only while a folder for JAX's cache is set (JAX decides once per process
whether its cache is used, so a later ``jax_enable_compilation_cache=False`` does not stop
it serving programs: the listener does not trust that flag).

A stored executable is used only where it is exactly what the jitted function would run:

- every argument is concrete (no tracer: under ``jax.grad``, ``jit`` or ``vmap`` the normal
  path runs, so custom derivative rules, which an executable does not carry, are never
  needed);
- the key holds everything that determines the program: the function's name, its static
  arguments (a ``Mechanism`` by its traced-program fingerprint, a registry scene by its name,
  options and flags by value, pytree structures whose node types are jaxmech's or Python's
  own), the structure, shapes, dtypes and weak types of the arguments, the JAX flags that
  change tracing (x64, promotion and precision defaults), ``XLA_FLAGS``, the devices, the
  backend and its version, the jax and jaxlib versions, this machine's processor (an
  executable is native code for its instruction set), and a hash of every source file of
  the jaxmech package (an edited library never reuses a stale program); a static argument
  that cannot be put in such a key (a user's function, a mechanism whose functions do not
  trace) means nothing is stored, only the normal path;
- files are written atomically (a temporary file, then a rename) with a SHA-256 of their
  contents, checked before loading; any failure to compile on its own, store, read or load
  falls back to the normal jitted call.

The files are pickles of compiled code, like JAX's own compilation cache: load them only
from a folder you trust (your own cache folder, the default).  Within a process, a program
serves every later call with the same key (compiled once, like the jitted function it
stands for).

Compiled code is memory the process keeps: before the store loads or compiles a program,
``room.make_room`` releases this process's compiled programs where its memory mappings near
the kernel's limit (a crash otherwise; see ``room``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import os
import pickle
import platform
import tempfile
import threading
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax
import jaxlib
from jax.experimental.serialize_executable import deserialize_and_load, serialize

from ..solver.xla import serve_top_level
from .cache import executables_dir
from .quiet import quiet_loads
from .room import make_room, on_release

__all__ = ["cached_call", "cached_chain", "calls_lapack", "store_dir", "store_stats", "static_token",
           "wait_for_stores"]

# What ``cached_call`` did, per process: loaded (a stored executable was used), stored (one
# was written), served (compiled, but JAX's own cache served it, so it is not stored),
# fallback (the normal path ran where a key existed but compiling failed).
_STATS = {"loaded": 0, "stored": 0, "served": 0, "fallback": 0}
# (folder, key) -> the compiled program that serves it in this process (None: use the jit path)
_PROGRAMS: dict[tuple[str, str], object] = {}
on_release(_PROGRAMS.clear)
_OFF = {"0", "off", "false", "no"}
# JAX flags that change what a traced program is
_FLAGS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_numpy_dtype_promotion", "jax_numpy_rank_promotion")


def store_stats() -> dict[str, int]:
    """Counts for this process: ``loaded`` (stored executables used), ``stored`` (written:
    after ``wait_for_stores``, every one this process compiled and may store), ``served``
    (compiled programs that JAX's persistent cache served, used but not stored), ``fallback``."""
    return dict(_STATS)


def store_dir() -> Path | None:
    """The folder of stored executables (``cache.executables_dir()``), or None when the
    store is off (``JAXMECH_COMPILE_CACHE=0`` or ``JAXMECH_EXPORT_CACHE=0``)."""
    if os.environ.get("JAXMECH_EXPORT_CACHE", "1").strip().lower() in _OFF:
        return None
    return executables_dir()


@functools.cache
def _processor() -> str:
    """This machine's processor: its architecture and, on Linux, its instruction-set flags."""
    flags = ""
    try:
        with open("/proc/cpuinfo") as f:
            flags = next((line for line in f if line.startswith(("flags", "Features"))), "")
    except OSError:
        pass
    return hashlib.sha256(f"{platform.machine()}|{platform.processor()}|{flags}".encode()).hexdigest()


@functools.cache
def source_hash() -> str:
    """SHA-256 of every ``.py`` file of the jaxmech package, its subpackages included
    (relative path and bytes)."""
    root = Path(__file__).resolve().parents[1]  # jaxmech/, above this module's _compile/
    digest = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        digest.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()


def _jaxmech_type(t: type) -> bool:
    return t.__module__ == "builtins" or t.__module__.split(".")[0] == "jaxmech"


def static_token(x):
    """A text that determines ``x`` as a static argument of a jaxmech program, or None when
    there is none (a user's function, a mechanism that does not trace, a foreign pytree)."""
    from ..mechanism.mechanism import Mechanism  # here: mechanism imports jax programs of its own

    if x is None or isinstance(x, (bool, int, float, complex, str)):  # complex: a load's direction
        return repr(x)
    if isinstance(x, Mechanism) or hasattr(type(x), "program_key"):  # a mechanism, a scene, a model
        key = x.program_key
        if key is not None:
            return f"{type(x).__name__}({key})"
        if isinstance(x, Mechanism):
            return None
        # else a model without a key: determined by its parts where they are all ours (below)
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
    leaves, treedef = jax.tree_util.tree_flatten(args)
    if any(isinstance(x, jax.core.Tracer) for x in leaves):  # inside a trace: the jit path
        return None
    tokens = [static_token(s) for s in static]
    if any(t is None for t in tokens):
        return None
    avals = []
    for x in leaves:
        a = x if isinstance(x, jax.ShapeDtypeStruct) else jax.typeof(x)
        avals.append((tuple(a.shape), str(a.dtype), bool(a.weak_type)))
    flags = tuple(getattr(jax.config, f, None) for f in _FLAGS)
    devices = [(d.platform, d.device_kind, d.id) for d in jax.devices()]
    material = (
        f"{fn.__module__}.{fn.__qualname__}", tokens, repr(treedef), avals, flags, os.environ.get("XLA_FLAGS", ""),
        jax.default_backend(), devices, jax.devices()[0].client.platform_version, _processor(),
        jax.__version__, jaxlib.__version__, source_hash(),
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


def _load(path: Path):
    """The stored executable at ``path`` (checked against its SHA-256), or None."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    digest, payload = data[:32], data[32:]
    if hashlib.sha256(payload).digest() != digest:  # truncated or damaged: never loaded
        return None
    try:
        with quiet_loads():  # jaxlib 0.10.1's loader logs a spurious machine mismatch
            return deserialize_and_load(*pickle.loads(zlib.decompress(payload)))
    except Exception:  # from another version or machine after all: compile it anew
        return None


def _path(folder: Path, key: str) -> Path:
    return folder / f"{key}.jaxexec"


def _tombstone(folder: Path, key: str) -> Path:
    """Marks a key whose stored executable this runtime loaded but could not run."""
    return folder / f"{key}.unloadable"


# Loaded executables not yet run once in this process: their first run is waited for.
_UNCHECKED: set = set()


def _stored_program(folder: Path | None, key: str):
    """The stored executable of ``key`` in ``folder`` (counted as loaded), or None (also
    for a key marked unloadable)."""
    if folder is None or _tombstone(folder, key).exists():
        return None
    prog = _load(_path(folder, key))
    if prog is not None:
        _STATS["loaded"] += 1
        _UNCHECKED.add((str(folder), key))
    return prog


def _run(folder: Path, key: str, prog, args):
    """``prog(*args)``; a loaded executable's first run is waited for, so that one this
    runtime cannot run raises here (a kernel missing after deserialisation: "Function
    iota..._kernel not found", jaxlib 0.10, seen once in 6 suite runs): its file is then
    replaced by a tombstone, never loaded or stored again, and the caller compiles anew."""
    slot = (str(folder), key)
    out = prog(*args)
    if slot in _UNCHECKED:
        try:
            jax.block_until_ready(out)
        except Exception:
            _UNCHECKED.discard(slot)
            try:
                _write(_tombstone(folder, key), b"")
                _path(folder, key).unlink(missing_ok=True)
            except OSError:
                pass
            raise
        _UNCHECKED.discard(slot)
    return out


def calls_lapack(compiled) -> bool:
    """Whether a compiled program calls LAPACK (a custom call): such an executable crashes
    the process that loads it (jaxlib 0.10 registers its LAPACK kernels only when it
    compiles one itself, jax-ml/jax#28908), so it is never stored."""
    try:
        return 'custom_call_target="lapack' in compiled.as_text()
    except Exception:  # noqa: BLE001 - no text: assume the worst
        return True


_LOCK = threading.Lock()  # the store's counts, read by other threads (e.g. a notebook's)


def _store(path: Path, compiled) -> None:
    """Store ``compiled`` at ``path``, on the calling thread (about 0.1 s for a scene's
    program, before the first answer returns)."""
    if path.with_suffix(".unloadable").exists():  # loaded once and could not run: never again
        return
    try:
        # serialised before its text is read: once ``as_text`` had run, an executable with a
        # sort (``lax.top_k``) was seen to fail to serialise ("`LessThan` is not
        # serializable", jaxlib 0.10); with JAX's own cache on it fails either way, so the
        # library's stored programs hold no sort (design.qp._largest)
        data = pickle.dumps(serialize(compiled))
        if calls_lapack(compiled):
            return
        # zlib at level 1: a sixth of the size (a 3.3 MB scene program took 0.58 MB) for
        # 13 ms here and 8 ms when loaded
        payload = zlib.compress(data, 1)
        _write(path, hashlib.sha256(payload).digest() + payload)
        with _LOCK:
            _STATS["stored"] += 1
    except Exception:  # not serialisable, or a read-only cache: used in this process only
        pass


def wait_for_stores() -> None:
    """Nothing to wait for: every store is written before the call that compiled it returns."""


# An executable that JAX loaded from its own persistent cache must not be stored again:
# serialised a second time, it lost kernels ("Function ... not found" when run, jaxlib 0.10).
# JAX says so only by an event, so while JAX's cache is on (the user's choice) a listener
# counts its hits per thread for the length of a store's compile; the last compile to end
# removes it again.
_HITS = threading.local()
_LISTENERS = {"n": 0}


def _count_hit(event: str, **_) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _HITS.n = getattr(_HITS, "n", 0) + 1


@contextlib.contextmanager
def _jax_cache_hits():
    """A function giving how many programs JAX's persistent cache served on this thread
    since entry (0 while no folder is set for that cache: then no listener is registered).
    The enable flag is not read: JAX memoises at a process's first compile whether its cache
    is used, and serves programs from it after the flag is turned off."""
    if jax.config.jax_compilation_cache_dir is None:
        yield lambda: 0
        return
    with _LOCK:
        if _LISTENERS["n"] == 0:
            jax.monitoring.register_event_listener(_count_hit)
        _LISTENERS["n"] += 1
    before = getattr(_HITS, "n", 0)
    try:
        yield lambda: getattr(_HITS, "n", 0) - before
    finally:
        with _LOCK:
            _LISTENERS["n"] -= 1
            if _LISTENERS["n"] == 0:
                jax.monitoring.unregister_event_listener(_count_hit)


def _compile(fn, static: tuple, args: tuple):
    """``(compiled, whether it may be stored)``: ``fn`` lowered and compiled for these arguments."""
    return _compile_lowered(fn.lower(*static, *args))


def _compile_lowered(lowered):
    """``(compiled, whether it may be stored)`` for a lowered program: compiled with the
    options of its ``jit`` only (the executable the jitted call would build); not storable
    when JAX's persistent cache served it."""
    with _jax_cache_hits() as hits:
        compiled = lowered.compile()
        served = hits() > 0
    if served:
        with _LOCK:
            _STATS["served"] += 1
    return compiled, not served


def _direct(fn):
    """``fn`` called without the store: a library ``jit``'s ``direct`` (``solver.xla``: never
    through the runner, which would bring the call back here), ``fn`` itself otherwise."""
    return fn.direct if hasattr(fn, "direct") else fn


def cached_call(fn, static: tuple, args: tuple):
    """``fn(*static, *args)`` for a ``jit`` function whose static arguments come first, by its
    stored executable where that is exactly equivalent (see the module docstring), else by
    ``fn`` itself.  The first call of a key compiles ``fn`` once, runs it, then stores it."""
    folder = store_dir()
    if folder is None or jax.config.jax_disable_jit or jax.config.jax_debug_nans or jax.config.jax_debug_infs:
        return _direct(fn)(*static, *args)
    key = _key(fn, static, args)
    if key is None:
        return _direct(fn)(*static, *args)
    slot = (str(folder), key)  # a process may switch cache folders: each gets its own file
    fresh = None
    if slot not in _PROGRAMS:
        make_room()
        prog = _stored_program(folder, key)
        if prog is None:
            try:
                prog, storable = _compile(fn, static, args)
            except Exception:  # e.g. inside a user's trace: the jit path serves this key
                prog, storable = None, False
            fresh = prog if storable and not _tombstone(folder, key).exists() else None
        _PROGRAMS[slot] = prog
    prog = _PROGRAMS[slot]
    if prog is not None:
        try:
            out = _run(folder, key, prog, args)
        except Exception:  # e.g. an executable the runtime rejects: never again this process
            _PROGRAMS[slot] = None
        else:
            if fresh is not None:
                _store(_path(folder, key), fresh)
            return out
    _STATS["fallback"] += 1
    return _direct(fn)(*static, *args)


def _shapes(tree):  # arrays (or shapes) as plain ShapeDtypeStructs
    return jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), tree)


def cached_chain(first, static1: tuple, args1: tuple, second, static2: tuple, args2, with_first: bool = False):
    """``second(*static2, *args2(first(*static1, *args1)))`` for two ``jit`` functions whose
    static arguments come first: two programs, each run by its stored executable where that
    is exactly equivalent (as ``cached_call``).  Where they must be compiled, both are
    lowered first (the second from the first's output shapes), then compiled at once: XLA
    compiles the first on a thread of its own (it releases the GIL) while this thread
    compiles the second (a scene's stroke, then its kinematics and outputs: two cores do
    both in about the time of the longer).  ``with_first``: returns ``(first's outputs,
    second's)``.  ``args2``: a function of the first's outputs
    (arrays, or their ``ShapeDtypeStruct``s) giving the second's arguments.  With the store
    off, the programs are kept for this process only."""
    def plain():
        out1 = _direct(first)(*static1, *args1)
        out2 = _direct(second)(*static2, *args2(out1))
        return (out1, out2) if with_first else out2

    if jax.config.jax_disable_jit or jax.config.jax_debug_nans or jax.config.jax_debug_infs:
        return plain()
    key1 = _key(first, static1, args1)
    if key1 is None:
        return plain()
    folder = store_dir()
    slot1 = (str(folder), key1)
    fresh = []
    lowered = pending = None
    if slot1 not in _PROGRAMS:
        make_room()  # here, not between the two programs: it empties _PROGRAMS
        prog = _stored_program(folder, key1)
        if prog is not None:
            _PROGRAMS[slot1] = prog
        else:
            lowered = first.lower(*static1, *args1)
    with ThreadPoolExecutor(1, thread_name_prefix="jaxmech-compile") as pool:
        try:
            info = (_PROGRAMS[slot1] if lowered is None else lowered).out_info
            shapes2 = args2(_shapes(info))
            key2 = _key(second, static2, shapes2)
            slot2 = (str(folder), key2)
            if key2 is not None and slot2 not in _PROGRAMS:
                prog = _stored_program(folder, key2)
                if prog is None:
                    # both lowered before either compiles: only XLA's compiles run at once
                    lowered2 = second.lower(*static2, *shapes2)
                    pending = pool.submit(_compile_lowered, lowered) if lowered is not None else None
                    prog, storable = _compile_lowered(lowered2)
                    if storable:
                        fresh.append((key2, prog))
                _PROGRAMS[slot2] = prog
        finally:
            if lowered is not None:  # registered even where the second failed to trace
                prog, storable = pending.result() if pending is not None else _compile_lowered(lowered)
                _PROGRAMS[slot1] = prog
                if storable:
                    fresh.append((key1, prog))
    try:
        out1 = _run(folder, key1, _PROGRAMS[slot1], args1)
        out2 = _direct(second)(*static2, *args2(out1)) if key2 is None else _run(folder, key2, _PROGRAMS[slot2], args2(out1))
    except Exception:  # a loaded executable this runtime cannot run (``_run``): the jit path
        _PROGRAMS.pop(slot1, None)
        if key2 is not None:
            _PROGRAMS.pop(slot2, None)
        _STATS["fallback"] += 1
        return plain()
    if folder is not None:
        for key, prog in fresh:
            _store(_path(folder, key), prog)
    return (out1, out2) if with_first else out2


def cached_json(label: str, static: tuple, compute):
    """``compute()`` (a JSON value determined by the static arguments ``static`` and the
    package's source, e.g. the units of a scene's outputs, which a stored executable does not
    return), kept beside the stored programs so a new process need not trace to know it;
    ``compute()`` itself when nothing can be stored or read."""
    folder = store_dir()
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


# every later top-level call of a storable library program comes here (solver.xla)
serve_top_level(lambda fn, n_static, args: cached_call(fn, args[:n_static], args[n_static:]))
