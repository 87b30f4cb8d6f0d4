"""The batched environment the trainer steps: ``num_envs`` games with auto-reset.

A finished game is restarted within the same ``step`` call; the step still reports the
finished episode's final observation (``final_obs``, for the truncation bootstrap) and its
summary (in the step's :class:`~.tallies.EpisodeBatch`). Episode seeds come from one
generator seeded at ``reset(seed)``.

With a learned evader (SPEC §1b, ``evader = "learned"``) the evader is a second team of one:
``step(actions, evader_actions)`` takes its actions too (``(B,)`` int64 moves, or ``(B, 2)``
float commands with continuous control), and each step and episode report its reward
(``VecStep.evader_reward``) and return (``EpisodeBatch.evader_ret``) beside the
pursuers'. It observes the same global state as the pursuers (``obs``).

With sensing on (SPEC §6b) ``obs`` rows are the team vectors of
:func:`~.sensing.team_observation` (the state, then each agent's masked observation), of
length ``obs_dim`` (:func:`~.sensing.team_dim`); with sensing off, the global state itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Scenario
from .core import StepOutcome, action_shape, check_joint_actions, evader_reward
from .evaders.learned import evader_action_shape
from .factory import make_core
from .sensing import team_dim, team_observation
from .tallies import EpisodeBatch, EpisodeTallies


@dataclass
class VecStep:
    """The result of one vector step (arrays over the ``B`` games).

    ``obs`` are the observations to act on next (new episodes already started where one
    ended); ``final_obs`` equals ``obs`` except in rows that finished, where it holds the
    last observation of the finished episode. ``positions`` (and ``velocities`` in physics
    mode, and the pursuers' ``headings`` ``(B, N, 2)`` with differential drive) are the
    agents' at the end of this step, before any auto-reset.
    ``reward`` is the pursuers' team reward; ``evader_reward`` a learned evader's (``(B,)``
    float64, see :func:`~.core.evader_reward`), ``None`` with a scripted evader.
    ``episodes`` are the episodes this step finished, in the order of their games.
    """

    obs: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    final_obs: np.ndarray
    outcome: StepOutcome
    positions: np.ndarray
    velocities: np.ndarray | None
    episodes: EpisodeBatch
    evader_reward: np.ndarray | None = None
    headings: np.ndarray | None = None


class VectorEnv:
    """``num_envs`` games of one scenario stepped together, restarted automatically.

    ``learned_evader`` says whether the evader is an agent whose actions each :meth:`step`
    takes (``evader_action_shape`` per game: ``()`` a move in ``[0, n_actions)``, or
    ``(2,)`` a command); see the module docstring."""

    def __init__(self, scenario: Scenario, num_envs: int = 1, workers: int = 1) -> None:
        self.scenario = scenario
        self.num_envs = num_envs
        self.n_agents = scenario.pursuers
        self.n_actions = scenario.actions  # discrete moves (unused with continuous control)
        self.action_shape = action_shape(scenario)  # one game's joint action
        self.learned_evader = scenario.evader == "learned"
        self.evader_action_shape = evader_action_shape(scenario)  # one game's evader action
        self.obs_dim = team_dim(scenario)  # the trainer's input per game
        self._sensing = scenario.sensing.on
        self.core = make_core(scenario, num_envs, workers)
        self._seeds = np.random.default_rng(0)
        self._tallies = EpisodeTallies(num_envs)
        self._no_episodes = EpisodeBatch.empty(self.learned_evader)
        self._closed = False

    def reset(self, seed: int) -> np.ndarray:
        """Seed the episode-seed generator, start every game, return the observations."""
        self._check_open("reset")
        self._seeds = np.random.default_rng(seed)
        envs = np.arange(self.num_envs)
        self._start(envs)
        return self.observe()

    def observe(self) -> np.ndarray:
        """The observations of every game ``(B, obs_dim)``: the global state, or with
        sensing the team vectors (see the module docstring)."""
        obs = self.core.observe()
        if self._sensing:
            obs = team_observation(self.scenario, obs, self.core.positions())
        return obs

    def _start(self, envs: np.ndarray) -> None:
        seeds = self._seeds.integers(0, 2**63, size=len(envs)).astype(np.uint64)
        self.core.reset(envs, seeds)
        self._tallies.restart(envs)

    def state(self) -> dict[str, Any]:
        """A copy of everything that decides the games' future (for checkpoints).

        The core's own state when it has one (grid: exact); otherwise ``None``, and
        :meth:`load_state` restarts every game with fresh episodes (a physics run then
        resumes deterministically, but not exactly as the uninterrupted run would go on).
        """
        core_state = getattr(self.core, "state", None)
        return {
            "core": core_state() if core_state is not None else None,
            "seeds": self._seeds.bit_generator.state,
            **self._tallies.state(),
        }

    def load_state(self, state: Mapping[str, Any]) -> np.ndarray:
        """Restore what :meth:`state` returned; return the observations to act on next."""
        self._check_open("load_state")
        self._seeds = np.random.default_rng()
        self._seeds.bit_generator.state = state["seeds"]
        if state["core"] is not None and hasattr(self.core, "load_state"):
            self.core.load_state(state["core"])
            self._tallies.load_state(state)
        else:
            self._start(np.arange(self.num_envs))
        return self.observe()

    def restart(self, envs: np.ndarray) -> np.ndarray:
        """Abandon the episodes running in games ``envs`` (no summary) and start new ones,
        seeded from the same generator as every start; the observations of every game."""
        self._check_open("restart")
        self._start(np.asarray(envs, dtype=np.int64))
        return self.observe()

    def episode_seeds(self) -> np.ndarray:
        """The episode seed of the episode running in each game."""
        return self.core.episode_seed.copy()

    def step(
        self,
        actions: np.ndarray,
        evader_actions: np.ndarray | None = None,
        validate: bool = True,
    ) -> VecStep:
        """Step every game with pursuer ``actions`` ``(B, N)`` (``(B, N, 2)`` commands with
        continuous control) and a learned evader's ``evader_actions`` ``(B,)`` (``(B, 2)``);
        restart finished games. Invalid pursuer actions (shape, type, range, NaN) are a
        ``ValueError`` naming the expected shape or the agent; ``validate=False`` (the
        trainer's, whose actions come from its own actors) skips those checks; the evader's
        (required with a learned evader, refused otherwise) are always made. After
        :meth:`close` every step is a ``RuntimeError``."""
        if self._closed:
            self._check_open("step")
        if validate:
            actions = check_joint_actions(self.scenario, actions, self.num_envs)
        core = self.core
        seeds, lengths = core.episode_seed.copy(), core.t + 1
        out = core.step(actions, evader_actions)
        evader_rewards = evader_reward(self.scenario, out) if self.learned_evader else None
        self._tallies.add(out, evader_rewards)
        obs = self.observe() if self._sensing else core.observe()
        positions, velocities = core.positions(), core.velocities()
        headings = self._headings()
        done = out.terminated | out.truncated
        episodes = self._no_episodes
        final_obs = obs
        if done.any():
            envs = np.flatnonzero(done)
            episodes = self._tallies.summaries(envs, seeds, lengths, out, self.learned_evader)
            final_obs = obs.copy()
            self._start(envs)
            obs[envs] = (self.observe() if self._sensing else core.observe())[envs]
        return VecStep(
            obs=obs,
            reward=out.reward,
            terminated=out.terminated,
            truncated=out.truncated,
            final_obs=final_obs,
            outcome=out,
            positions=positions,
            velocities=velocities,
            episodes=episodes,
            evader_reward=evader_rewards,
            headings=headings,
        )

    def _headings(self) -> np.ndarray | None:
        """The pursuers' headings ``(B, N, 2)`` with differential drive, else ``None``."""
        return self.core.headings() if self.scenario.differential else None

    def close(self) -> None:
        """Stop worker processes, if any; the env then refuses to step or reset."""
        self._closed = True
        close = getattr(self.core, "close", None)
        if close is not None:
            close()

    def _check_open(self, method: str) -> None:
        """A ``RuntimeError`` if the env was closed."""
        if self._closed:
            raise RuntimeError(
                f"VectorEnv.{method}() called after close(): this env is closed; make a new one"
            )
