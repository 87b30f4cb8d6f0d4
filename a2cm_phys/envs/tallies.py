"""What a :class:`~.vector.VectorEnv` counts of the episode running in each game
(:class:`EpisodeTallies`), and the summary of a finished one (:class:`EpisodeSummary`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .core import StepOutcome


@dataclass(frozen=True)
class EpisodeSummary:
    """One finished episode of a vector env (``ret``: the pursuers' team return;
    ``evader_ret``: a learned evader's return, ``None`` with a scripted evader)."""

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
        return [
            EpisodeSummary(
                env=int(i),
                seed=int(seeds[i]),
                length=int(lengths[i]),
                ret=float(self.ret[i]),
                captured=bool(out.captured[i]),
                truncated=bool(out.truncated[i]),
                collision_terminated=bool(out.terminated[i] and not out.captured[i]),
                collisions=int(self.collisions[i]),
                wall_contacts=int(self.walls[i]),
                evader_ret=float(self.evader_ret[i]) if learned_evader else None,
            )
            for i in envs
        ]

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
