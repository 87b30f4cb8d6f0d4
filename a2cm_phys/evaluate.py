"""``python -m a2cm_phys.evaluate``: hands over to :mod:`a2cm_phys.commands.evaluate`."""

import sys

from .commands.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
