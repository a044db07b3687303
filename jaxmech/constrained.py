"""Deprecated: constrained design moved to ``jaxmech.design.constrained`` (the design layer
is one package).  This module re-exports its names and warns on import."""

import warnings

from .design.constrained import FAIL_VIOLATION as FAIL_VIOLATION
from .design.constrained import ConstrainedResult as ConstrainedResult
from .design.constrained import Program as Program
from .design.constrained import Stated as Stated
from .design.constrained import minimize as minimize
from .design.constrained import program as program

__all__ = ["Stated", "Program", "ConstrainedResult", "program", "minimize", "FAIL_VIOLATION"]

warnings.warn(
    "jaxmech.constrained moved to jaxmech.design.constrained; import it from there "
    "(the old path will be removed)",
    DeprecationWarning,
    stacklevel=2,
)
