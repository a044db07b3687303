import os
import sys
import tempfile
from pathlib import Path

import jax

# Tests run in the accuracy mode: float64.  The library itself never flips this flag.
# (XLA_FLAGS=--xla_backend_optimization_level=0 halves compile time, but it was seen to give
# wrong values for a vmapped closed form here, so the tests compile as users do.)
jax.config.update("jax_enable_x64", True)

# Compiling dominates the suite's time; the test workers (pytest -n) and the command-line and
# notebook subprocesses share compiled kernels through JAX's persistent cache.
_CACHE = os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(tempfile.gettempdir(), "jaxmech-test-xla-cache"))
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)  # as jaxmech.enable_compile_cache
# The library's stored executables (jaxmech._compile.stored) likewise, out of the home folder.
os.environ.setdefault("JAXMECH_COMPILE_CACHE", os.path.join(tempfile.gettempdir(), "jaxmech-test-store"))

# The worked studies live in examples/ at the repository root (not in the package): make
# ``import examples`` work from any working directory, relative to this file.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
