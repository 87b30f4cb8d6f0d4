"""A run's log in parts: ``episodes.mcap``, then one ``episodes-KKK-from-UUUUUU.mcap`` per
resumed session (``KKK`` the session, counting from 1; ``UUUUUU`` the update it resumed
from). Runs resumed before sessions were numbered have parts ``episodes-from-UUUUUU[-K].mcap``
instead; they are read in their order (before any numbered part).

A session resumes from the last checkpoint, and the trainer makes the log durable up to a
checkpoint before it writes that checkpoint; so the parts before a session hold every
episode up to its start, and the part it writes repeats whatever they logged after it (a
run killed between two checkpoints has logged more than it saved). Each part records where
it starts (metadata ``part``: session, update, episode id, step, and the parts that existed
before it), and :func:`read_run_dir` keeps from each part only the episodes before the
start of every later part: every episode and update of the run exactly once, in order,
however many times it was killed and resumed, and whichever checkpoint it resumed from.

A part that cannot be read at all (empty, cut before its metadata, overwritten) is skipped
and named in :attr:`RunLog.problems`; it never hides the other parts.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from .reader import read_file
from .runlog import LogError, RunLog

FIRST_PART = "episodes.mcap"
"""File name of a run's first log part."""

_LEGACY = re.compile(r"episodes-from-(\d+)(?:-(\d+))?\.mcap")
_NUMBERED = re.compile(r"episodes-(\d+)-from-(\d+)\.mcap")


def _order(path: Path) -> tuple[int, int, int]:
    if path.name == FIRST_PART:
        return (0, 0, 0)
    legacy = _LEGACY.fullmatch(path.name)
    if legacy is not None:
        return (1, int(legacy[1]), int(legacy[2] or 1))
    numbered = _NUMBERED.fullmatch(path.name)
    assert numbered is not None
    return (2, int(numbered[1]), 0)


def _is_part(path: Path) -> bool:
    name = path.name
    return name == FIRST_PART or bool(_LEGACY.fullmatch(name) or _NUMBERED.fullmatch(name))


def part_files(run_dir: str | Path) -> list[Path]:
    """The log parts of a run folder, in the order the sessions wrote them."""
    return sorted((p for p in Path(run_dir).glob("episodes*.mcap") if _is_part(p)), key=_order)


def new_part(run_dir: str | Path, update: int) -> tuple[Path, int]:
    """``(file, session)`` for a session starting at ``update``: never an existing file,
    and numbered after every existing part."""
    run_dir = Path(run_dir)
    parts = part_files(run_dir)
    if not parts:
        return run_dir / FIRST_PART, 0
    numbered = [_order(p)[1] for p in parts if _order(p)[0] == 2]
    session = max(len(parts), max(numbered, default=0) + 1)
    return run_dir / f"episodes-{session:03d}-from-{update:06d}.mcap", session


def read_run(path: str | Path) -> RunLog:
    """Read a run folder (every part of its log, see the module docstring) or one log file.

    Raises :class:`~.reader.LogError` if the file is missing or is not an MCAP file; a file
    that ends early is read up to its last complete chunk (``clean`` is then ``False``),
    and so is a damaged one (``damaged`` is then ``True`` as well).
    """
    path = Path(path)
    return read_run_dir(path) if path.is_dir() else read_file(path)


def read_run_dir(run_dir: str | Path) -> RunLog:
    """Every part of a run as one :class:`RunLog` (see the module docstring).

    ``parts`` lists the files read; ``clean`` is true if every part was closed cleanly;
    ``error`` describes the first damaged or cut part; ``problems`` names every part that
    could not be read, or was damaged, and every earlier part a later one names that is
    missing.
    """
    run_dir = Path(run_dir)
    files = part_files(run_dir)
    if not files:
        raise LogError(f"{run_dir}: no episodes.mcap in this folder")
    logs, problems = [], []
    for f in files:
        try:
            logs.append(read_file(f))
        except LogError as err:
            problems.append(f"{f.name}: unreadable, skipped ({_reason(err, f)})")
    if not logs:
        raise LogError(f"{run_dir}: no readable log part ({'; '.join(problems)})")
    problems += _missing_parts(logs, {f.name for f in files})
    problems += [f"{lg.path.name}: {lg.error}" for lg in logs if lg.damaged]
    problems += [p for lg in logs for p in lg.problems]
    starts = [_start(lg) for lg in logs]
    if len(logs) == 1:
        return replace(logs[0], path=run_dir / FIRST_PART, parts=files, problems=problems)
    # Optional columns (``evader_return``) absent from a part (e.g. one with no episode) are NaN.
    columns: dict[str, list[np.ndarray]] = {k: [] for lg in logs for k in lg.episodes}
    updates, blocks, where = [], [], {}
    for i, lg in enumerate(logs):
        later = [s for s in starts[i + 1 :] if s is not None]
        end_episode = min((s[0] for s in later), default=None)
        end_update = min((s[1] for s in later), default=None)
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
        metadata=logs[0].metadata,
        episodes={k: np.concatenate(v) for k, v in columns.items()},
        updates=updates,
        clean=first_bad is None and not problems,
        error=None if first_bad is None else f"{first_bad.path.name}: {first_bad.error}",
        damaged=any(lg.damaged for lg in logs),
        topic_counts={t: sum(lg.topic_counts.get(t, 0) for lg in logs) for t in _topics(logs)},
        parts=files,
        problems=problems,
        _blocks=blocks,
        _where=where,
    )


def _reason(err: LogError, path: Path) -> str:
    text = str(err)
    prefix = f"{path}: "
    return text[len(prefix) :] if text.startswith(prefix) else text


def _missing_parts(logs: list[RunLog], present: set[str]) -> list[str]:
    """Parts that a part's metadata names as written before it but that are gone."""
    out = []
    for lg in logs:
        part = lg.metadata.get("part")
        before = part.get("after", []) if isinstance(part, dict) else []
        for name in before:
            if name not in present:
                out.append(f"{name}: missing (named by {lg.path.name} as an earlier part)")
    return sorted(set(out))


def _start(log: RunLog) -> tuple[int, int] | None:
    """(first episode id, first update) of a part: from its metadata, else from its data
    (``None`` for a part that says nothing of where it starts and holds no episode)."""
    part = log.metadata.get("part")
    if isinstance(part, dict):
        return int(part["episode"]), int(part["update"])
    ids = log.episodes["episode"]
    if not len(ids):
        return None
    first_update = min((u["update"] for u in log.updates), default=1) - 1
    return int(ids.min()), first_update


def _topics(logs: list[RunLog]) -> list[str]:
    return sorted({t for lg in logs for t in lg.topic_counts})
