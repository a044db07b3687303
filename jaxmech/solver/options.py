"""Solver settings and the tolerances they give for a dtype."""

from __future__ import annotations

import dataclasses
import functools
import warnings

import jax.numpy as jnp

__all__ = ["SolverOptions", "tolerances"]


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Static solver settings (hashable; part of the compiled function's identity).

    - `max_iterations`: Newton/Levenberg-Marquardt iteration budget per sample (formerly
      ``max_steps``, a name one letter from ``max_step``: still accepted, with a
      ``DeprecationWarning``).
    - `xtol`: converged when the next scaled Newton step is below this (rad, or
      multiples of the design's length scale).  Default ``eps**(2/3)`` of the dtype.
    - `ftol`: converged residual, relative to the design's length scale.  Default
      ``1024 eps``.
    - `cond_max`: a sample whose scaled Jacobian condition number exceeds this is reported
      ``SINGULAR`` (the toggle band).  Default ``eps**-0.5 / 32`` (2.1e6 in float64): an
      exact toggle's Newton iterate lands near ``eps**-0.5``, so it falls in the band in
      any unit system.
    - `max_step`: largest scaled step per iteration (rad, or length scales); keeps far-off
      guesses from jumping across assembly branches.
    - `patience`: iterations with less than 10% residual decrease before a sample is
      declared stalled (``INFEASIBLE``).
    - `anchors`: stroke points solved in sequence (``solve_stroke``); the points between
      two anchors are solved together from the earlier one's predictor.  More anchors:
      safer near toggles, slower.  A scene's stroke (``run_scene``, sweeps, design) is
      solved with ``scenes.evaluation.SCENE_OPTIONS``: 256 anchors.
    - `dtype`: require this floating dtype (``"float64"`` raises if x64 is off or an
      argument is float32); ``None`` follows the arguments.
    """

    max_iterations: int = 80
    xtol: float | None = None
    ftol: float | None = None
    cond_max: float | None = None
    max_step: float = 1.0
    patience: int = 8
    anchors: int = 512
    dtype: str | None = None


def _deprecated_init(init):
    """``SolverOptions``'s constructor, also taking ``max_steps`` (the deprecated name of
    ``max_iterations``, one letter from ``max_step``) with a ``DeprecationWarning``."""

    @functools.wraps(init)
    def wrapped(self, *args, max_steps=None, **kwargs):
        if max_steps is not None:
            warnings.warn("SolverOptions(max_steps=...) is deprecated: use max_iterations=... (max_step is the step cap)",
                          DeprecationWarning, stacklevel=2)
            kwargs.setdefault("max_iterations", int(max_steps))
        init(self, *args, **kwargs)

    return wrapped


def _max_steps(self) -> int:
    warnings.warn("SolverOptions.max_steps is deprecated: use max_iterations", DeprecationWarning, stacklevel=2)
    return self.max_iterations


SolverOptions.__init__ = _deprecated_init(SolverOptions.__init__)
SolverOptions.max_steps = property(_max_steps)




def tolerances(opts: SolverOptions, dtype):
    """``(xtol, ftol, cond_max)`` of ``opts`` for ``dtype`` (defaults from its machine eps)."""
    eps = float(jnp.finfo(dtype).eps)
    xtol = opts.xtol if opts.xtol is not None else eps ** (2.0 / 3.0)
    ftol = opts.ftol if opts.ftol is not None else 1024.0 * eps
    # A toggle band, scale-free: at an exact toggle (a double root) Newton stops where the
    # residual reaches round-off, about sqrt(eps) from the singular pose, where the scaled
    # condition number is about eps**-0.5 (seen: 0.9-4x that).  The band starts 32x below,
    # so a toggle reads SINGULAR whatever the units, never CONVERGED by a hair.
    cond_max = opts.cond_max if opts.cond_max is not None else eps**-0.5 / 32.0
    return xtol, ftol, cond_max


