"""How a sweep stops: SIGINT and SIGTERM raise :class:`Interrupted` in the sweep's main
thread (:func:`stop_signals`), or are noted and raised at the end of a block that must not
be cut short; the handlers found are put back (:func:`handlers_kept`)."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any


class Interrupted(KeyboardInterrupt):
    """A stop signal (``signum``: SIGINT or SIGTERM) stopped the sweep; running runs have
    saved their checkpoints."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signum)  # the args make it picklable (it may cross from a Ray task)
        self.signum = signum


@dataclass
class Received:
    """The first stop signal :func:`stop_signals` caught (``None``: none yet)."""

    signum: int | None = None

    def behind(self, stop: KeyboardInterrupt) -> int:
        """The signal that raised ``stop``: Ray turns an :class:`Interrupted` raised inside
        ``ray.wait`` into a bare ``KeyboardInterrupt``, so the handler's record counts too."""
        if isinstance(stop, Interrupted):
            return stop.signum
        return self.signum or signal.SIGINT


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""The signals that stop a sweep."""


@contextlib.contextmanager
def stop_signals(wait: str | None = None) -> Iterator[Received]:
    """For the block, SIGINT and SIGTERM raise :class:`Interrupted` (naming the signal) in
    the sweep's main thread; with ``wait`` (a message saying why), they are only noted, and
    the first raises at the end of the block. A trainer running in this process replaces
    the handlers while it runs (it stops after its update, with a checkpoint) and restores
    them. The handlers found are restored at the end, whoever replaced them meanwhile
    (``ray.init`` does)."""
    received = Received()
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def handle(signum: int, frame: Any) -> None:
        received.signum = received.signum or signum
        if wait is None:
            raise Interrupted(signum)
        print(f"{signal.Signals(signum).name}: {wait}, please wait", file=sys.stderr)

    previous = {s: signal.signal(s, handle) for s in STOP_SIGNALS}
    try:
        yield received
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
    if wait is not None and received.signum is not None:
        raise Interrupted(received.signum)


@contextlib.contextmanager
def handlers_kept() -> Iterator[None]:
    """The SIGINT and SIGTERM handlers of the start of the block are back at its end."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
