"""Progress of many runs (a sweep's, the report's): how many are done of how many, which
one goes on, and a line at least every ``A2CM_PROGRESS_SECONDS`` even while one run trains
for minutes.

:class:`RunsProgress` is :class:`a2cm_phys.base.progress.Progress` (a tqdm bar on a
terminal, plain lines elsewhere) with a heartbeat: a thread that asks it every second
whether a line is due, because the runs themselves report nothing to it until they end.
"""

from __future__ import annotations

import sys
import threading
from types import TracebackType
from typing import TextIO

from ..base.progress import Progress

HEARTBEAT_SECONDS = 1.0
"""How often the heartbeat asks for a line at most (the line itself comes at the
progress's own interval)."""


BAR_NOTE = 30
"""The longest status the bar shows (a long run name keeps its end: the algorithm, the
preset, the seed), so that the bar stays within 80 columns."""


class RunsProgress:
    """``done/total`` runs and the runs going on, for a loop of runs; a context manager.

    :meth:`started` names a run that begins, :meth:`finished` counts one that ended and
    prints its line (``name: what became of it``) on ``out`` without breaking the bar.
    Safe to call from the thread that waits for the runs while the heartbeat runs.
    """

    def __init__(
        self, desc: str, total: int, *, unit: str = "runs", out: TextIO | None = None
    ) -> None:
        self.progress = Progress(desc, total, unit)
        self.out = out
        self.running: list[str] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> RunsProgress:
        self.progress.__enter__()
        if self.progress.enabled:
            self._thread = threading.Thread(target=self._beat, name="runs-progress", daemon=True)
            self._thread.start()
        return self

    def _beat(self) -> None:
        tick = min(HEARTBEAT_SECONDS, self.progress.interval / 2)
        while not self._stop.wait(tick):
            with self._lock:
                self.progress.update(0)  # a plain line when one is due; the bar's clock

    def started(self, name: str) -> None:
        """``name`` begins."""
        with self._lock:
            self.running.append(name)
            self._note()

    def finished(self, name: str, line: str | None = None) -> None:
        """``name`` ended; ``line`` (if any) is printed on ``out`` (default stdout)."""
        with self._lock:
            if name in self.running:
                self.running.remove(name)
            self._note()
            if line is not None:
                self._print(line)
            self.progress.update(1)

    def _note(self) -> None:
        if not self.running:
            text = ""
        elif len(self.running) == 1:
            text = f"now {self.running[0]}"
        else:
            text = f"{len(self.running)} running"
        bar = self.progress.bar
        if bar is not None and len(text) > BAR_NOTE:  # the bar keeps 80 columns: the name's end
            text = "now …" + self.running[0][-(BAR_NOTE - 5) :]
        self.progress.note(text)
        if bar is not None:
            bar.refresh()

    def _print(self, line: str) -> None:
        out = self.out if self.out is not None else sys.stdout
        if self.progress.bar is not None:
            self.progress.bar.write(line, file=out)
        else:
            print(line, file=out, flush=True)

    def __exit__(
        self,
        kind: type[BaseException] | None,
        err: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.progress.__exit__(kind, err, trace)
