"""``python -m a2cm_phys.plot``: hands over to :mod:`a2cm_phys.commands.plot`."""

import sys

from .commands.plot import main

if __name__ == "__main__":
    sys.exit(main())
