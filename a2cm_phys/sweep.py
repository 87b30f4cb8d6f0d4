"""``python -m a2cm_phys.sweep``: hands over to :mod:`a2cm_phys.commands.sweep`."""

import sys

from .commands.sweep import main

if __name__ == "__main__":
    sys.exit(main())
