"""``python -m a2cm_phys.oracle``: hands over to :mod:`a2cm_phys.commands.oracle`."""

import sys

from .commands.oracle import main

if __name__ == "__main__":
    sys.exit(main())
