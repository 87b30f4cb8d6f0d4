"""``python -m a2cm_phys.train``: hands over to :mod:`a2cm_phys.commands.train`."""

import sys

from .commands.train import main

if __name__ == "__main__":
    sys.exit(main())
