"""What a :class:`~.vector.VectorEnv` counts of the episode running in each game
(:class:`EpisodeTallies`), and the summary of a finished one (:class:`EpisodeSummary`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from .core import StepOutcome


class EpisodeSummary(NamedTuple):
    """One finished episode of a vector env (``ret``: the pursuers' team return;
    ``evader_ret``: a learned evader's return, ``None`` with a scripted evader). A named
    tuple: the main job makes some 200,000 of them, and a frozen dataclass's fields cost
    several times as much to set."""

    env: int
    seed: int
    length: int
    ret: float
    captured: bool
    truncated: bool
    collision_terminated: bool
    collisions: int
    wall_contacts: int
    evader_ret: float | None = None


class EpisodeTallies:
    """Running totals of the episode in progress in each of ``num_envs`` games: the
    pursuers' return, a learned evader's return, collisions and wall contacts."""

    def __init__(self, num_envs: int) -> None:
        self.ret = np.zeros(num_envs)
        self.evader_ret = np.zeros(num_envs)
        self.collisions = np.zeros(num_envs, dtype=np.int64)
        self.walls = np.zeros(num_envs, dtype=np.int64)

    def restart(self, envs: np.ndarray) -> None:
        """Zero the totals of games ``envs``, whose new episodes start now."""
        self.ret[envs] = 0.0
        self.evader_ret[envs] = 0.0
        self.collisions[envs] = 0
        self.walls[envs] = 0

    def add(self, out: StepOutcome, evader_rewards: np.ndarray | None) -> None:
        """Count one step of every game (``evader_rewards``: a learned evader's, or ``None``)."""
        self.ret += out.reward
        if evader_rewards is not None:
            self.evader_ret += evader_rewards
        self.collisions += out.collisions
        self.walls += out.wall_contacts

    def summaries(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        lengths: np.ndarray,
        out: StepOutcome,
        learned_evader: bool,
    ) -> list[EpisodeSummary]:
        """The summaries of the episodes that ``out`` ended in games ``envs``, whose episode
        ``seeds`` and ``lengths`` (per game) the caller took before stepping."""
        i = np.asarray(envs, dtype=np.int64)
        if not len(i):
            return []
        captured = np.asarray(out.captured, dtype=bool)[i]
        columns = (  # whole columns to Python numbers at once: the same values as int()/float()
            i.tolist(),
            np.asarray(seeds)[i].tolist(),
            np.asarray(lengths)[i].tolist(),
            self.ret[i].tolist(),
            captured.tolist(),
            np.asarray(out.truncated, dtype=bool)[i].tolist(),
            (np.asarray(out.terminated, dtype=bool)[i] & ~captured).tolist(),
            self.collisions[i].tolist(),
            self.walls[i].tolist(),
            self.evader_ret[i].tolist() if learned_evader else [None] * len(i),
        )
        return [EpisodeSummary._make(row) for row in zip(*columns, strict=True)]

    def state(self) -> dict[str, np.ndarray]:
        """A copy of the totals, under the keys of a vector env's state."""
        return {
            "return": self.ret.copy(),
            "evader_return": self.evader_ret.copy(),
            "collisions": self.collisions.copy(),
            "walls": self.walls.copy(),
        }

    def load_state(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state` returned (an older state without a learned evader's
        return counts it from 0)."""
        self.ret[:] = state["return"]
        self.evader_ret[:] = state.get("evader_return", 0.0)
        self.collisions[:] = state["collisions"]
        self.walls[:] = state["walls"]
