"""Scripted pursuer policies to measure learned ones against (``evaluate --policy``).

``pursuit``: every pursuer heads straight for the evader at full speed, each on its own,
with no thought for the others: the baseline that cooperation must beat. A
differential-drive pursuer (continuous control) turns towards the evader and drives once
facing it (:func:`steer`); with discrete moves the move primitives turn it themselves.
Around obstacles it heads instead for the next cell on a shortest path over the free
cells to the evader's cell (:func:`detour_targets`: breadth-first over the grid of cells,
4-connected), and straight for the evader once in its cell or next to it.
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario
from ..envs.paths import cells_of, neighbours, path_lengths

UP, DOWN, LEFT, RIGHT, STAY = range(5)


def pursuit_actions(
    scenario: Scenario, positions: np.ndarray, headings: np.ndarray | None = None
) -> np.ndarray:
    """Every pursuer's action towards the evader, from positions ``(..., N + 1, 2)``
    (pursuers, then the evader; cells or metres, as ``Core.positions`` gives them), and
    with differential drive the pursuers' ``headings`` ``(..., N, 2)`` (``(cos θ, sin θ)``,
    as ``Core.headings`` gives them; needed with continuous control).

    With continuous control: the unit command ``(..., N, 2)`` float32 pointing at the
    evader (zero on top of it), or with differential drive the ``(forward, turn)`` command
    that steers towards it (:func:`steer`). With discrete moves ``(..., N)`` int64: the
    axis move that most reduces the distance, i.e. along the axis of the larger gap (x on
    a tie), or ``stay`` when on the evader's position if the scenario has it (else ``up``).
    With obstacles each pursuer heads for :func:`detour_targets` instead of the evader.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if not scenario.obstacles:
        return _towards(scenario, positions[..., -1:, :] - positions[..., :-1, :], headings)
    games = positions.reshape(-1, *positions.shape[-2:])
    targets = detour_targets(scenario, games).reshape(*positions.shape[:-2], -1, 2)
    return _towards(scenario, targets - positions[..., :-1, :], headings)


def _towards(scenario: Scenario, gap: np.ndarray, headings: np.ndarray | None) -> np.ndarray:
    """The actions of :func:`pursuit_actions` for the gaps ``(..., N, 2)`` from each
    pursuer to where it heads."""
    if scenario.continuous:
        norm = np.sqrt((gap * gap).sum(-1, keepdims=True))
        unit = np.divide(gap, norm, out=np.zeros_like(gap), where=norm > 0)
        if scenario.differential:
            if headings is None:
                raise ValueError("pursuit with differential drive needs the pursuers' headings")
            return steer(scenario, unit, headings)
        return unit.astype(np.float32)
    dx, dy = gap[..., 0], gap[..., 1]
    horizontal = np.abs(dx) >= np.abs(dy)
    moves = np.where(horizontal, np.where(dx > 0, RIGHT, LEFT), np.where(dy > 0, UP, DOWN))
    there = (dx == 0) & (dy == 0)
    return np.where(there, STAY if scenario.actions == 5 else UP, moves).astype(np.int64)


def steer(scenario: Scenario, direction: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """The differential-drive commands ``(..., N, 2)`` float32 ``(forward, turn)`` that take
    pursuers at ``headings`` ``(..., N, 2)`` (``(cos θ, sin θ)``) along ``direction``
    ``(..., N, 2)`` (unit vectors, or zero: stop): the turn closes the angle error ``e``
    within one control period where the turn rate allows (``e / (max_turn_rate · dt)``,
    clipped to ``[-1, 1]``), and the forward command is ``max(cos e, 0)``, full speed when
    facing the way, none while facing more than 90° off it."""
    direction = np.asarray(direction, dtype=np.float64)
    headings = np.asarray(headings, dtype=np.float64)
    cos = (headings * direction).sum(-1)
    sin = headings[..., 0] * direction[..., 1] - headings[..., 1] * direction[..., 0]
    error = np.arctan2(sin, cos)  # 0 where direction is zero
    ph = scenario.physics
    turn = np.clip(error / (ph.max_turn_rate * ph.dt), -1.0, 1.0)
    forward = np.maximum(cos, 0.0)  # |direction| scales it: zero stops
    return np.stack((forward, turn), axis=-1).astype(np.float32)


def detour_targets(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Where each pursuer heads ``(B, N, 2)`` (cells or metres, as ``positions`` ``(B, N +
    1, 2)``): the next cell (its centre, in physics) on a shortest path over the free cells
    (:func:`~a2cm_phys.envs.paths.path_lengths`) to the evader's cell, the first of up,
    down, left, right on a tie; the evader itself once in its cell or next to it, or where
    no path leads there."""
    positions = np.asarray(positions, dtype=np.float64)
    far = path_lengths(scenario)
    cells = cells_of(scenario, positions)
    pursuers, evader = cells[:, :-1], cells[:, -1:]
    nb = neighbours(scenario.size)[pursuers]  # (B, N, 4)
    via = np.where(nb >= 0, far[evader[..., None], np.maximum(nb, 0)], -1)
    best = np.take_along_axis(
        nb, np.where(via >= 0, via, np.iinfo(np.int64).max).argmin(-1)[..., None], -1
    )[..., 0]
    centre = 0.0 if scenario.mode == "grid" else 0.5
    ahead = np.stack([best % scenario.size, best // scenario.size], axis=-1) + centre
    straight = far[evader, pursuers] <= 1  # by the evader, or cut off from it
    return np.where(straight[..., None], positions[:, -1:], ahead)
