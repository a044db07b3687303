"""One family of result codes for every result of the library, with one readable message
for each: a position solve's samples, a statics solve, a forward-dynamics run, a design
start of ``minimize_second_order`` and a start of ``fit``.

A code means the same wherever it appears; each kind of result uses the codes that can
happen to it (the table below).  ``0`` (``CONVERGED``) is success everywhere.  The codes
before this family (``DynStatus``, ``StopReason``, the SQP's own ``Status``) are kept one
release as deprecated views onto it: their member names give the members here, so code
that compares with names keeps working; code that compares with raw integers must use the
names (``CHANGELOG.md`` lists the numbers that moved).
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["Status", "status_message", "status_counts"]


class Status(enum.IntEnum):
    """Result code of one sample, solve, run or start.  Only ``CONVERGED`` carries a valid
    answer (positions, an equilibrium, a whole trajectory, an optimum).

    Positions (``solve``, ``solve_stroke``, the scenes and sweeps), per sample:

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

    Statics and forward dynamics (``statics``, ``equilibrium``, ``forward_dynamics``), per
    solve or run: ``CONVERGED`` (converged; integrated to the end), ``NONFINITE`` (a
    singular mass matrix, a NaN load or parameter), and

    - ``POSITION``: the loop could not be closed at some state: a singular (toggle, dead
      centre) or unassemblable position was reached.
    - ``STROKE_END``: the input left the given stroke range; the run stopped there.
    - ``NOT_CONVERGED``: a Newton iteration (statics, or an implicit step) did not converge.
    - ``NO_EQUILIBRIUM``: statics: the generalized force does not change sign over the
      given range (no equilibrium in it, or an even number of them).
    - ``FRICTION``: forward dynamics with joint friction: at some state friction's Newton
      found no accelerations satisfying the friction law (friction jams the linkage).

    Design (``minimize_second_order`` and ``fit``), per start: ``CONVERGED`` (the KKT
    residual, or the objective and parameter changes, within tolerance), ``MAX_STEPS`` (the
    iteration or step budget ran out), ``INFEASIBLE`` (the start cannot be evaluated, or a
    fit's design stopped solving: it keeps its last feasible design), ``NONFINITE`` (a
    derivative or a step was not finite), and

    - ``SMALL_STEP``: the line search found no acceptable step.
    - ``DIVERGED``: a fit's parameters or gradient became non-finite, or its objective grew
      beyond ``diverge`` times its starting magnitude.
    """

    CONVERGED = 0
    MAX_STEPS = 1
    SINGULAR = 2
    INFEASIBLE = 3
    NONFINITE = 4
    BRANCH = 5
    POSITION = 6
    STROKE_END = 7
    NOT_CONVERGED = 8
    NO_EQUILIBRIUM = 9
    FRICTION = 10
    SMALL_STEP = 11
    DIVERGED = 12


_MESSAGES = {
    Status.CONVERGED: "converged",
    Status.MAX_STEPS: "not converged within the iteration budget; raise the budget (SolverOptions.max_iterations, "
                      "max_iter, steps) or give a closer guess",
    Status.SINGULAR: "singular Jacobian (toggle / dead-centre position): positions exist but derivatives are unbounded",
    Status.INFEASIBLE: "cannot be assembled here: the loop-closure residual stalls above tolerance",
    Status.NONFINITE: "a non-finite value: an input, parameter, guess, residual, load, derivative or step is NaN or "
                      "infinite (or the mass matrix is singular)",
    Status.BRANCH: "closed on a different assembly branch than the guess",
    Status.POSITION: "the loop could not be closed: a singular (toggle) or unassemblable position was reached",
    Status.STROKE_END: "the input reached the end of the stroke range; integration stopped",
    Status.NOT_CONVERGED: "Newton did not converge (statics) or an implicit step failed (reduce the step)",
    Status.NO_EQUILIBRIUM: "no equilibrium in the given range: the generalized force keeps one sign there",
    Status.FRICTION: ("joint friction's Newton found no accelerations satisfying the friction law: friction jams the "
                      "linkage there (or a step too large for the sign's band: use a smaller h)"),
    Status.SMALL_STEP: "the line search found no acceptable step (every shorter or corrected step failed or did not "
                       "decrease the penalty)",
    Status.DIVERGED: "diverged: non-finite parameters or gradient, or the objective blew up",
}


def status_message(code) -> str:
    """Readable message for a status code (int or ``Status``)."""
    return _MESSAGES[Status(int(code))]


def status_counts(status) -> dict[str, int]:
    """``{name: count}`` of the statuses in a batch (only the codes that occur)."""
    codes, counts = np.unique(np.asarray(status).ravel(), return_counts=True)
    return {Status(int(c)).name: int(n) for c, n in zip(codes, counts)}


class OldCodes:
    """A deprecated enum's view onto ``Status``: its member names give the ``Status``
    members now used for them (``DynStatus.OK`` is ``Status.CONVERGED``), and calling it
    with a code gives ``Status(code)``; iterating gives the members in the old order."""

    def __init__(self, name: str, members: dict[str, str]):
        self.__name__ = self.__qualname__ = name
        self._members = members

    def __getattr__(self, name):
        try:
            return Status[self.__dict__["_members"][name]]
        except KeyError:
            raise AttributeError(f"{self.__name__} has no member {name!r}") from None

    def __getitem__(self, name):
        return Status[self._members[name]]

    def __call__(self, code):
        return Status(int(code))

    def __iter__(self):
        return iter(Status[v] for v in self._members.values())

    def __len__(self):
        return len(self._members)

    def __repr__(self):
        return f"<deprecated {self.__name__}: the names of jaxmech.Status>"


#: The deprecated enums: old member name -> its ``Status`` name.
DYN_STATUS = OldCodes("DynStatus", {"OK": "CONVERGED", "POSITION": "POSITION", "STROKE_END": "STROKE_END",
                                    "NOT_CONVERGED": "NOT_CONVERGED", "NONFINITE": "NONFINITE",
                                    "NO_EQUILIBRIUM": "NO_EQUILIBRIUM", "FRICTION": "FRICTION"})
STOP_REASON = OldCodes("StopReason", {"CONVERGED": "CONVERGED", "MAX_STEPS": "MAX_STEPS", "INFEASIBLE": "INFEASIBLE",
                                      "DIVERGED": "DIVERGED"})
SQP_STATUS = OldCodes("Status", {"CONVERGED": "CONVERGED", "MAX_ITERATIONS": "MAX_STEPS", "SMALL_STEP": "SMALL_STEP",
                                 "START_NOT_EVALUATED": "INFEASIBLE", "NONFINITE": "NONFINITE"})


#: The retired names of the codes, per module that offered them: name -> (replacement, value).
RETIRED = {
    "jaxmech": {"DynStatus": ("jaxmech.Status", DYN_STATUS), "dyn_status_message": ("jaxmech.status_message", status_message)},
    "jaxmech.dynamics": {"DynStatus": ("jaxmech.Status", DYN_STATUS),
                         "dyn_status_message": ("jaxmech.status_message", status_message)},
    "jaxmech.design": {"StopReason": ("jaxmech.Status", STOP_REASON)},
    "jaxmech.design.fitting": {"StopReason": ("jaxmech.Status", STOP_REASON)},
    "jaxmech.design.nlp": {"Status": ("jaxmech.Status", SQP_STATUS)},
}


def retired(module: str, name: str):
    """A module's ``__getattr__`` for the codes' retired names (``RETIRED``): the value, with a
    DeprecationWarning naming its replacement; ``AttributeError`` for any other name."""
    if name not in RETIRED.get(module, {}):
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    import warnings

    replacement, value = RETIRED[module][name]
    warnings.warn(f"{module}.{name} is deprecated: use {replacement} (status codes are one family now; "
                  f"compare with the names, not the numbers)", DeprecationWarning, stacklevel=3)
    return value
