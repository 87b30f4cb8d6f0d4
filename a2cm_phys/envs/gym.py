"""Gymnasium id ``a2cm_phys/Pursuit-v0``: the joint view of the game (SPEC §8).

One ``MultiDiscrete`` action holds every pursuer's move, or with continuous control one
``Box(-1, 1, (N, 2))`` every pursuer's velocity command; the reward is the team reward.
It serves scripted evaders only: one agent with one reward cannot be both teams of a game
with a learned evader (``evader = "learned"``, SPEC §1b), which is refused with a
:class:`~a2cm_phys.config.ConfigError` naming the key; use ``make_env`` (the evader is an
agent there) or ``VectorEnv``.

With sensing (SPEC §6b) the observation is the pursuers' own observations concatenated in
index order, ``N · obs_dim`` numbers: what the team knows between them, never the state.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from ..config import ConfigError, Scenario, load_scenario
from .game import Game
from .parallel import observation_space, state_space


class PursuitEnv(gym.Env):
    """All pursuers as one agent: ``MultiDiscrete([A] * N)`` or ``Box(-1, 1, (N, 2))``
    actions, the team reward; scripted evaders only (see the module docstring).

    Used directly, without the wrappers of ``gymnasium.make``, it enforces their order
    itself: ``step()`` or ``render()`` before ``reset()`` raises
    ``gymnasium.error.ResetNeeded``, anything but ``close()`` after ``close()``
    ``gymnasium.error.ClosedEnvironmentError``."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}

    def __init__(
        self,
        scenario: str | Path | Scenario = "grid",
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        self.scenario = load_scenario(scenario, overrides)
        if self.scenario.evader == "learned":
            raise ConfigError(
                f"scenario '{self.scenario.name}': key 'evader': the Gymnasium joint view "
                "(a2cm_phys/Pursuit-v0) serves scripted evaders only (random, flee, static), "
                "got 'learned'; use a2cm_phys.make_env, where the evader is an agent"
            )
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self.game = Game(self.scenario)
        self.observation_space = _joint_space(self.scenario)
        n = self.scenario.pursuers
        if self.scenario.continuous:
            self.action_space = gym.spaces.Box(-1.0, 1.0, (n, 2), dtype=np.float32)
        else:
            self.action_space = gym.spaces.MultiDiscrete([self.scenario.actions] * n)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode (``options={"positions": …}`` places agents)."""
        self.game.check("reset", started=False)
        super().reset(seed=seed)
        episode_seed = self.game.reset(seed, options)
        return self._observe(), {**self.game.info(), "episode_seed": episode_seed}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the joint action; returns the team reward."""
        self.game.check("step")
        out = self.game.step(np.asarray(action))
        return (
            self._observe(),
            float(out.reward[0]),
            bool(out.terminated[0]),
            bool(out.truncated[0]),
            self.game.info(),
        )

    def _observe(self) -> np.ndarray:
        """The global state, or with sensing the pursuers' observations concatenated."""
        if not self.scenario.sensing.on:
            return self.game.observation()
        return self.game.observations()[: self.scenario.pursuers].reshape(-1)

    def render(self) -> str | np.ndarray | None:
        """A text picture (``ansi``) or an RGB array (``rgb_array``) of the arena."""
        self.game.check("render")
        return self.game.render(self.render_mode)

    def close(self) -> None:
        """Release the simulation; the env then refuses everything but ``close()``."""
        self.game.close()


def _joint_space(scenario: Scenario) -> gym.spaces.Box:
    """The joint view's observation space: the state's, or with sensing the pursuers'
    observation spaces end to end."""
    if not scenario.sensing.on:
        return state_space(scenario)
    one = observation_space(scenario)
    n = scenario.pursuers
    return gym.spaces.Box(np.tile(one.low, n), np.tile(one.high, n), dtype=np.float32)
