"""``python -m jaxmech.cli``: the ``jaxmech`` command, as before the command line became a
package (``python -m jaxmech`` is the documented form)."""

import sys

from .commands import main

sys.exit(main())
