"""What an exported team's folder holds and what its ``policy.json`` says, read back
(:func:`read_policy`): the one description of the format, shared by the exporter
(:mod:`a2cm_phys.training.export`) and the runtime (:mod:`.runtime`).

An exported team is a folder: one ONNX model per actor (``pursuer_0.onnx``, …, and
``evader.onnx`` for a learned evader) and ``policy.json`` beside them. Each model takes the
observation its agent receives from the env, as the env gives it (float32, the positions
and velocities already scaled by the env; any one-hot encoding of grid cells happens inside
the graph), and returns its action distribution's parameters: ``logits`` for discrete
control, ``mean`` and ``log_std`` of a diagonal Gaussian for continuous control.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from ..base.errors import UserError

POLICY_FILE = "policy.json"
"""The name of an exported team's description, beside its ONNX models."""

FORMAT = "a2cm_phys.policy/1"
"""``policy.json``'s ``format``: a reader refuses any other."""

INPUT = "observation"
"""Every actor's input tensor: ``(batch, obs_dim)`` float32."""

LOGITS, MEAN, LOG_STD = "logits", "mean", "log_std"
"""The actors' output tensors: ``logits (batch, actions)`` for discrete control;
``mean (batch, 2)`` and ``log_std (batch, 2)`` for continuous control."""

REQUIRED = (
    "format",
    "package_version",
    "run",
    "scenario",
    "observation",
    "actions",
    "greedy",
    "sampling",
    "onnx",
    "actors",
)
"""The keys every ``policy.json`` holds (see :func:`read_policy`)."""

ACTION_MEANINGS = ("up (+y)", "down (-y)", "left (-x)", "right (+x)", "stay")
"""Discrete moves by index (the env's ``ACTION_NAMES``, with their direction)."""


class DeployError(UserError):
    """An exported team that cannot be used: a missing or damaged file, an unknown format,
    an observation of the wrong shape, or onnxruntime not installed."""


def sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_policy(folder: str | Path) -> dict[str, Any]:
    """The ``policy.json`` of an exported team's ``folder``, checked: its format, every key
    of :data:`REQUIRED`, and every actor's file present and unchanged (its SHA-256). A
    :class:`DeployError` naming the file otherwise."""
    folder = Path(folder)
    path = folder / POLICY_FILE
    if not folder.is_dir():
        raise DeployError(
            f"{folder}: not a folder (an exported team is a folder with {POLICY_FILE})"
        )
    try:
        policy = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DeployError(f"{folder}: not an exported team (no {POLICY_FILE})") from None
    except (OSError, ValueError) as err:
        raise DeployError(f"{path}: unreadable ({err})") from None
    if not isinstance(policy, dict) or policy.get("format") != FORMAT:
        found = policy.get("format") if isinstance(policy, dict) else type(policy).__name__
        raise DeployError(f"{path}: format {found!r}, this runtime reads {FORMAT!r}")
    missing = [key for key in REQUIRED if key not in policy]
    if missing:
        raise DeployError(f"{path}: missing {', '.join(missing)}")
    actors = policy["actors"]
    keys = ("agent", "file", "sha256")
    if not isinstance(actors, list) or not actors:
        raise DeployError(f"{path}: 'actors' must list the actors' files")
    for actor in actors:
        if not isinstance(actor, dict) or not all(isinstance(actor.get(k), str) for k in keys):
            raise DeployError(f"{path}: each of 'actors' needs {', '.join(keys)}: {actor!r}")
        if Path(actor["file"]).name != actor["file"]:  # the folder's own files only
            raise DeployError(f"{path}: {actor['file']!r} is not a file name of the folder")
        file = folder / actor["file"]
        if not file.is_file():
            raise DeployError(f"{file}: missing (named by {path})")
        if sha256(file) != actor["sha256"]:
            raise DeployError(f"{file}: changed since export (its SHA-256 differs from {path}'s)")
    return policy
