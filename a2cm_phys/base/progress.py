"""Progress for any loop a user waits on: a tqdm bar on a terminal, plain lines elsewhere.

Every command that can run for more than a few seconds reports through :class:`Progress`:

- on a terminal (stderr is a tty), a tqdm bar at most 80 columns wide;
- otherwise (a log file, a pipe, a batch job), one line when the work starts, one at least
  every :func:`line_interval` seconds with what is done, the rate and the time left, and
  one when it ends, so that nothing is silent for minutes.

Work that ends within :data:`GRACE_SECONDS` shows nothing in either form: a command that
answers at once needs no report of its progress.

``A2CM_PROGRESS_SECONDS`` sets the interval between plain lines (default 30 s);
``A2CM_PROGRESS=0`` silences both forms (``--no-progress`` in ``train`` does the same).
"""

from __future__ import annotations

import os
import sys
import time
from types import TracebackType
from typing import TextIO

from tqdm import tqdm

BAR_COLUMNS = 80
"""The widest a bar may be: a standard terminal."""

GRACE_SECONDS = 5.0
"""Work shorter than this (or than the line interval, if shorter) reports nothing."""

DEFAULT_LINE_SECONDS = 30.0
"""Seconds between plain progress lines, unless ``A2CM_PROGRESS_SECONDS`` says otherwise."""


def line_interval() -> float:
    """Seconds between plain progress lines (``A2CM_PROGRESS_SECONDS``, default 30)."""
    text = os.environ.get("A2CM_PROGRESS_SECONDS", "")
    try:
        value = float(text) if text else DEFAULT_LINE_SECONDS
    except ValueError:
        return DEFAULT_LINE_SECONDS
    return value if value > 0 else DEFAULT_LINE_SECONDS


def progress_enabled() -> bool:
    """False when ``A2CM_PROGRESS=0`` asks for silence."""
    return os.environ.get("A2CM_PROGRESS", "1") != "0"


def duration(seconds: float) -> str:
    """``"45 s"``, ``"3 min 05 s"`` or ``"1 h 02 min"``: a time a person reads at a glance."""
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


class Progress:
    """Progress of one loop of ``total`` ``unit``\\ s (``total=None`` when unknown, as for a
    solver iterating to a tolerance); use as a context manager.

    ``update(n)`` counts work done; ``note(text)`` sets a short status (e.g. the residual)
    shown after the count. ``enabled=False`` (or ``A2CM_PROGRESS=0``) makes it silent.
    ``upper_bound=True`` says the loop may stop before ``total`` (a solver that converges
    early): the time left is then shown as "at most".
    """

    def __init__(
        self,
        desc: str,
        total: int | None = None,
        unit: str = "it",
        *,
        initial: int = 0,
        enabled: bool = True,
        file: TextIO | None = None,
        upper_bound: bool = False,
    ) -> None:
        self.desc = desc
        self.total = total
        self.unit = unit
        self.done = initial
        self.initial = initial
        self.status = ""
        self.upper_bound = upper_bound
        self.file = file if file is not None else sys.stderr
        self.enabled = enabled and progress_enabled()
        self.bar: tqdm | None = None
        self.interval = line_interval()
        self.grace = min(GRACE_SECONDS, self.interval)
        self.started = time.monotonic()
        self.next_line = self.started + self.grace
        self.announced = False

    def __enter__(self) -> Progress:
        if not self.enabled:
            return self
        if _is_terminal(self.file):
            self.bar = tqdm(
                total=self.total,
                initial=self.initial,
                desc=self.desc,
                unit=self.unit,
                file=self.file,
                ncols=min(BAR_COLUMNS, _columns()),
                leave=True,
                delay=self.grace,
            )
        return self

    def update(self, n: int = 1) -> None:
        """``n`` more units done."""
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
        elif self.enabled and time.monotonic() >= self.next_line:
            self._line()

    def due(self) -> bool:
        """Whether the next :meth:`update` prints a plain line (so that a caller formats its
        status only then)."""
        return self.enabled and self.bar is None and time.monotonic() >= self.next_line

    def note(self, status: str) -> None:
        """Show ``status`` (a few words) beside the count from now on."""
        self.status = status
        if self.bar is not None:
            self.bar.set_postfix_str(status, refresh=False)

    def summary(self, done: bool = False) -> str:
        """What is done, the rate and the time left (none once ``done``), in one line."""
        elapsed = time.monotonic() - self.started
        rate = (self.done - self.initial) / elapsed if elapsed > 0 else 0.0
        if self.total:
            count = (
                f"{self.done:,}/{self.total:,} {self.unit} ({100 * self.done / self.total:.0f}%)"
            )
        else:
            count = f"{self.done:,} {self.unit}"
        parts = [count, f"{_rate(rate)} {self.unit}/s", f"{duration(elapsed)} elapsed"]
        if self.total and rate > 0 and self.done < self.total and not done:
            left = duration((self.total - self.done) / rate)
            parts.append(f"at most ~{left} left" if self.upper_bound else f"~{left} left")
        if self.status:
            parts.append(self.status)
        return f"{self.desc}: {'done, ' if done else ''}" + ", ".join(parts)

    def _line(self) -> None:
        if not self.announced:  # the first line, once the grace is over
            self.announced = True
            what = f" ({self.total:,} {self.unit})" if self.total is not None else ""
            self._say(f"{self.desc}: started{what}")
        self._say(self.summary())
        self.next_line = time.monotonic() + self.interval

    def _say(self, text: str) -> None:
        print(text, file=self.file, flush=True)

    def __exit__(
        self,
        kind: type[BaseException] | None,
        err: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if self.bar is not None:
            self.bar.close()
            return
        late = self.announced or time.monotonic() - self.started >= self.grace
        if self.enabled and kind is None and late:
            self._say(self.summary(done=True))


def _is_terminal(file: TextIO) -> bool:
    try:
        return file.isatty()
    except (AttributeError, ValueError):
        return False


def _columns() -> int:
    try:
        return os.get_terminal_size(sys.stderr.fileno()).columns
    except (OSError, ValueError):
        return BAR_COLUMNS


def _rate(rate: float) -> str:
    return f"{rate:,.0f}" if rate >= 10 else f"{rate:.2g}"
