"""``python -m jaxmech``: the ``jaxmech`` command."""

import sys

from .cli.commands import main

sys.exit(main())
