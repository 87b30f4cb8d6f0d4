"""How a run stops: the first Ctrl-C or SIGTERM asks for a stop at the end of the update, a
second one stops at once but never in the middle of a log write or a checkpoint
(:class:`StopSignals`, :class:`ShieldedLog`); while the run saves, signals are only
acknowledged."""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""Signals that stop a run cleanly: Ctrl-C, and what ``timeout``, Slurm and Ray send."""


class StopSignals:
    """What the stop signals asked: the first one requests a stop at the end of the update,
    the second stops at once (raises ``KeyboardInterrupt``, but only between log writes);
    after :meth:`shield`, while the run is being saved, signals are only acknowledged."""

    def __init__(self) -> None:
        self.stop_requested = False
        self.received: int | None = None  # the first stop signal
        self.in_log = False  # a log write is under way: an interrupt waits for its end
        self.interrupt_pending = False
        self.shielded = False

    def handle(self, signum: int, frame: Any) -> None:
        name = signal.Signals(signum).name
        if self.shielded:
            print(f"\n{name}: saving the checkpoint and closing the log, please wait",
                  file=sys.stderr)  # fmt: skip
            return
        if not self.stop_requested:
            self.stop_requested, self.received = True, signum
            print(f"\n{name}: stopping after this update (again: at once)", file=sys.stderr)
            return
        if self.in_log:
            self.interrupt_pending = True
            return
        raise KeyboardInterrupt

    def shield(self) -> None:
        """From now on, signals do not interrupt."""
        self.shielded = True

    def after_log(self) -> None:
        """End of a log write: raise the interrupt that waited for it, if any."""
        self.in_log = False
        if self.interrupt_pending and not self.shielded:
            self.interrupt_pending = False
            raise KeyboardInterrupt


class ShieldedLog:
    """The recorder's per-step and per-update calls, never cut in the middle by a signal."""

    def __init__(self, recorder: Any, signals: StopSignals) -> None:
        self.recorder, self.signals = recorder, signals

    def record_step(self, *args: Any) -> None:
        self.signals.in_log = True
        self.recorder.record_step(*args)
        self.signals.after_log()

    def record_update(self, update: int, metrics: dict[str, Any]) -> None:
        self.signals.in_log = True
        self.recorder.record_update(update, metrics)
        self.signals.after_log()


@contextmanager
def signals_deferred() -> Iterator[StopSignals]:
    """SIGINT and SIGTERM handled by a :class:`StopSignals` for the time of the block (in
    the main thread; elsewhere the signals are left as they are)."""
    signals = StopSignals()
    if threading.current_thread() is not threading.main_thread():
        yield signals
        return
    previous = {s: signal.signal(s, signals.handle) for s in STOP_SIGNALS}
    try:
        yield signals
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
