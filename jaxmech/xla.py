"""Backend workarounds: each one limited to the backend it helps, each with a test.

XLA's CPU fusion copies an elementwise producer into every consumer fusion, so a value
used by several consumers (the sine of a link angle in a residual, its Jacobian and its
second derivatives) is recomputed in each of them.  A product is not fused, so passing a
few packed values through an identity product makes them one materialised array.  On
other backends (GPU: fusions are cheap to recompute, memory traffic is not) the values
pass unchanged.  ``tests/test_xla.py`` counts the sines and cosines this saves in a compiled
residual-and-derivatives program.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["unfused"]


def _on_cpu() -> bool:
    return jax.default_backend() == "cpu"


def unfused(v):
    """``v`` unchanged; on CPU computed once under jit as ``I @ v`` over its first axis.

    Exact (``1 x + 0 y``) for finite values; a non-finite entry can turn the others along
    the first axis non-finite, so pack only values that are finite or non-finite together.
    Cost: one pass over ``v`` (the first axis is small).
    """
    if not _on_cpu():
        return v
    eye = jnp.eye(v.shape[0], dtype=v.dtype)
    return jnp.tensordot(eye, v, axes=1, precision=jax.lax.Precision.HIGHEST)
