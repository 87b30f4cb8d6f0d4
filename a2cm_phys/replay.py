"""``python -m a2cm_phys.replay``: hands over to :mod:`a2cm_phys.commands.replay`."""

import sys

from .commands.replay import main

if __name__ == "__main__":
    sys.exit(main())
