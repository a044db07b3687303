import jax

# Tests run in the accuracy mode: float64.  The library itself never flips this flag.
# (XLA_FLAGS=--xla_backend_optimization_level=0 halves compile time, but it was seen to give
# wrong values for a vmapped closed form here, so the tests compile as users do.)
jax.config.update("jax_enable_x64", True)
