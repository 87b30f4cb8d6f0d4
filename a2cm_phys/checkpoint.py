"""Save and load a run's state atomically (``torch.save`` to a temp file, then ``os.replace``).

A checkpoint is a plain dict of tensors, numpy arrays and Python scalars (see
:meth:`a2cm_phys.train.Trainer.checkpoint_state`). Loading uses ``weights_only=True`` with
numpy's array types allowed, so no arbitrary code runs when a checkpoint is opened.
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch

CHECKPOINT_NAME = "checkpoint.pt"
"""File name of the checkpoint inside a run directory."""

FORMAT = 1
"""Version of the checkpoint layout, stored under ``"format"``."""


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
    """Write ``state`` to ``path`` atomically: a crash leaves the old file or the new one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as fh:
        torch.save({**state, "format": FORMAT}, fh)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def load(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint written by :func:`save` (a run directory or the file itself)."""
    file = checkpoint_path(path)
    try:
        with torch.serialization.safe_globals(_numpy_globals()):
            state = torch.load(file, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError) as err:
        raise ValueError(f"{file}: not a readable checkpoint ({type(err).__name__})") from None
    if state.get("format") != FORMAT:
        raise ValueError(f"{file}: checkpoint format {state.get('format')!r}, expected {FORMAT}")
    return state


def _numpy_globals() -> list[Any]:
    """What unpickling plain numpy arrays needs (found via numpy itself: version-proof)."""
    reconstruct = np.zeros(1).__reduce__()[0]
    dtypes = {type(np.dtype(t)) for t in (bool, np.int32, np.int64, np.uint64, np.float32, float)}
    return [reconstruct, np.ndarray, np.dtype, *dtypes, bytes]  # bytes(): empty arrays
