"""Save and load a run's state: checksummed, atomic, with the previous good one kept.

A checkpoint is a plain dict of tensors, numpy arrays and Python scalars (see
:meth:`a2cm_phys.training.trainer.Trainer.checkpoint_state`). On disk it is :data:`MAGIC`, the
SHA-256 of the payload, then the payload (``torch.save`` of the dict), so that a flipped
byte anywhere is caught on load instead of changing a weight. Loading uses
``weights_only=True`` with numpy's array types allowed, so no arbitrary code runs when a
checkpoint is opened. Checkpoints written before the checksum (a bare ``torch.save`` zip)
still load.

:func:`save` replaces ``checkpoint.pt`` atomically and first keeps the one it replaces as
``checkpoint.prev.pt``; :func:`load_latest` falls back to that one when the latest is
damaged or missing.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..record.integrity import SavedCount
from .rundir import CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME, fsync_dir, write_atomic

FORMAT = 1
"""Version of the checkpoint's dict layout, stored under ``"format"``."""

MAGIC = b"A2CMCKPT\x01\n"
"""First bytes of a checksummed checkpoint file."""

DAMAGED_NAME = "checkpoint.damaged.pt"
"""Where :func:`load_latest` moves a damaged latest checkpoint when it falls back."""

REQUIRED = {
    "scenario": dict,
    "train": dict,
    "update": int,
    "learner": dict,
    "rng": dict,
    "stats": dict,
    "wall_time": (int, float),
}
"""Keys every checkpoint holds, with their types (others are checked by their users)."""

__all__ = [
    "CHECKPOINT_NAME",
    "FORMAT",
    "checkpoint_path",
    "load",
    "load_latest",
    "save",
    "saved_counts",
    "write",
]


def checkpoint_path(path: str | Path) -> Path:
    """The checkpoint file of a run directory, or ``path`` itself if it is a file.

    Raises ``FileNotFoundError`` with a readable message when there is none.
    """
    path = Path(path)
    file = path / CHECKPOINT_NAME if path.is_dir() else path
    if not file.is_file():
        raise FileNotFoundError(f"{path}: no checkpoint (expected a run directory or a .pt file)")
    return file


def save(path: str | Path, state: dict[str, Any]) -> None:
    """Write ``state`` to ``path``: a kill or a full disk leaves the old file or the new one
    (and no temp file); the file it replaces is kept as ``checkpoint.prev.pt`` beside it."""
    path = Path(path)
    if path.is_file():
        _keep_previous(path)
    write(path, state)


def write(path: str | Path, state: dict[str, Any]) -> None:
    """Write ``state`` to ``path`` as a checkpoint file, atomically, keeping no previous
    one (a file that is not the run's own checkpoint: a copy cut down for a reader)."""
    buffer = io.BytesIO()
    torch.save({**state, "format": FORMAT}, buffer)
    payload = buffer.getvalue()
    write_atomic(Path(path), MAGIC + hashlib.sha256(payload).digest() + payload)


def _keep_previous(path: Path) -> None:
    """Make ``checkpoint.prev.pt`` the file at ``path``, atomically (a hard link renamed
    into place; a copy where the file system has no hard links)."""
    previous = path.with_name(PREVIOUS_CHECKPOINT_NAME)
    if previous.exists() and os.path.samefile(path, previous):
        return  # a save killed after keeping the previous: it is kept already
    tmp = path.with_name(f".{PREVIOUS_CHECKPOINT_NAME}.tmp")
    tmp.unlink(missing_ok=True)
    try:
        try:
            os.link(path, tmp)
        except OSError:
            shutil.copyfile(path, tmp)
        os.replace(tmp, previous)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def load(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save` (a run directory or the file itself).

    Raises ``ValueError`` naming the file when it is damaged (checksum), unreadable, or not
    a checkpoint of this package (wrong structure); ``FileNotFoundError`` when missing.
    """
    file = checkpoint_path(path)
    try:
        raw = file.read_bytes()
    except OSError as err:
        raise ValueError(f"{file}: cannot be read ({err.strerror or err})") from None
    if raw.startswith(MAGIC):
        digest, payload = raw[len(MAGIC) : len(MAGIC) + 32], raw[len(MAGIC) + 32 :]
        if hashlib.sha256(payload).digest() != digest:
            raise ValueError(f"{file}: damaged checkpoint (its checksum does not match)")
    else:
        payload = raw  # written before checkpoints carried a checksum
    try:
        with torch.serialization.safe_globals(_numpy_globals()):
            state = torch.load(io.BytesIO(payload), map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, ValueError, OSError) as err:
        raise ValueError(f"{file}: not a readable checkpoint ({type(err).__name__})") from None
    _check_structure(file, state)
    return state


def _check_structure(file: Path, state: Any) -> None:
    """A ``ValueError`` naming the file and the key unless ``state`` is laid out as a
    checkpoint of this package."""
    if not isinstance(state, dict):
        raise ValueError(f"{file}: not a checkpoint of a2cm_phys (holds a {type(state).__name__})")
    if state.get("format") != FORMAT:
        raise ValueError(f"{file}: checkpoint format {state.get('format')!r}, expected {FORMAT}")
    for key, kind in REQUIRED.items():
        if key not in state:
            raise ValueError(f"{file}: not a checkpoint of a2cm_phys (no key {key!r})")
        value = state[key]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ValueError(f"{file}: checkpoint key {key!r} holds {value!r:.40}")
    if state["update"] < 0:
        raise ValueError(f"{file}: checkpoint key 'update' is {state['update']}")
    episodes = state["stats"].get("episodes")
    if not isinstance(episodes, int) or isinstance(episodes, bool) or episodes < 0:
        raise ValueError(f"{file}: checkpoint key 'stats.episodes' holds {episodes!r:.40}")


def load_latest(run_dir: str | Path) -> tuple[dict[str, Any], str | None]:
    """The run's latest good checkpoint and a note, or ``(state, None)`` for the latest.

    When ``checkpoint.pt`` is damaged or missing but ``checkpoint.prev.pt`` is good, the
    damaged file is moved to ``checkpoint.damaged.pt`` (so that the next save keeps the good
    one as the previous) and the note says so. Raises like :func:`load` when neither is good.
    """
    run_dir = Path(run_dir)
    latest, previous = run_dir / CHECKPOINT_NAME, run_dir / PREVIOUS_CHECKPOINT_NAME
    try:
        return load(latest), None
    except (ValueError, FileNotFoundError) as err:
        if not previous.is_file():
            raise
        problem = str(err)
    try:
        state = load(previous)
    except ValueError as err:
        raise ValueError(f"{problem}; and {err}") from None
    if latest.exists():
        os.replace(latest, run_dir / DAMAGED_NAME)
    os.replace(previous, latest)  # the good one becomes the latest; no previous for now
    fsync_dir(run_dir)
    note = f"{problem}; falling back to the previous checkpoint (update {state['update']})" + (
        f", the damaged one kept as {DAMAGED_NAME}" if (run_dir / DAMAGED_NAME).exists() else ""
    )
    return state, note


def saved_counts(run_dir: str | Path) -> tuple[list[SavedCount], list[str]]:
    """What each of the run's checkpoints (latest and previous) says of its log, and the
    checkpoints that are damaged (each named), for ``replay --verify``."""
    counts, problems = [], []
    for name in (CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME):
        path = Path(run_dir) / name
        if not path.exists():
            continue
        try:
            state = load(path)
        except ValueError as err:
            problems.append(str(err))
            continue
        log = state.get("log") if isinstance(state.get("log"), dict) else {}
        if log.get("record") is False:
            continue
        episodes = log.get("episodes", state["stats"]["episodes"])
        counts.append(SavedCount(name, int(episodes), log.get("part")))
    return counts, problems


def _numpy_globals() -> list[Any]:
    """What unpickling plain numpy arrays needs (found via numpy itself: version-proof)."""
    reconstruct = np.zeros(1).__reduce__()[0]
    dtypes = {type(np.dtype(t)) for t in (bool, np.int32, np.int64, np.uint64, np.float32, float)}
    return [reconstruct, np.ndarray, np.dtype, *dtypes, bytes]  # bytes(): empty arrays
