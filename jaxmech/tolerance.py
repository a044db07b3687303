"""Deprecated: tolerance analysis moved to ``jaxmech.design.tolerance`` (the design layer is
one package).  This module re-exports its names and warns on import."""

import warnings

from .design.tolerance import ToleranceResult as ToleranceResult
from .design.tolerance import analyse as analyse
from .design.tolerance import monte_carlo as monte_carlo

__all__ = ["ToleranceResult", "analyse", "monte_carlo"]

warnings.warn(
    "jaxmech.tolerance moved to jaxmech.design.tolerance; import it from there (the old path will be removed)",
    DeprecationWarning,
    stacklevel=2,
)
