"""The paper's grid game (SPEC §2), as a batched numpy core stepping ``B`` games at once.

Positions are cell indices ``x + size · y``; a precomputed table gives the cell each action
leads to (a move off the arena stays put), so one fancy-index moves every agent of every
game. Captures and collisions are whole-array comparisons of the old and new cells.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import combinations

import numpy as np

from ..config import Scenario
from .core import ACTION_DELTAS, StepOutcome, agent_names, default_start, parse_positions
from .evader import evader_actions


class GridRules:
    """Static tables of one arena (moves, wall bumps, coordinates) and the move rule itself.

    Arrays are *agent-major*: ``cells`` is ``(N + 1, B)``, one contiguous row per agent
    (pursuers, then the evader), which keeps every comparison a fast 1-D operation.
    """

    def __init__(self, scenario: Scenario) -> None:
        size, n = scenario.size, scenario.pursuers
        self.size, self.pursuers = size, n
        xy = np.stack(np.meshgrid(np.arange(size), np.arange(size), indexing="xy"), -1)
        self.cell_xy = xy.reshape(-1, 2).astype(np.int64)  # cell -> (x, y)
        target = self.cell_xy[:, None, :] + ACTION_DELTAS[None]  # (C, 5, 2); column 4 = stay
        inside = np.all((target >= 0) & (target < size), axis=-1)
        target = np.where(inside[..., None], target, self.cell_xy[:, None, :])
        # Flat tables indexed by cell * 5 + action.
        self.move = (target[..., 0] + size * target[..., 1]).astype(np.int32).ravel()
        self.blocked = (~inside).astype(np.int32).ravel()
        self.cell_obs = (self.cell_xy / (size - 1)).astype(np.float32)
        self.pairs = list(combinations(range(n), 2))

    def apply(
        self, cells: np.ndarray, pursuer_actions: np.ndarray, evader_action: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One simultaneous move of every agent: ``(new_cells, captured, collisions, walls)``.

        ``cells`` is ``(N + 1, B)``, ``pursuer_actions`` ``(B, N)``, ``evader_action`` ``(B,)``.
        Capture: a pursuer ends on the evader's cell or swaps cells with it. Collision: each
        pursuer pair that ends on one cell or swaps cells counts once. Walls: pursuer moves
        blocked by the border.
        """
        n = self.pursuers
        index = cells * 5
        index[:n] += pursuer_actions.T
        index[n] += evader_action
        new = self.move[index]
        walls = self.blocked[index[:n]].sum(axis=0)
        old_e, new_e = cells[n], new[n]
        captured = np.zeros(cells.shape[1], dtype=bool)
        for i in range(n):
            captured |= (new[i] == new_e) | ((new[i] == old_e) & (cells[i] == new_e))
        collisions = np.zeros(cells.shape[1], dtype=np.int64)
        for i, j in self.pairs:
            collisions += (new[i] == new[j]) | ((new[i] == cells[j]) & (cells[i] == new[j]))
        return new, captured, collisions, walls


class GridCore:
    """``num_envs`` independent grid games of one scenario (implements ``core.Core``)."""

    def __init__(self, scenario: Scenario, num_envs: int = 1) -> None:
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
        mode = scenario.collisions.mode
        self._collision_reward = scenario.rewards.collision if mode != "off" else 0.0
        self._collision_ends = mode == "terminate"

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Mapping[str, Sequence[float]] | None] | None = None,
    ) -> None:
        """Start new episodes in games ``envs``; optional explicit positions per game."""
        self.t[envs] = 0
        self.episode_seed[envs] = seeds
        self.cells[:, envs] = self._start[:, None]
        for env, placed in zip(np.atleast_1d(envs), positions or (), strict=False):
            if placed:
                self.cells[:, env] = self._cells_from(placed)

    def _cells_from(self, placed: Mapping[str, Sequence[float]]) -> np.ndarray:
        xy = parse_positions(self.scenario, placed, 0, self.scenario.size - 1).astype(np.int64)
        names = agent_names(self.scenario)
        for a, b in combinations(range(len(names)), 2):
            if np.array_equal(xy[a], xy[b]):
                raise ValueError(
                    f"positions: {names[a]} and {names[b]} overlap at {tuple(int(v) for v in xy[a])}"
                )
        return xy[:, 0] + self.scenario.size * xy[:, 1]

    def step(self, actions: np.ndarray) -> StepOutcome:
        """Advance every game one step; ``actions`` are the pursuers' ``(B, N)`` actions."""
        sc, n = self.scenario, self.scenario.pursuers
        if sc.evader == "flee":  # only the flee policy looks at positions
            xy = self.rules.cell_xy[self.cells].astype(np.float64)  # (N + 1, B, 2)
            evader_xy, pursuer_xy = xy[n], xy[:n].transpose(1, 0, 2)
        else:
            evader_xy = pursuer_xy = None
        evader = evader_actions(
            sc, self.episode_seed, self.t, evader_xy, pursuer_xy, 0, sc.size - 1
        )
        self.cells, captured, collisions, walls = self.rules.apply(self.cells, actions, evader)
        self.t += 1
        rw = sc.rewards
        reward = rw.step + self._collision_reward * collisions + rw.capture * captured
        if rw.wall:
            reward = reward + rw.wall * walls
        terminated = captured | (self._collision_ends & (collisions > 0))
        truncated = (self.t >= sc.max_steps) & ~terminated
        return StepOutcome(
            reward=reward,
            terminated=terminated,
            truncated=truncated,
            captured=captured,
            collisions=collisions,
            wall_contacts=walls,
            evader_action=evader,
        )

    def observe(self) -> np.ndarray:
        """Global observations ``(B, 2 (N + 1))``: all ``(x, y)`` divided by ``size − 1``."""
        return self.rules.cell_obs[self.cells.T].reshape(self.num_envs, -1)

    def positions(self) -> np.ndarray:
        """Agent cells as ``(B, N + 1, 2)`` integer ``(x, y)``."""
        return self.rules.cell_xy[self.cells.T]

    def velocities(self) -> None:
        """Grid agents have no velocity."""
        return None
