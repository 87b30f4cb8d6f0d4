"""The exit statuses of every ``python -m a2cm_phys.<command>``, defined once.

| status | meaning |
| --- | --- |
| 0 | done |
| 1 | a check failed (``replay --verify`` found a divergence or a gap in the log) |
| 2 | a user's mistake: a bad option, scenario, input file, or a run another process writes |
| 3 | training stopped: the loss became NaN/inf (the last good checkpoint is kept) |
| 4 | training stopped: a physics worker died (the checkpoint holds the last whole update) |
| 5 | no space to write (a full disk or quota): the last good checkpoint is kept, |
|   | consistent with the log; resume once there is room |
| 130 | Ctrl-C (a run saved its checkpoint and can be resumed) |
| 143 | SIGTERM, likewise (``128 + signal``) |
"""

from __future__ import annotations

import errno

EXIT_USAGE = 2
"""A bad command line, scenario or input file, or a run that another process writes."""

EXIT_NONFINITE = 3
"""The loss became NaN/inf (the last good checkpoint is kept)."""

EXIT_WORKER_DIED = 4
"""A physics worker died (the checkpoint holds the last whole update)."""

EXIT_NO_SPACE = 5
"""A write failed for want of space: a fault of the machine, not the user's mistake."""

EXIT_INTERRUPTED = 130
"""Ctrl-C (and, as ``128 + signal``, SIGTERM: 143)."""

OUT_OF_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
"""``OSError`` numbers that mean "no room to write", which give :data:`EXIT_NO_SPACE`."""
