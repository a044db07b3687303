"""``python -m jaxmech``: the ``jaxmech`` command."""

import sys

from .cli import main

sys.exit(main())
