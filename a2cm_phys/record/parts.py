"""A run's log in parts: ``episodes.mcap``, then one ``episodes-from-NNNNNN[-K].mcap`` per
resumed session (``NNNNNN`` the update it resumed from, ``K`` counting sessions that resumed
from the same checkpoint).

A session resumes from the last checkpoint, so the part it writes repeats whatever earlier
parts logged after that checkpoint (a run killed between two checkpoints has logged more
than it saved). Each part records where it starts (metadata ``part``: update, episode id,
step), and :func:`read_run_dir` keeps from each part only what comes before the start of
the next one: every episode and update of the run once, in order, however many times it
was killed and resumed.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from .reader import LogError, RunLog, read_file

FIRST_PART = "episodes.mcap"
"""File name of a run's first log part."""

_PART = re.compile(r"episodes-from-(\d+)(?:-(\d+))?\.mcap")


def _order(path: Path) -> tuple[int, int]:
    if path.name == FIRST_PART:
        return (0, 0)
    match = _PART.fullmatch(path.name)
    assert match is not None
    return (int(match[1]), int(match[2] or 1))


def part_files(run_dir: str | Path) -> list[Path]:
    """The log parts of a run folder, in the order the sessions wrote them."""
    run_dir = Path(run_dir)
    parts = [
        p for p in run_dir.glob("episodes*.mcap") if p.name == FIRST_PART or _PART.fullmatch(p.name)
    ]
    return sorted(parts, key=_order)


def new_part(run_dir: str | Path, update: int) -> Path:
    """The file a session starting at ``update`` logs to (never an existing one)."""
    run_dir = Path(run_dir)
    if not part_files(run_dir):
        return run_dir / FIRST_PART
    k = 1
    while True:
        path = run_dir / f"episodes-from-{update:06d}{'' if k == 1 else f'-{k}'}.mcap"
        if not path.exists():
            return path
        k += 1


def read_run_dir(run_dir: str | Path) -> RunLog:
    """Every part of a run as one :class:`RunLog` (see the module docstring).

    ``parts`` lists the files read; ``clean`` is true if every part was closed cleanly,
    ``damaged``/``error`` describe the first damaged or cut part.
    """
    run_dir = Path(run_dir)
    files = part_files(run_dir)
    if not files:
        raise LogError(f"{run_dir}: no episodes.mcap in this folder")
    logs = [read_file(f) for f in files]
    starts = [_start(lg) for lg in logs]
    merged = logs[0]
    if len(logs) == 1:
        return replace(merged, parts=files)
    # Optional columns (``evader_return``) absent from a part (e.g. one with no episode) are NaN.
    columns: dict[str, list[np.ndarray]] = {k: [] for lg in logs for k in lg.episodes}
    updates, blocks, where = [], [], {}
    for i, lg in enumerate(logs):
        end_episode, end_update = starts[i + 1] if i + 1 < len(logs) else (None, None)
        ids = lg.episodes["episode"]
        keep = np.ones(len(ids), dtype=bool) if end_episode is None else ids < end_episode
        for k in columns:
            columns[k].append(lg.episodes.get(k, np.full(len(ids), np.nan))[keep])
        updates += [u for u in lg.updates if end_update is None or u["update"] <= end_update]
        offset = len(blocks)
        blocks += lg._blocks
        where.update(
            {e: b + offset for e, b in lg._where.items() if end_episode is None or e < end_episode}
        )
    first_bad = next((lg for lg in logs if not lg.clean), None)
    return RunLog(
        path=run_dir / FIRST_PART,
        metadata=merged.metadata,
        episodes={k: np.concatenate(v) for k, v in columns.items()},
        updates=updates,
        clean=first_bad is None,
        error=None if first_bad is None else f"{first_bad.path.name}: {first_bad.error}",
        damaged=any(lg.damaged for lg in logs),
        topic_counts={t: sum(lg.topic_counts.get(t, 0) for lg in logs) for t in _topics(logs)},
        parts=files,
        _blocks=blocks,
        _where=where,
    )


def _start(log: RunLog) -> tuple[int, int]:
    """(first episode id, first update) of a part: from its metadata, else from its data."""
    part = log.metadata.get("part")
    if isinstance(part, dict):
        return int(part["episode"]), int(part["update"])
    ids = log.episodes["episode"]
    first_update = min((u["update"] for u in log.updates), default=1) - 1
    return (int(ids.min()) if len(ids) else 0), first_update


def _topics(logs: list[RunLog]) -> list[str]:
    return sorted({t for lg in logs for t in lg.topic_counts})
