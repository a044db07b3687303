"""Strokes by continuation: ``solve`` (the walk, its repair and the public
``solve_stroke``), ``point`` (a guarded predictor and checked Newton steps at one point),
``stages`` (a block of points walked by one scan), ``attachment`` (implicit derivatives
attached to a walked stroke) and ``repair`` (the points the walk left failed).

This face hands on the names of ``solve``, which was the module ``jaxmech.continuation``
(no module of the package bears one of those names: ``stroke`` and ``attach`` are functions).
"""

from .solve import Walked as Walked
from .solve import all_converged as all_converged
from .solve import attach as attach
from .solve import bucket as bucket
from .solve import checked_step as checked_step
from .solve import predict as predict
from .solve import repair_stroke as repair_stroke
from .solve import repair_strokes as repair_strokes
from .solve import repaired_rows as repaired_rows
from .solve import robust_size as robust_size
from .solve import solve_stroke as solve_stroke
from .solve import stroke as stroke
from .solve import take_rows as take_rows
from .solve import walk as walk

__all__ = ["solve_stroke", "stroke", "walk", "attach", "Walked", "repaired_rows", "take_rows", "robust_size",
           "repair_stroke", "repair_strokes", "all_converged", "predict", "bucket", "checked_step"]
