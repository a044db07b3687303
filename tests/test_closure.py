"""Closing the loop at a new input (statics' and forward dynamics' inner step) judges the
residual in the mechanism's own residual scale, as the solver does."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.dynamics import close_loop  # noqa: E402

# A balance in its own units (k times a measure), not a loop in metres: its residual scale
# is k.  Root: x = u^(1/3), where the residual is k times round-off (1e-7 for k = 1e9).
BALANCE = jm.Mechanism(coords=("x",), inputs=("u",), params=("k",), lengths=(),
                       constraints=lambda q, u, p: [p.k * (q.x**3 - u.u)], residual_scale=lambda p: p.k)


def test_close_loop_uses_the_residual_scale():
    for k in (1e-6, 1.0, 1e9, 1e12):
        for u in (0.3, 0.7, 1.3, 2.9):
            q, ok = close_loop(BALANCE, jnp.array([u]), {"k": jnp.asarray(k)}, jnp.array([1.01 * u ** (1 / 3)]), 4)
            assert bool(ok), (k, u)
            assert abs(float(q[0]) - u ** (1 / 3)) <= 4e-16 * u ** (1 / 3)
    # a guess it cannot close from in one step is refused whatever the scale
    q, ok = close_loop(BALANCE, jnp.array([0.3]), {"k": jnp.asarray(1e9)}, jnp.array([2.0]), 1)
    assert not bool(ok) and np.isnan(float(q[0]))
