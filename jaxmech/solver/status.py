"""Per-sample result codes of a position solve, with a readable message for each."""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["Status", "status_message", "status_counts"]


class Status(enum.IntEnum):
    """Result code of one sample.  Only ``CONVERGED`` carries finite positions.

    - ``CONVERGED``: residual and Newton step below the scale-aware tolerances, Jacobian
      well conditioned.
    - ``MAX_STEPS``: the iteration budget ran out while still making progress.
    - ``SINGULAR``: the loop closes but the constraint Jacobian is singular to working
      precision (toggle / dead-centre); derivatives are unbounded there.
    - ``INFEASIBLE``: the residual stalls above tolerance: the design cannot be assembled
      at this input (a triangle inequality is violated), or no root is near the guess.
    - ``NONFINITE``: an input, parameter, guess or residual is NaN or infinite.
    - ``BRANCH``: the loop closed on a different assembly branch than the guess's (the
      mechanism's ``branch`` indicator changed sign).
    """

    CONVERGED = 0
    MAX_STEPS = 1
    SINGULAR = 2
    INFEASIBLE = 3
    NONFINITE = 4
    BRANCH = 5


_MESSAGES = {
    Status.CONVERGED: "converged",
    Status.MAX_STEPS: "not converged within the iteration budget; raise SolverOptions.max_iterations or give a closer guess",
    Status.SINGULAR: "singular Jacobian (toggle / dead-centre position): positions exist but derivatives are unbounded",
    Status.INFEASIBLE: "cannot be assembled here: the loop-closure residual stalls above tolerance",
    Status.NONFINITE: "non-finite input, parameter, guess or residual",
    Status.BRANCH: "closed on a different assembly branch than the guess",
}


def status_message(code) -> str:
    """Readable message for a status code (int or ``Status``)."""
    return _MESSAGES[Status(int(code))]


def status_counts(status) -> dict[str, int]:
    """``{name: count}`` of the statuses in a batch (only the codes that occur)."""
    codes, counts = np.unique(np.asarray(status).ravel(), return_counts=True)
    return {Status(int(c)).name: int(n) for c, n in zip(codes, counts)}
