"""The result of a position solve: a pytree of per-sample values, statuses and diagnostics."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from .status import Status, status_counts, status_message

__all__ = ["Solution", "raise_if_failed", "require_concrete"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Solution:
    """Result of a position solve (a pytree; every array field has the batch shape in front).

    - `q`: dependent coordinates, ``(..., m)``; NaN where the status is not ``CONVERGED``.
    - `status`: ``(...)`` int32 ``Status`` codes.
    - `steps`: iterations used.
    - `residual`: final ``|Phi / R|_2``, R the residual scale (the length scale for loops).
    - `cond`: 1-norm condition number of the scaled constraint Jacobian ``Phi_q``.
    - `branch`: the mechanism's branch indicator at the solution, ``(...)`` or
      ``(..., n_branches)`` for one per loop (NaN if none defined).
    - `flipped`: ``(...)`` int32 bit mask of the branch entries whose sign differs from the
      requested one (bit ``i`` for ``branches[i]``); nonzero exactly where ``BRANCH``.
    - `coords`: coordinate names (static).
    - `branches`: names of the branch indicator's entries (static).
    """

    q: jax.Array
    status: jax.Array
    steps: jax.Array
    residual: jax.Array
    cond: jax.Array
    branch: jax.Array
    flipped: jax.Array
    coords: tuple = dataclasses.field(metadata=dict(static=True), default=())
    branches: tuple = dataclasses.field(metadata=dict(static=True), default=())

    def __getitem__(self, name: str):
        """Coordinate by name: ``sol["theta3"]``."""
        try:
            return self.q[..., self.coords.index(name)]
        except ValueError:
            raise KeyError(f"unknown coordinate {name!r}; coordinates: {self.coords}") from None

    @property
    def ok(self):
        """Boolean mask of converged samples."""
        return self.status == Status.CONVERGED

    def message(self, index=()) -> str:
        """Why the sample at ``index`` (a tuple into the batch shape) has its status, in
        words: for ``BRANCH`` the loops whose assembly flipped, for ``SINGULAR`` the
        condition number, with the fix."""
        code = int(np.asarray(self.status)[index])
        text = status_message(code)
        if code == Status.BRANCH:
            bits = int(np.asarray(self.flipped)[index])
            loops = [n for i, n in enumerate(self.branches) if bits >> i & 1]
            if loops:
                text += f": {', '.join(repr(n) for n in loops)} flipped; give a guess (or stroke start) on the branch you want, or a stroke that stays on it"
        elif code == Status.SINGULAR:
            text += (
                f": scaled condition number {float(np.asarray(self.cond)[index]):.3g} is inside the toggle band "
                "(SolverOptions.cond_max); keep the input away from the toggle, where positions and "
                "their derivatives are ill-defined"
            )
        return text


def require_concrete(args) -> None:
    """``ValueError`` if any leaf of ``args`` is traced: ``throw=True`` decides on values, and
    inside ``jax.jit``, ``vmap`` or ``grad`` none is known when the program is built (raising
    from the running program, by a callback, would surface as an opaque runtime error)."""
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(args)):
        raise ValueError("throw=True needs concrete inputs: inside jax.jit, vmap or grad no value is known when the "
                         "program is built; call with throw=False and check sol.status (jaxmech.status_counts) instead")


def raise_if_failed(sol: Solution):
    """``RuntimeError`` naming the failed samples' statuses and the first one's message, if
    any sample of ``sol`` is not ``CONVERGED`` (one failure raises for the batch)."""
    status = np.asarray(sol.status)
    if np.any(status != Status.CONVERGED):
        bad = {k: v for k, v in status_counts(status).items() if k != "CONVERGED"}
        first = np.argwhere(status != Status.CONVERGED)[0]
        raise RuntimeError(
            f"{int(np.sum(status != Status.CONVERGED))} of {status.size} samples failed {bad}; "
            f"first at index {tuple(int(i) for i in first)}: {sol.message(tuple(first))}"
        )



