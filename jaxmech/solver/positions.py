"""Position solves of batches of samples: ``solve`` (jit-compiled, vmapped) and ``solve_one``.

Every sample is one damped Newton solve (``newton.newton``) from its guess, with its root
attached to ``(u, p)`` by the implicit function theorem (``implicit.implicit_positions``).
Strokes, solved by continuation, are in ``continuation``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanism.branches import branch_names
from .linalg import where
from .implicit import implicit_positions
from .inputs import batch_shape, prepare
from ..mechanism.mechanism import Mechanism
from .newton import newton
from .options import SolverOptions
from .solution import Solution, raise_if_failed, require_concrete
from .status import Status
from .xla import jit

__all__ = ["solve", "solve_one"]


def solve_one(mech: Mechanism, u, p, guess, options: SolverOptions = SolverOptions()) -> Solution:
    """Solve ``Phi(q, u, p) = 0`` for one sample, differentiable in ``u`` and ``p``.

    `u`: ``(dof,)``; `p`: mapping of scalars; `guess`: ``(m,)``, which selects the branch.
    Returns a ``Solution`` with scalar status.  No checks: use ``solve`` from user code.
    """
    stop = jax.lax.stop_gradient
    res = newton(mech, options, stop(u), jax.tree_util.tree_map(stop, p), stop(guess))
    ok = res.status == Status.CONVERGED
    q = implicit_positions(mech, where(ok, res.q, jnp.nan), ok, u, p)
    return dataclasses.replace(res, q=q, coords=mech.coords, branches=branch_names(mech))


@functools.partial(jit, static_argnums=(0, 1))
def _solve_flat(mech, options, u, p, guess):
    return jax.vmap(lambda u_, p_, g_: solve_one(mech, u_, p_, g_, options))(u, p, guess)


def solve(mech: Mechanism, u, p: Mapping, guess, *, options: SolverOptions = SolverOptions(), throw: bool = False) -> Solution:
    """Solve the loop closure for a batch of inputs and designs (jit-compiled, vmapped).

    **Arguments**

    - `u`: driven inputs; array ``(..., dof)`` (or the bare batch array for one input), or a
      dict ``{input_name: array}``.  Radians for angles, metres for lengths.
    - `p`: ``{param_name: scalar or array}``; arrays broadcast against the batch.
    - `guess`: ``(..., m)`` or ``{coord_name: array}``; picks the assembly branch.
    - `options`: ``SolverOptions``.
    - `throw`: raise ``RuntimeError`` if any sample did not converge (one bad sample raises
      for the whole batch).  Needs concrete arguments: inside ``jax.jit``, ``vmap`` or
      ``grad`` no value is known when the program is built, so ``throw=True`` there raises
      ``ValueError`` at once; check ``sol.status`` instead.

    **Returns** a ``Solution`` whose fields have the broadcast batch shape in front;
    differentiable in ``u`` and ``p`` by the implicit function theorem.

    **Raises** ``ValueError`` for unknown names, bad values, shapes or dtypes (before tracing),
    and for ``throw=True`` with traced arguments.
    """
    if throw:
        require_concrete((u, p, guess))
    u, p, guess = prepare(mech, u, p, guess, options)
    shape = batch_shape(mech, {"u": u.shape[:-1], "guess": guess.shape[:-1], **{f"p[{k!r}]": v.shape for k, v in p.items()}})
    n = int(np.prod(shape, dtype=np.int64))
    uf = jnp.broadcast_to(u, shape + u.shape[-1:]).reshape(n, -1)
    gf = jnp.broadcast_to(guess, shape + guess.shape[-1:]).reshape(n, -1)
    pf = {k: jnp.broadcast_to(v, shape).reshape(n) for k, v in p.items()}
    sol = _solve_flat(mech, options, uf, pf, gf)
    sol = jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), sol)
    if throw:
        raise_if_failed(sol)
    return sol
