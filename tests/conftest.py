import jax

# Tests run in the accuracy mode: float64.  The library itself never flips this flag.
jax.config.update("jax_enable_x64", True)
