"""Scripted pursuer policies to measure learned ones against (``evaluate --policy``).

``pursuit``: every pursuer heads straight for the evader at full speed, each on its own,
with no thought for the others: the baseline that cooperation must beat.
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario

UP, DOWN, LEFT, RIGHT, STAY = range(5)


def pursuit_actions(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Every pursuer's action towards the evader, from positions ``(..., N + 1, 2)``
    (pursuers, then the evader; cells or metres, as ``Core.positions`` gives them).

    With continuous control: the unit command ``(..., N, 2)`` float32 pointing at the
    evader (zero on top of it). With discrete moves ``(..., N)`` int64: the axis move that
    most reduces the distance, i.e. along the axis of the larger gap (x on a tie), or
    ``stay`` when on the evader's position if the scenario has it (else ``up``).
    """
    positions = np.asarray(positions, dtype=np.float64)
    gap = positions[..., -1:, :] - positions[..., :-1, :]  # (..., N, 2) to the evader
    if scenario.continuous:
        norm = np.sqrt((gap * gap).sum(-1, keepdims=True))
        unit = np.divide(gap, norm, out=np.zeros_like(gap), where=norm > 0)
        return unit.astype(np.float32)
    dx, dy = gap[..., 0], gap[..., 1]
    horizontal = np.abs(dx) >= np.abs(dy)
    moves = np.where(horizontal, np.where(dx > 0, RIGHT, LEFT), np.where(dy > 0, UP, DOWN))
    there = (dx == 0) & (dy == 0)
    return np.where(there, STAY if scenario.actions == 5 else UP, moves).astype(np.int64)
