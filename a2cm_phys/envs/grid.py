"""The paper's grid game (SPEC §2), as a batched numpy core stepping ``B`` games at once.

Positions are cell indices ``x + size · y``; a precomputed table gives the cell each action
leads to (a move off the arena or into a cell an obstacle blocks stays put), so one
fancy-index moves every agent of every game. Captures and collisions are whole-array
comparisons of the old and new cells.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import combinations

import numpy as np

from ..config import Scenario
from .core import (
    ACTION_DELTAS,
    EvaderPolicy,
    StepOutcome,
    agent_names,
    default_start,
    parse_positions,
    settle,
)
from .evaders import make_evader
from .evaders.learned import refuse_evader_actions
from .starts import random_starts


def meet(old_a: np.ndarray, new_a: np.ndarray, old_b: np.ndarray, new_b: np.ndarray) -> np.ndarray:
    """The one contact rule of the grid: two movers end on one cell, or swap cells.

    A pursuer meeting the evader is a capture; two pursuers meeting is a collision.
    """
    return (new_a == new_b) | ((new_a == old_b) & (old_a == new_b))


class GridRules:
    """Static tables of one arena and the move rule itself.

    A *move index* is ``cell * 5 + action`` (action 4 = stay). Tables indexed by it give the
    next cell and whether the move bumps into a wall: the border, or a cell the scenario's
    obstacles block (``blocked_cell``, :meth:`~a2cm_phys.config.Scenario.blocked_cells`).
    No agent ever stands on a blocked cell (starts avoid them, moves into them stay put);
    the tables still give moves *from* one, as if the obstacles were not there, so that a
    solver sweeping every joint state finds each of them a way out. ``meets[i, j]`` tabulates
    :func:`meet` for every pair of moves, so a step is a handful of lookups. Arrays are
    *agent-major*: ``cells`` is ``(N + 1, B)``, one contiguous row per agent (pursuers,
    then the evader).
    """

    MEET_TABLE_LIMIT = 3000
    """Largest number of move indices (``size² · 5``) for which ``meets`` is tabulated."""

    def __init__(self, scenario: Scenario) -> None:
        size, n = scenario.size, scenario.pursuers
        self.size, self.pursuers = size, n
        xy = np.stack(np.meshgrid(np.arange(size), np.arange(size), indexing="xy"), -1)
        self.cell_xy = xy.reshape(-1, 2).astype(np.int64)  # cell -> (x, y)
        self.blocked_cell = scenario.blocked_cells()  # (C,) bool
        target = self.cell_xy[:, None, :] + ACTION_DELTAS[None]  # (C, 5, 2)
        goes = np.all((target >= 0) & (target < size), axis=-1)  # (C, 5): not a wall bump
        if self.blocked_cell.any():  # from a free cell into a blocked one: a bump too
            into = np.where(goes, target[..., 0] + size * target[..., 1], 0)
            goes &= ~(self.blocked_cell[into] & ~self.blocked_cell[:, None])
        target = np.where(goes[..., None], target, self.cell_xy[:, None, :])
        self.move = (target[..., 0] + size * target[..., 1]).astype(np.int32).ravel()
        self.blocked = (~goes).astype(np.int32).ravel()
        self.cell_obs = (self.cell_xy / (size - 1)).astype(np.float32)
        # Rows of the move-index array compared in a step: pursuer pairs, then each
        # pursuer with the evader (row n).
        pairs = list(combinations(range(n), 2)) + [(i, n) for i in range(n)]
        self.n_pairs = len(pairs) - n
        self.left, self.right = (
            np.array(side, dtype=np.int64) for side in zip(*pairs, strict=True)
        )
        moves = len(self.move)
        self.meets: np.ndarray | None = None
        if moves <= self.MEET_TABLE_LIMIT:
            old = np.arange(moves) // 5
            self.meets = meet(old[:, None], self.move[:, None], old[None], self.move[None])

    def _meet(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """:func:`meet` for move indices ``a`` and ``b`` (broadcast), tabulated if small."""
        if self.meets is not None:
            return self.meets[a, b]
        return meet(a // 5, self.move[a], b // 5, self.move[b])

    def apply(
        self, cells: np.ndarray, pursuer_actions: np.ndarray, evader_action: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One simultaneous move of every agent: ``(new_cells, captured, collisions, walls)``.

        ``cells`` is ``(N + 1, B)``, ``pursuer_actions`` ``(B, N)``, ``evader_action`` ``(B,)``.
        Capture: a pursuer meets the evader. Collision: each pursuer pair that meets counts
        once. Walls: pursuer moves blocked by the border or an obstacle.
        """
        n = self.pursuers
        index = np.concatenate((pursuer_actions.T, evader_action[None])) + cells * 5
        # take(): numpy's fancy indexing has several times its fixed cost per call
        met = self._meet(index.take(self.left, 0), index.take(self.right, 0))
        collisions = np.add.reduce(met[: self.n_pairs], axis=0, dtype=np.int64)
        captured = np.logical_or.reduce(met[self.n_pairs :], axis=0)
        walls = np.add.reduce(self.blocked[index[:n]], axis=0, dtype=np.int64)
        return self.move[index], captured, collisions, walls


class GridCore:
    """``num_envs`` independent grid games of one scenario (implements ``core.Core``).

    ``evader`` is the evader's policy (default: the scenario's, see
    :func:`~.evaders.make_evader`; with ``evader = "learned"`` its actions come with each
    :meth:`step`)."""

    def __init__(
        self, scenario: Scenario, num_envs: int = 1, evader: EvaderPolicy | None = None
    ) -> None:
        if scenario.mode != "grid":
            raise ValueError(f"GridCore needs a grid scenario, got mode={scenario.mode!r}")
        self.scenario = scenario
        self.num_envs = num_envs
        self.rules = GridRules(scenario)
        start = default_start(scenario.size, scenario.pursuers)
        self._start = (start[:, 0] + scenario.size * start[:, 1]).astype(np.int32)
        self.cells = np.repeat(self._start[:, None], num_envs, axis=1)  # (N + 1, B)
        self.t = np.zeros(num_envs, dtype=np.int64)
        self.episode_seed = np.zeros(num_envs, dtype=np.uint64)
        self._evader = evader or make_evader(scenario, num_envs, 0, scenario.size - 1)
        self._looks = getattr(self._evader, "needs_positions", True)
        self._give = getattr(self._evader, "give", None)  # a learned evader's mailbox

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Mapping[str, Sequence[float]] | None] | None = None,
    ) -> None:
        """Start new episodes in games ``envs`` at the scenario's start (random starts drawn
        from ``seeds``, :mod:`.starts`); optional explicit positions per game."""
        self.t[envs] = 0
        self.episode_seed[envs] = seeds
        self._evader.restart(envs, self.episode_seed[envs])
        if self.scenario.start.random:
            xy = random_starts(self.scenario, self.episode_seed[envs])  # (K, N + 1, 2)
            self.cells[:, envs] = (xy[..., 0] + self.scenario.size * xy[..., 1]).T
        else:
            self.cells[:, envs] = self._start[:, None]
        for env, placed in zip(np.atleast_1d(envs), positions or (), strict=False):
            if placed:
                self.cells[:, env] = self._cells_from(placed)

    def _cells_from(self, placed: Mapping[str, Sequence[float]]) -> np.ndarray:
        xy = parse_positions(self.scenario, placed, 0, self.scenario.size - 1).astype(np.int64)
        names = agent_names(self.scenario)
        for a, b in combinations(range(len(names)), 2):
            if np.array_equal(xy[a], xy[b]):
                cell = tuple(int(v) for v in xy[a])
                raise ValueError(f"positions: {names[a]} and {names[b]} overlap at {cell}")
        cells = xy[:, 0] + self.scenario.size * xy[:, 1]
        on = np.flatnonzero(self.rules.blocked_cell[cells])
        if len(on):
            cell = tuple(int(v) for v in xy[on[0]])
            raise ValueError(f"positions: {names[on[0]]} on {cell}, a cell an obstacle blocks")
        return cells

    def step(self, actions: np.ndarray, evader_actions: np.ndarray | None = None) -> StepOutcome:
        """Advance every game one step; ``actions`` are the pursuers' ``(B, N)`` actions,
        ``evader_actions`` a learned evader's ``(B,)`` (required then, refused otherwise)."""
        sc, n = self.scenario, self.scenario.pursuers
        if self._give is not None:
            self._give(evader_actions)
        elif evader_actions is not None:
            raise refuse_evader_actions(sc)
        if self._looks:  # of the scripted policies only flee looks at positions
            xy = self.rules.cell_xy[self.cells].astype(np.float64)  # (N + 1, B, 2)
            evader_xy, pursuer_xy = xy[n], xy[:n].transpose(1, 0, 2)
        else:
            evader_xy = pursuer_xy = None
        evader = self._evader.moves(self.episode_seed, self.t, evader_xy, pursuer_xy)
        self.cells, captured, collisions, walls = self.rules.apply(self.cells, actions, evader)
        self.t += 1
        return settle(sc, self.t, captured, collisions, walls, evader)

    def observe(self) -> np.ndarray:
        """Global observations ``(B, 2 (N + 1))``: all ``(x, y)`` divided by ``size − 1``."""
        return self.rules.cell_obs[self.cells.T].reshape(self.num_envs, -1)

    def positions(self) -> np.ndarray:
        """Agent cells as ``(B, N + 1, 2)`` integer ``(x, y)``."""
        return self.rules.cell_xy[self.cells.T]

    def velocities(self) -> None:
        """Grid agents have no velocity."""
        return None

    def state(self) -> dict[str, np.ndarray]:
        """Copies of the arrays that define every running game (for checkpoints).

        The evader's randomness is a function of ``episode_seed`` and ``t``, so these three
        arrays continue every game exactly.
        """
        return {
            "cells": self.cells.copy(),
            "t": self.t.copy(),
            "episode_seed": self.episode_seed.copy(),
        }

    def load_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore what :meth:`state` returned (same scenario and ``num_envs``)."""
        cells = np.asarray(state["cells"], dtype=self.cells.dtype)
        if cells.shape != self.cells.shape:
            raise ValueError(f"state: cells of shape {cells.shape}, expected {self.cells.shape}")
        self.cells = cells.copy()
        self.t = np.asarray(state["t"], dtype=np.int64).copy()
        self.episode_seed = np.asarray(state["episode_seed"], dtype=np.uint64).copy()
        self._evader.forget()
