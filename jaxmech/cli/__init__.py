"""The ``jaxmech`` command: ``commands`` (its subcommands and ``main``), ``parser`` (the
argument parser), ``values`` (reading and checking what the user typed) and ``simulate``
(``jaxmech simulate``, forward dynamics of a linkage file).

This face hands on the names of ``commands``, which was the module ``jaxmech.cli``.
"""

from .commands import is_linkage_file as is_linkage_file
from .commands import main as main
from .commands import mistakes_of as mistakes_of
from .commands import write_csv as write_csv

__all__ = ["main", "is_linkage_file", "mistakes_of", "write_csv"]
