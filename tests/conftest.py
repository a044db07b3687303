import os

# The tests check numbers, not speed: XLA's backend optimisation buys run time we do not
# need at a compile cost we do (it halves the compile time of the Newton loops).  Set before
# JAX starts its backend; subprocesses (the CLI tests) inherit it.
os.environ.setdefault("XLA_FLAGS", "--xla_backend_optimization_level=0")

import jax  # noqa: E402

# Tests run in the accuracy mode: float64.  The library itself never flips this flag.
jax.config.update("jax_enable_x64", True)
