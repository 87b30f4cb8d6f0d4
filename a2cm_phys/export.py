"""``python -m a2cm_phys.export``: hands over to :mod:`a2cm_phys.commands.export`."""

import sys

from .commands.export import main

if __name__ == "__main__":
    sys.exit(main())
