"""The module paths of the library before its modules went into packages (``jaxmech.positions``
is ``jaxmech.solver.positions``): one release more, ``import jaxmech.positions`` and ``from
jaxmech.positions import solve`` give the module at its new path, with a DeprecationWarning
naming that path.

One finder on ``sys.meta_path`` answers for the old names alone; the module it hands out is
the one at the new path (the same object: ``sys.modules`` holds it under both names).  The
old ``jaxmech.continuation``, ``jaxmech.mechanism``, ``jaxmech.export`` and ``jaxmech.cli``
are packages now, whose faces hand on the old modules' names.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings

#: Old dotted module name -> new one.
MOVED = {
    "jaxmech.options": "jaxmech.solver.options",
    "jaxmech.status": "jaxmech.solver.status",
    "jaxmech.solution": "jaxmech.solver.solution",
    "jaxmech.newton": "jaxmech.solver.newton",
    "jaxmech.implicit": "jaxmech.solver.implicit",
    "jaxmech.positions": "jaxmech.solver.positions",
    "jaxmech.linalg": "jaxmech.solver.linalg",
    "jaxmech.inputs": "jaxmech.solver.inputs",
    "jaxmech.stroke_point": "jaxmech.continuation.point",
    "jaxmech.stroke_stages": "jaxmech.continuation.stages",
    "jaxmech.stroke_attach": "jaxmech.continuation.attachment",
    "jaxmech.stroke_repair": "jaxmech.continuation.repair",
    "jaxmech.structure": "jaxmech.mechanism.structure",
    "jaxmech.branches": "jaxmech.mechanism.branches",
    "jaxmech.plot": "jaxmech.viz.plot",
    "jaxmech.drawing": "jaxmech.viz.drawing",
    "jaxmech.live": "jaxmech.viz.live",
    "jaxmech.cad": "jaxmech.export.cad",
    "jaxmech.cli_parser": "jaxmech.cli.parser",
    "jaxmech.cli_simulate": "jaxmech.cli.simulate",
    "jaxmech.cli_values": "jaxmech.cli.values",
    "jaxmech.xla": "jaxmech.solver.xla",
    "jaxmech.stored": "jaxmech._compile.stored",
    "jaxmech.cache": "jaxmech._compile.cache",
}


class _Moved(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old module name of ``MOVED``; loading it imports the new module, warns, and
    puts the new module in ``sys.modules`` under the old name too."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):
        return None  # a placeholder; exec_module puts the real module in its place

    def exec_module(self, module):
        new = MOVED[module.__name__]
        warnings.warn(f"{module.__name__} moved to {new}; import it from there (the old path will be removed)",
                      DeprecationWarning, stacklevel=2)
        # the import system returns what sys.modules holds under the old name once this returns
        sys.modules[module.__name__] = importlib.import_module(new)


def install() -> None:
    """Put the finder on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Moved) for f in sys.meta_path):
        sys.meta_path.append(_Moved())
