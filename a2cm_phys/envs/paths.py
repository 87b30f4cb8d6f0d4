"""Shortest paths over an arena's free cells: how many cell steps (4-connected, around the
cells obstacles block, :meth:`~a2cm_phys.config.Scenario.blocked_cells`) lead from any cell
to any other (:func:`path_lengths`), and from it a distance around the obstacles between
points of the arena (:func:`around_obstacles`).

Cell ``(x, y)`` is index ``x + size · y`` and spans ``[x, x + 1] × [y, y + 1]`` in physics
(its centre ``(x + 0.5, y + 0.5)``); on a grid an agent's position is its cell.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from ..config import Scenario

STEPS = ((0, 1), (0, -1), (-1, 0), (1, 0))
"""The four cell steps, up, down, left, right (the moves' order)."""


@cache
def neighbours(size: int) -> np.ndarray:
    """Each cell's neighbour in each of :data:`STEPS`, ``(size², 4)`` int64, -1 off the
    arena (read only: it is cached)."""
    y, x = np.divmod(np.arange(size * size), size)
    out = np.full((size * size, 4), -1, dtype=np.int64)
    for k, (dx, dy) in enumerate(STEPS):
        ax, ay = x + dx, y + dy
        inside = (ax >= 0) & (ax < size) & (ay >= 0) & (ay < size)
        out[inside, k] = (ax + size * ay)[inside]
    out.flags.writeable = False
    return out


@cache
def path_lengths(scenario: Scenario) -> np.ndarray:
    """Cell steps ``(size², size²)`` int64 from every cell (row) to every cell (column)
    over the free cells, -1 where no path leads (read only: it is cached per scenario).
    A path may start in a blocked cell (an agent's centre can lie in a cell whose centre an
    obstacle covers, beside a thin wall or in a corner by a disc) but never enters one."""
    n = scenario.size * scenario.size
    free = ~scenario.blocked_cells()
    nb = neighbours(scenario.size)
    far = np.full((n, n), -1, dtype=np.int64)
    for source in range(n):  # breadth-first from each cell
        row = far[source]
        row[source] = 0
        frontier, d = np.array([source]), 0
        while len(frontier):
            d += 1
            nxt = nb[frontier].ravel()
            nxt = np.unique(nxt[nxt >= 0])
            nxt = nxt[free[nxt] & (row[nxt] < 0)]
            row[nxt] = d
            frontier = nxt
    far.flags.writeable = False
    return far


def cells_of(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """The cell index of each position ``(..., 2)`` (cells on a grid, rounded, as
    observations scaled back give them; metres in physics)."""
    top = scenario.size - 1
    xy = np.asarray(positions, dtype=np.float64)
    xy = np.rint(xy) if scenario.mode == "grid" else np.floor(xy)
    xy = np.clip(xy, 0, top).astype(np.int64)
    return xy[..., 0] + scenario.size * xy[..., 1]


def around_obstacles(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Each pursuer's distance to the evader around the obstacles ``(..., N)``, from
    positions ``(..., N + 1, 2)`` (metres; cells on a grid): straight when in the evader's
    cell or next to it, else the least over the pursuer's free neighbouring cells of the
    straight distance to that cell's centre plus its path length to the evader's cell (one
    metre a cell step), and never less than straight; straight too where no path leads (a
    pursuer cut off)."""
    xy = np.asarray(positions, dtype=np.float64)
    pursuers, evader = xy[..., :-1, :], xy[..., -1:, :]
    straight = np.linalg.norm(pursuers - evader, axis=-1)
    far = path_lengths(scenario)
    cells, target = cells_of(scenario, pursuers), cells_of(scenario, evader)
    steps = far[target, cells]  # (..., N): from the evader's cell, which may be blocked
    nb = neighbours(scenario.size)[cells]  # (..., N, 4)
    via = np.where(nb >= 0, far[target[..., None], np.maximum(nb, 0)], -1)
    size = scenario.size
    offset = 0.0 if scenario.mode == "grid" else 0.5
    centres = np.stack([nb % size, nb // size], axis=-1) + offset  # (..., N, 4, 2)
    legs = np.linalg.norm(centres - pursuers[..., None, :], axis=-1) + via
    legs = np.where(via >= 0, legs, np.inf).min(-1)
    return np.where((steps > 1) & np.isfinite(legs), np.maximum(legs, straight), straight)
