"""Backend workarounds: each one limited to the backend it helps, each with a test.

XLA's CPU fusion copies an elementwise producer into every consumer fusion, so a value
used by several consumers (the sine of a link angle in a residual, its Jacobian and its
second derivatives) is recomputed in each of them.  A product is not fused, so passing a
few packed values through an identity product makes them one materialised array.  On
other backends (GPU: fusions are cheap to recompute, memory traffic is not) the values
pass unchanged.  ``tests/test_xla.py`` counts the sines and cosines this saves in a compiled
residual-and-derivatives program.

XLA's CPU fusion emitters (the MLIR code generator for fused loops, on by default in
jaxlib 0.10) take twice as long to compile the library's programs as the classic LLVM IR
emitters, for the same values: the four-bar's stroke program compiles in 0.59 s instead of
1.18 s and runs in 0.97 instead of 1.28 ms (``benchmarks/latency.py``).  ``jit`` compiles
the library's programs with ``COMPILER_OPTIONS``, which turn them off: a field of XLA's
debug options that only the CPU compiler reads.  Other backends refuse it (jax 0.11.2 on an
H200: ``INVALID_ARGUMENT: No such compile option``), so on them the library's programs
compile with the backend's defaults (``_on_cpu``).  A CPU compiler that no longer knows the
option (jaxlib 0.11.2 on a CPU refuses it the same way) is found by a tiny program it
compiles once: then this process compiles with the defaults (``_with_options``).  ``tests/test_xla.py`` checks that a scene's whole stroke (positions,
statuses, derivatives and points) comes out the same either way, to rounding.

A top-level call of a library program (concrete arguments) is run by this process's
*runner* where one is installed (``serve_top_level``): ``import jaxmech`` installs the
executable store's (``jaxmech._compile.stored.cached_call``), so a new process loads a
program instead of compiling it.  The numerical modules only ``jit`` their programs; they
never name the store, and which programs it may keep is decided here, from their form
(``_storable_statics``), not marked by them.
"""

from __future__ import annotations

import functools
import inspect

import jax
import jax.numpy as jnp

__all__ = ["COMPILER_OPTIONS", "jit", "serve_top_level", "unfused", "warn_if_wrong_jaxlib"]

#: XLA options for every program the library compiles itself (see the module docstring).
#: A user's own ``jax.jit`` around library calls compiles with the user's options.
#: (LLVM at optimisation level 2, XLA's default being 3, was tried: 10-20% less compile for a
#: scene's program, but a sweep of 8192 four-bar designs ran 7-10% slower, its batched stroke
#: above all, and the level changes the last bits of some accelerations.)
COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def jit(fun=None, **kwargs):
    """``jax.jit`` with ``COMPILER_OPTIONS`` where JAX allows them; usable as ``@jit``,
    ``@jit(static_argnums=...)`` or ``functools.partial(jit, static_argnums=...)``.

    JAX takes compiler options only on a top-level ``jit``: a call with traced arguments (the
    library inside a user's ``jit``, ``vmap`` or ``grad``) runs the plain ``jax.jit``
    function, which the enclosing program compiles with its own options.  A top-level call
    goes to the installed runner (``serve_top_level``) where the program may be kept
    (``_storable_statics``)."""
    if fun is None:
        return functools.partial(jit, **kwargs)
    return _Jitted(fun, jax.jit(fun, compiler_options=COMPILER_OPTIONS, **kwargs), jax.jit(fun, **kwargs),
                   _storable_statics(fun, kwargs))


# runner(fn, n_static, args) for top-level calls of storable programs (serve_top_level); None: call them
_RUNNER: list = [None]


def serve_top_level(runner) -> None:
    """Run every later top-level call of a storable library program as ``runner(fn,
    n_static, args)``: ``fn`` is the library's jitted function (``fn.program()`` the
    ``jax.jit`` function the call would compile, with its compiler options; ``fn.direct``
    calls it without the runner), its first ``n_static`` positional arguments are static,
    and ``runner`` must return what ``fn.direct(*args)`` returns.  None: the programs are
    called directly."""
    _RUNNER[0] = runner


def _storable_statics(fun, kwargs) -> int | None:
    """How many leading positional arguments of ``fun`` are static, where a runner may keep
    its compiled program by its name, static arguments and shapes; None where it may not:
    a closure or lambda (its captured values are in no key), a method or other callable,
    static arguments named or not leading."""
    if not inspect.isfunction(fun) or "<" in fun.__qualname__ or "." in fun.__qualname__:
        return None
    if set(kwargs) - {"static_argnums"}:  # named statics, donations, shardings: not keyed
        return None
    nums = kwargs.get("static_argnums", ())
    nums = (nums,) if isinstance(nums, int) else tuple(nums)
    return len(nums) if sorted(nums) == list(range(len(nums))) else None


class _Jitted:
    """A function jitted twice: with the options (top level, on a CPU) and without (inside a
    trace, or on another backend, which refuses the CPU compiler's options)."""

    def __init__(self, fun, top, nested, n_static: int | None):
        self._top, self._nested, self._n_static = top, nested, n_static
        functools.update_wrapper(self, fun)

    def program(self):
        """The ``jax.jit`` function a top-level call runs: with ``COMPILER_OPTIONS`` where this
        backend's compiler takes them."""
        return self._top if _with_options() else self._nested

    def __call__(self, *args, **kwargs):
        if _traced((args, kwargs)):
            return self._nested(*args, **kwargs)
        runner = _RUNNER[0]
        if runner is not None and self._n_static is not None and not kwargs:
            # the runner resolves the program only where it compiles: a warm call that loads
            # a stored executable never probes the compiler (``_accepted``, a compile of its own)
            return runner(self, self._n_static, args)
        return self._concrete(*args, **kwargs)

    def direct(self, *args, **kwargs):
        """The call without the runner: the program itself (``program``), or the plain
        ``jax.jit`` function inside a trace."""
        if _traced((args, kwargs)):
            return self._nested(*args, **kwargs)
        return self._concrete(*args, **kwargs)

    def _concrete(self, *args, **kwargs):
        program = self.program()
        try:
            return program(*args, **kwargs)
        except ValueError as err:  # concrete arguments, but inside a trace all the same
            if program is self._nested or "compiler_options" not in str(err):
                raise
            return self._nested(*args, **kwargs)

    def __getattr__(self, name):  # lower, trace, eval_shape...: the top-level function's
        return getattr(self.program(), name)


def _traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _on_cpu() -> bool:
    return jax.default_backend() == "cpu"


@functools.cache
def _accepted(backend: str, options: tuple) -> bool:
    """Whether the default backend's compiler (`backend`, the cache's key) takes `options` (a
    tiny program compiled once per process:
    ~10 ms; jaxlib 0.11.2's CPU compiler refuses ``xla_cpu_use_fusion_emitters``)."""
    try:
        jax.jit(lambda x: x + 1, compiler_options=dict(options)).lower(jnp.zeros((), jnp.int32)).compile()
    except Exception as err:  # noqa: BLE001 - "INVALID_ARGUMENT: No such compile option"
        if "compile option" not in str(err):
            raise
        return False
    return True


def _with_options() -> bool:
    """Whether the library's top-level programs compile with ``COMPILER_OPTIONS``: on a CPU
    whose compiler knows them."""
    return _on_cpu() and _accepted(jax.default_backend(), tuple(sorted(COMPILER_OPTIONS.items())))


def unfused(v):
    """``v`` unchanged; on CPU computed once under jit as ``I @ v`` over its first axis.

    Exact (``1 x + 0 y``) for finite values; a non-finite entry can turn the others along
    the first axis non-finite, so pack only values that are finite or non-finite together.
    Cost: one pass over ``v`` (the first axis is small).
    """
    if not _on_cpu():
        return v
    # built by iota and compare: a product with a constant identity (np.eye) is folded away
    # by XLA, and the values are fused again (tests/test_xla.py counts the sines)
    eye = jnp.eye(v.shape[0], dtype=v.dtype)
    return jnp.tensordot(eye, v, axes=1, precision=jax.lax.Precision.HIGHEST)


#: jaxlib releases known to compute wrong values on the CPU, with the report that shows it.
#: ``pyproject.toml`` excludes them; an environment that has one anyway is warned at import.
WRONG_JAXLIB = {"0.10.2": "vmapped reductions miscompiled on the CPU, jax-ml/jax#39103"}


def warn_if_wrong_jaxlib() -> None:
    """A ``RuntimeWarning`` when the installed jaxlib is one of ``WRONG_JAXLIB``."""
    import warnings
    from importlib import metadata

    try:
        version = metadata.version("jaxlib")
    except metadata.PackageNotFoundError:
        return
    if version in WRONG_JAXLIB:
        warnings.warn(
            f"jaxlib {version} computes wrong values ({WRONG_JAXLIB[version]}); install another: "
            f"pip install 'jax!={version}' 'jaxlib!={version}'",
            RuntimeWarning, stacklevel=3,
        )  # fmt: skip
