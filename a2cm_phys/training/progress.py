"""The progress of a training run: what a user watches while it trains, on stderr.

On a terminal, a tqdm bar of at most 80 columns over the updates, with the figures that
say how the run is doing (:meth:`Figures.main`: episodes, the mean episode length and the
collisions per episode over the last 100 episodes, and the return over them), and one or
two status lines below it with the rest (:meth:`Figures.detail`: the time left, the
speed, the return's time and collision parts, self-play's evader return and opponent,
exploitability descent's values). Each line is filled with whole figures
(:func:`fit`): a figure that does not fit moves to the next line, none is cut.

Elsewhere (a log file, a pipe, a batch job), plain lines from
:class:`~a2cm_phys.base.progress.Progress`: one at the start, one at least every 30 s
(``A2CM_PROGRESS_SECONDS``) with the updates done, the rate, the time left and every
figure (:meth:`Figures.plain`), one at the end. ``A2CM_PROGRESS=0`` (or the trainer's
``progress=False``, ``--no-progress``) silences both.

The figures are formatted at most twice a second (and, without a terminal, only when a
line is due), so an update pays for a clock read and a comparison.
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass
from typing import TextIO

from tqdm import tqdm

from ..base.progress import BAR_COLUMNS, Progress, progress_enabled
from .state import RunState

RECENT = 100
"""Episodes the figures are averaged over (the most recent)."""

MIN_BAR = 6
"""The narrowest the bar itself may get on the first line, in columns."""

REFRESH_SECONDS = 0.5
"""Seconds between two formattings of the figures on a terminal."""

SEP = "  "
"""Between two figures on a line."""


def number(x: float) -> str:
    """A figure in a few characters: ``-2939``, ``4.20``, ``0.140``, ``-4.53e5``, ``–``
    for NaN."""
    if math.isnan(x):
        return "–"
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e4:
        return f"{x:.0f}" if abs(x) >= 99.995 else f"{x:.2f}" if abs(x) >= 1 else f"{x:.3f}"
    exponent = math.floor(math.log10(abs(x)))
    mantissa = x / 10**exponent
    if round(abs(mantissa), 2) >= 10:  # 9.996e5 rounds to 10.00e5: 1.00e6
        mantissa, exponent = mantissa / 10, exponent + 1
    return f"{mantissa:.2f}e{exponent}"


def fit(parts: list[str], width: int, sep: str = SEP) -> tuple[str, list[str]]:
    """The longest run of ``parts`` from the first that fits in ``width`` columns, joined
    by ``sep``, and the parts left over (in order): nothing is ever cut."""
    line = ""
    for i, part in enumerate(parts):
        longer = f"{line}{sep}{part}" if line else part
        if len(longer) > width:
            return line, parts[i:]
        line = longer
    return line, []


@dataclass(frozen=True)
class Figures:
    """What a run's progress shows, read from its state (:meth:`of`)."""

    episodes: int
    steps: float  # mean episode length, last RECENT episodes
    collisions: float  # collisions per episode, same episodes
    ret: float  # mean return, same episodes
    collision_part: float | None  # the collision penalty's share of ``ret`` (None: no penalty)
    evader_ret: float | None  # a learned evader's mean return
    opponent: str | None  # self-play's pairing
    descent: float | None  # exploitability descent: the pursuers' worst case
    evader_descent: float | None  # and the evader's
    speed: float  # environment steps per second in this session

    @classmethod
    def of(cls, run: RunState, now: float) -> Figures:
        """The figures of ``run`` now (``now``: ``time.perf_counter()``)."""
        s, sc = run.stats, run.scenario
        collisions = s.recent_mean(2, RECENT)
        penalty = sc.rewards.collision if sc.collisions.mode != "off" else 0.0
        descent = run.descent
        return cls(
            episodes=s.episodes,
            steps=s.recent_mean(0, RECENT),
            collisions=collisions,
            ret=s.recent_mean(1, RECENT),
            collision_part=penalty * collisions if penalty else None,
            evader_ret=s.recent_mean(3, RECENT) if run.evader is not None else None,
            opponent=run.pairing.kind if run.pool is not None else None,
            descent=descent.last_value if descent is not None else None,
            evader_descent=descent.last_evader_value if run.evader_descends() else None,
            speed=run.session_speed(now),
        )

    @property
    def time_part(self) -> float:
        """The return without its collision part: steps, capture and walls."""
        return self.ret - (self.collision_part or 0.0)

    def main(self) -> list[str]:
        """The figures of the bar's own line, in the order they are dropped last."""
        return [
            f"ep {self.episodes:,}",
            f"steps {number(self.steps)}",
            f"coll/ep {number(self.collisions)}",
            f"ret {number(self.ret)}",
        ]

    def detail(self) -> list[str]:
        """The figures of the status lines (after the time left and the rate)."""
        parts = [f"{self.speed:,.0f} steps/s"]
        if self.collision_part is not None:
            parts.append(
                f"ret = time {number(self.time_part)} + coll {number(self.collision_part)}"
            )
        if self.evader_ret is not None:
            parts.append(f"evader ret {number(self.evader_ret)}")
        if self.opponent is not None:
            parts.append(f"opp {self.opponent}")
        if self.descent is not None:
            parts.append(f"descent {number(self.descent)}")
        if self.evader_descent is not None:
            parts.append(f"evader descent {number(self.evader_descent)}")
        return parts

    def plain(self) -> str:
        """Every figure, in words, for a plain progress line."""
        words = [
            f"episodes {self.episodes:,}",
            f"mean steps {number(self.steps)} (last {RECENT})",
            f"collisions/episode {number(self.collisions)}",
        ]
        ret = f"return {number(self.ret)}"
        if self.collision_part is not None:
            ret += f" (time {number(self.time_part)}, collisions {number(self.collision_part)})"
        words += [ret, f"{self.speed:,.0f} steps/s"]
        if self.evader_ret is not None:
            words.append(f"evader return {number(self.evader_ret)}")
        if self.opponent is not None:
            words.append(f"opponent {self.opponent}")
        if self.descent is not None:
            words.append(f"descent worst case {number(self.descent)}")
        if self.evader_descent is not None:
            words.append(f"evader descent {number(self.evader_descent)}")
        return ", ".join(words)


BAR_FORMAT = "{percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} {desc}"
"""The first line: the bar, the updates, then the main figures (tqdm's ``desc``)."""


def first_line_room(total: int, columns: int) -> int:
    """Columns left for the figures on the first line of a bar over ``total`` updates."""
    fixed = BAR_FORMAT.format(percentage=100.0, bar="", n_fmt=total, total_fmt=total, desc="")
    return columns - len(fixed) - MIN_BAR


def status_lines(figures: Figures, pace: list[str], columns: int, room: int) -> list[str]:
    """The first line's figures (in ``room`` columns), then the status lines' texts
    (``columns`` wide each), starting with ``pace`` (the time left, the rate)."""
    first, rest = fit(figures.main(), room)
    lines = [first]
    rest = [*pace, *rest, *figures.detail()]
    while rest:
        line, after = fit(rest, columns - 2)
        if not line:  # one figure wider than a line: it goes alone (never happens)
            line, after = rest[0], rest[1:]
        lines.append(f"  {line}")
        rest = after
    return lines


class ProgressBar:
    """The progress of a session (see the module); a no-op without a run. ``tick()`` after
    every update."""

    def __init__(self, run: RunState | None, file: TextIO | None = None) -> None:
        self.run = run if run is not None and progress_enabled() else None
        self.file = file if file is not None else sys.stderr
        self.bar: tqdm | None = None
        self.status: list[tqdm] = []
        self.plain: Progress | None = None
        self.columns = BAR_COLUMNS
        self.room = 0
        self._next = 0.0
        self._started = time.perf_counter()
        self._first = 0

    def __enter__(self) -> ProgressBar:
        t = self.run
        if t is None:
            return self
        self._started, self._first = time.perf_counter(), t.update
        if _is_terminal(self.file):
            self.columns = min(BAR_COLUMNS, _columns(self.file))
            self.room = first_line_room(t.cfg.updates, self.columns)
            self.bar = tqdm(
                total=t.cfg.updates,
                initial=t.update,
                unit="upd",
                file=self.file,
                ncols=self.columns,
                bar_format=BAR_FORMAT,
                position=0,
                leave=True,
            )
            lines = 2 if (t.evader is not None or t.descent is not None) else 1
            self.status = [
                tqdm(file=self.file, bar_format="{desc}", position=i, ncols=self.columns)
                for i in range(1, 1 + lines)
            ]
        else:
            self.plain = Progress(
                "train", t.cfg.updates, "updates", initial=t.update, file=self.file
            )
            self.plain.__enter__()
        return self

    def tick(self) -> None:
        """One update done: advance the count (and show the figures when due)."""
        if self.bar is not None:
            self.bar.update(1)
            now = time.perf_counter()
            if now >= self._next:  # formatting the figures costs ~50 µs
                self._next = now + REFRESH_SECONDS
                self.refresh(now)
        elif self.plain is not None:
            if self.plain.due():
                self.plain.note(Figures.of(self.run, time.perf_counter()).plain())
            self.plain.update(1)

    def refresh(self, now: float) -> None:
        """Write the figures into the bar and the status lines."""
        assert self.bar is not None and self.run is not None
        run = self.run
        rate = (run.update - self._first) / max(now - self._started, 1e-9)
        left = run.cfg.updates - run.update
        pace = [f"{tqdm.format_interval(left / rate) if rate > 0 else '?'} left"]
        pace.append(f"{rate:,.0f} upd/s" if rate >= 10 else f"{rate:.2g} upd/s")
        lines = status_lines(Figures.of(run, now), pace, self.columns, self.room)
        self.bar.set_description_str(lines[0], refresh=False)
        for bar, text in zip(self.status, lines[1:], strict=False):
            bar.set_description_str(text, refresh=True)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.refresh(time.perf_counter())
            self.bar.close()  # a bar left on screen is written where the cursor is: in order
            for bar in self.status:
                bar.close()
        elif self.plain is not None:
            assert self.run is not None
            self.plain.note(Figures.of(self.run, time.perf_counter()).plain())
            if self.run.finished:
                self.plain.__exit__(None, None, None)
            else:  # stopped early: the summary says how; no "done" line
                print(self.plain.summary(), file=self.file, flush=True)


def _is_terminal(file: TextIO) -> bool:
    try:
        return file.isatty()
    except (AttributeError, ValueError):
        return False


def _columns(file: TextIO) -> int:
    try:
        return os.get_terminal_size(file.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return BAR_COLUMNS
