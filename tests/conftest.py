import os
import sys
import tempfile
from pathlib import Path

import jax
import pytest

# Tests run in the accuracy mode: float64.  The library itself never flips this flag.
# (XLA_FLAGS=--xla_backend_optimization_level=0 halves compile time, but it was seen to give
# wrong values for a vmapped closed form here, so the tests compile as users do.)
jax.config.update("jax_enable_x64", True)

# JAX's persistent compilation cache stays off in the suite: with jaxlib 0.10.2 its reads and
# writes of serialised executables crashed test workers (segfaults in
# compilation_cache.get_executable_and_time and put_executable_and_time, three CI runs of
# 2026-11-27, the last with no other thread doing XLA work).  The workers and the command-line
# and notebook subprocesses share the library's stored executables (jaxmech._compile.stored),
# out of the home folder; tests of the user's own JAX cache switch it on in a process of their own.
# ``jaxmech``'s command line switches JAX's cache on for its own process, and the in-process
# command-line tests run it inside a worker: that left the cache on for every later test of
# the worker (the CI runs of 8672e96 crashed a worker in put_executable_and_time, in a test
# that never asked for the cache).  Switched off here for the workers' whole life; the
# subprocesses that test the cache start with JAX's defaults.
jax.config.update("jax_enable_compilation_cache", False)
# CPU programs run synchronously in the workers: with jaxlib 0.10.x, XLA work on two threads
# at once crashed or hung (a worker segfaulted loading a stored program in the suite run of
# 2026-11-28 with an unnamed native thread beside it; benchmarks/flap_torque.py's executables
# hung on futexes with asynchronous dispatch).  Set before the CPU client exists.  (The
# lost workers of 2026-11-28 turned out to be the memory-mapping limit, see the fixture
# below; the hang is another symptom, so dispatch stays synchronous here.)
jax.config.update("jax_cpu_enable_async_dispatch", False)
os.environ.setdefault("JAXMECH_COMPILE_CACHE", os.path.join(tempfile.gettempdir(), "jaxmech-test-store"))

from jaxmech._compile import room  # noqa: E402


@pytest.fixture(autouse=True)
def _room_for_compiled_code():
    """A worker compiles hundreds of programs; each keeps its code mapped, and a process
    whose mappings reach the kernel's limit (``vm.max_map_count``) dies in its next compile or
    load (every suite run of 2026-11-28 lost a worker so, at 80-87% of its tests).  The
    library releases its compiled programs before that (``room.make_room``) where it loads
    or compiles through its store; the tests' own ``jax.jit`` programs count too, so the
    check also runs after every test."""
    yield
    room.make_room(every=True)

# The worked studies live in examples/ at the repository root (not in the package): make
# ``import examples`` work from any working directory, relative to this file.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
