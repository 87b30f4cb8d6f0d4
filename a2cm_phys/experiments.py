"""``python -m a2cm_phys.experiments``: hands over to :mod:`a2cm_phys.commands.experiments`."""

import sys

from .commands.experiments import main

if __name__ == "__main__":
    sys.exit(main())
