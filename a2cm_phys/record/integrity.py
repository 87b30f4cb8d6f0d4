"""The run log's invariant, checked: every episode exactly once, none lost to a kill.

The trainer makes its log durable up to a checkpoint before it writes that checkpoint, and
a resumed session logs into a part of its own that supersedes what earlier parts logged
from its start on (:mod:`.parts`). So at every moment a run directory must satisfy:

- the log's episode ids are ``0, 1, …, n - 1``: contiguous from 0, each exactly once;
- ``n`` is at least every good checkpoint's episode count (the log may run ahead of a
  checkpoint, never behind it), and the part a checkpoint names exists;
- a finished run's log holds exactly ``summary.json``'s episodes (a stopped run's summary
  counts what it had in memory, which a full disk may have kept from the log: the
  checkpoints bind it);
- a trajectory is logged for exactly the episodes whose summary says ``logged``, once each;
- every part is readable, undamaged, and no part named by a later one is missing.

:func:`check_run_log` lists what breaks it; ``replay --verify`` prints that besides
re-simulating every kept trajectory.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .runlog import RunLog


@dataclass(frozen=True)
class SavedCount:
    """What one checkpoint says of the log: its file name, the episodes it counts (all of
    them durable in the log when it was written) and the log part it was written with."""

    name: str
    episodes: int
    part: str | None = None


def check_run_log(
    log: RunLog,
    saved: Sequence[SavedCount] = (),
    summary: Mapping[str, Any] | None = None,
) -> list[str]:
    """What in ``log`` (with its run's checkpoints and summary) breaks the invariant of the
    module docstring; an empty list when it holds."""
    problems = list(log.problems)
    ids = np.asarray(log.episodes["episode"], dtype=np.int64)
    n = len(ids)
    problems += _id_problems(ids)
    prefix = _contiguous_prefix(ids)
    part_names = {p.name for p in log.parts}
    for count in saved:
        if count.episodes > prefix:
            problems.append(
                f"{count.name} counts {count.episodes:,} episodes, but the log holds ids 0 to"
                f" {prefix - 1:,} without a gap: {count.episodes - prefix:,} lost"
            )
        if count.part is not None and count.part not in part_names:
            problems.append(f"{count.name} was written with log part {count.part}: missing")
    if summary is not None and summary.get("status") == "done":
        want = summary.get("episodes")
        if isinstance(want, int) and n != want:
            problems.append(f"summary.json counts {want:,} episodes; the log holds {n:,}")
    problems += _trajectory_problems(log, ids)
    return problems


def _id_problems(ids: np.ndarray) -> list[str]:
    """Repeated, out-of-order or missing episode ids."""
    out = []
    unique, counts = np.unique(ids, return_counts=True)
    repeated = unique[counts > 1]
    if len(repeated):
        out.append(f"{len(repeated):,} episode ids logged more than once ({_ranges(repeated)})")
    if len(ids) and np.any(np.diff(ids) < 0):
        out.append("episode ids out of order")
    if len(unique):
        missing = np.setdiff1d(np.arange(int(unique[-1]) + 1), unique)
        if len(missing):
            out.append(f"{len(missing):,} episode ids missing ({_ranges(missing)})")
    return out


def _contiguous_prefix(ids: np.ndarray) -> int:
    """How many of the ids ``0, 1, …`` the log holds before the first gap."""
    present = np.zeros(len(ids) + 1, dtype=bool)
    inside = ids[(ids >= 0) & (ids < len(present))]
    present[inside] = True
    return int(np.argmin(present))


def _trajectory_problems(log: RunLog, ids: np.ndarray) -> list[str]:
    """Trajectories missing for episodes whose summary says logged, or logged without one."""
    if "logged" not in log.episodes:
        return []
    flagged = set(ids[np.asarray(log.episodes["logged"], dtype=bool)].tolist())
    present = set(log.logged_episodes)
    out = []
    lost = np.array(sorted(flagged - present), dtype=np.int64)
    if len(lost):
        out.append(f"{len(lost):,} logged episodes have no trajectory ({_ranges(lost)})")
    stray = np.array(sorted(present - set(ids.tolist())), dtype=np.int64)
    if len(stray):
        out.append(f"{len(stray):,} trajectories have no summary ({_ranges(stray)})")
    return out


def _ranges(ids: np.ndarray, limit: int = 4) -> str:
    """``3-7, 12, …`` for sorted ids."""
    ids = np.unique(ids)
    breaks = np.flatnonzero(np.diff(ids) != 1) + 1
    runs = [(int(r[0]), int(r[-1])) for r in np.split(ids, breaks)]
    text = [f"{a:,}" if a == b else f"{a:,}-{b:,}" for a, b in runs[:limit]]
    return ", ".join(text) + (", …" if len(runs) > limit else "")
