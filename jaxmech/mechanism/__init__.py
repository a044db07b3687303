"""A mechanism and its structure: ``mechanism`` (named coordinates, parameters and
loop-closure equations), ``structure`` (the equations' block-triangular order) and
``branches`` (the assembly mode of each block).

This face hands on the names of ``mechanism``, which was the module ``jaxmech.mechanism``.
"""

from .mechanism import Mechanism as Mechanism
from .mechanism import Vars as Vars
from .mechanism import cis as cis
from .mechanism import equation_entries as equation_entries

__all__ = ["Mechanism", "cis", "Vars", "equation_entries"]
