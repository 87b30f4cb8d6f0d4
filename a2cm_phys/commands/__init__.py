"""One module per command: each parses its options, calls the library below and prints
(``python -m a2cm_phys.COMMAND``, ``python -m a2cm_phys COMMAND`` and the ``a2cm-*``
console scripts all land here). :mod:`.options` holds what every command shares."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

COMMANDS = ("train", "evaluate", "replay", "plot", "oracle", "export", "sweep", "experiments")
"""The commands, in the order a newcomer meets them."""


def run(argv: Sequence[str]) -> int:
    """``python -m a2cm_phys COMMAND …``: run ``COMMAND`` with the rest of ``argv``."""
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        usage = f"usage: python -m a2cm_phys {{{','.join(COMMANDS)}}} [options]"
        if argv and argv[0] not in ("-h", "--help"):
            print(f"error: unknown command {argv[0]!r}\n{usage}", file=sys.stderr)
            return 2
        print(usage)
        return 0 if argv else 2
    return importlib.import_module(f"{__name__}.{argv[0]}").main(argv[1:])
