"""``python -m a2cm_phys COMMAND …``: the commands of :mod:`a2cm_phys.commands`."""

import sys

from .commands import run

if __name__ == "__main__":
    sys.exit(run(sys.argv[1:]))
