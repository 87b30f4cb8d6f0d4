"""The sensing masks in the run log (SPEC §6b): packed one integer per agent and state.

With ``sensing.radius`` set, each logged state row carries what every agent knows in that
state: :func:`a2cm_phys.envs.sensing.sensed` of the row's positions, ``(N + 1, N + 1)``
bool (agents and bodies: the pursuers in order, then the evader). The log packs each
agent's row into one integer whose bit ``j`` (value ``2**j``) is set when the agent knows
body ``j`` (its own bit always is): ``N + 1`` small integers per state row (0 … 15 with 3
pursuers), exact in any JSON reader up to 52 pursuers. Logs without sensing, and logs
written before the masks were logged, have no such field; their masks can still be
recomputed from the positions (:func:`masks_of`; a trajectory's, logged or recomputed:
:func:`.runlog.trajectory_masks`), since they depend on nothing else.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..config import Scenario
from ..envs.sensing import sensed


def packed(masks: np.ndarray) -> np.ndarray:
    """Masks ``(R, N + 1, N + 1)`` bool as the log holds them: ``(R, N + 1)`` int64, bit
    ``j`` of ``[r, i]`` set when agent ``i`` knows body ``j`` in state ``r``."""
    masks = np.asarray(masks, dtype=bool)
    bits = np.left_shift(np.int64(1), np.arange(masks.shape[-1], dtype=np.int64))
    return (masks.astype(np.int64) * bits).sum(-1)


def unpacked(rows: np.ndarray) -> np.ndarray:
    """The log's integers ``(R, N + 1)`` as masks ``(R, N + 1, N + 1)`` bool."""
    rows = np.asarray(rows, dtype=np.int64)
    bits = np.left_shift(np.int64(1), np.arange(rows.shape[-1], dtype=np.int64))
    return (rows[..., None] & bits) != 0


def masks_of(scenario: Scenario, positions: np.ndarray) -> np.ndarray | None:
    """The masks ``(R, N + 1, N + 1)`` of state rows ``positions`` ``(R, N + 1, 2)``, or
    ``None`` without sensing."""
    if not scenario.sensing.on:
        return None
    return sensed(scenario, np.asarray(positions).reshape(-1, scenario.pursuers + 1, 2))


def in_range(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the pursuers whose own range holds the evader at ``positions``
    ``(N + 1, 2)`` (what each senses itself, shared or not)."""
    alone = dataclasses.replace(scenario.sensing, share=False)
    own = sensed(dataclasses.replace(scenario, sensing=alone), np.asarray(positions)[None])
    return own[0, :-1, -1]
