"""``make_env``: the PettingZoo-style parallel API over either core (SPEC §8).

Dicts keyed by agent in, dicts keyed by agent out; the rules live in the core. The class
follows PettingZoo's ``ParallelEnv`` protocol without importing PettingZoo, which is only
needed to run its conformance tests. With a learned evader (SPEC §1b, ``evader =
"learned"``) the evader is the last agent, ``"evader"``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from ..config import Scenario, load_scenario
from .core import evader_reward
from .evaders.learned import EVADER
from .game import Game


def state_space(scenario: Scenario) -> spaces.Box:
    """The global state's space: positions in [0, 1], physics velocities unbounded, the
    headings' ``cos θ, sin θ`` (differential drive) in [-1, 1]."""
    n = scenario.pursuers + 1
    low = np.zeros(scenario.state_dim, dtype=np.float32)
    high = np.ones(scenario.state_dim, dtype=np.float32)
    if scenario.mode == "physics":
        low[2 * n : 4 * n], high[2 * n : 4 * n] = -np.inf, np.inf
        low[4 * n :] = -1.0
    return spaces.Box(low, high, dtype=np.float32)


def observation_space(scenario: Scenario) -> spaces.Box:
    """One agent's observation space: the global state's with sensing off; with sensing
    (SPEC §6b) mask bits and positions in [0, 1], physics velocities unbounded, headings'
    ``cos θ, sin θ`` in [-1, 1]."""
    if not scenario.sensing.on:
        return state_space(scenario)
    low = np.zeros(scenario.obs_dim, dtype=np.float32)
    high = np.ones(scenario.obs_dim, dtype=np.float32)
    if scenario.mode == "physics":  # own (x, y, vx, vy[, cos, sin]), then a mask bit and those
        k = scenario.body_features
        for at in (0, *(k + (1 + k) * j + 1 for j in range(scenario.pursuers))):
            low[at + 2 : at + 4], high[at + 2 : at + 4] = -np.inf, np.inf
            low[at + 4 : at + k] = -1.0
    return spaces.Box(low, high, dtype=np.float32)


def action_space(scenario: Scenario) -> spaces.Discrete | spaces.Box:
    """One agent's actions (a pursuer's, or a learned evader's): ``Discrete(4)`` (up, down,
    left, right), ``Discrete(5)`` with stay, or with continuous control ``Box(-1, 1, (2,))``,
    its velocity command as a fraction of ``max_speed`` (clipped to the unit disc by the
    env)."""
    if scenario.continuous:
        return spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
    return spaces.Discrete(scenario.actions)


class PursuitParallelEnv:
    """The pursuit game for N pursuers, PettingZoo parallel style.

    Every pursuer observes the global state, or with sensing (SPEC §6b) its own masked
    observation, and receives the team reward. The evader is
    scripted, or with ``evader = "learned"`` the agent ``"evader"`` (last in
    ``possible_agents``): it observes the same global state, acts in the pursuers' kind of
    action space, and receives :func:`~.core.evader_reward` (``rewards.evader``: minus the
    team reward by default). ``infos[agent]`` carries ``captured``, ``collisions``,
    ``wall_contacts``, ``evader_action``, ``t`` and, in physics mode, ``events`` (the
    contact events that began in this step).

    As PettingZoo's environments do, it refuses ``step()``, ``render()`` and ``state()``
    before the first ``reset()``, and everything but ``close()`` after ``close()`` (a
    ``RuntimeError`` saying what to call instead).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "a2cm_pursuit_v0",
        "render_modes": ["ansi", "rgb_array"],
        "is_parallelizable": True,
    }

    def __init__(self, scenario: Scenario, render_mode: str | None = "ansi") -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.scenario = scenario
        self.render_mode = render_mode
        self.game = Game(scenario)
        self.learned_evader = scenario.evader == "learned"
        self.possible_agents = [*scenario.agents, *([EVADER] if self.learned_evader else [])]
        self.agents: list[str] = []
        self._observation_space = observation_space(scenario)
        self._action_space = action_space(scenario)
        self.state_space = state_space(scenario)
        self.episode_seed: int | None = None

    def observation_space(self, agent: str) -> spaces.Box:
        """Every agent's observation space (the same for all; see :func:`observation_space`)."""
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Discrete | spaces.Box:
        """Every agent's action space, the evader's too (see :func:`action_space`)."""
        return self._action_space

    def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode; ``options={"positions": {agent: (x, y)}}`` places agents."""
        self.game.check("reset", started=False)
        self.episode_seed = self.game.reset(seed, options)
        self.agents = list(self.possible_agents)
        info = self.game.info()
        return self._observe(self.agents), {a: dict(info) for a in self.agents}

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Move every agent (one action each; a scripted evader moves by itself); see the
        class docstring."""
        self.game.check("step")
        if not self.agents:
            raise RuntimeError("step() called on a finished episode: call reset() first")
        try:
            joint: list[Any] | None = [actions[a] for a in self.agents]
        except KeyError:
            joint = None
        if joint is None or len(joint) != len(actions):  # a missing or an unknown agent
            missing = [a for a in self.agents if a not in actions]
            unknown = [a for a in actions if a not in self.agents]
            raise ValueError(f"actions: missing {missing}, unknown {unknown}")
        joint_array = (
            _commands(joint, self.agents) if self.scenario.continuous else self._moves(joint)
        )
        if self.learned_evader:  # the evader is the last agent
            n = self.scenario.pursuers
            out = self.game.step(joint_array[:, :n], checked=True, evader_action=joint_array[0, n])
        else:
            out = self.game.step(joint_array, checked=True)
        obs = self._observe(self.agents)
        info = self.game.info()
        reward = float(out.reward[0])
        terminated, truncated = bool(out.terminated[0]), bool(out.truncated[0])
        agents = self.agents
        if terminated or truncated:
            self.agents = []
        rewards = dict.fromkeys(agents, reward)
        if self.learned_evader:
            rewards[EVADER] = float(evader_reward(self.scenario, out)[0])
        return (
            obs,
            rewards,
            dict.fromkeys(agents, terminated),
            dict.fromkeys(agents, truncated),
            {a: info.copy() for a in agents},
        )

    def _observe(self, agents: list[str]) -> dict[str, np.ndarray]:
        """Each agent's observation: the global state, or with sensing its own (a scripted
        evader's row is not served)."""
        if not self.scenario.sensing.on:
            return dict.fromkeys(agents, self.game.observation())
        rows = self.game.observations()
        return {a: rows[k] for k, a in enumerate(agents)}

    def _moves(self, joint: list[Any]) -> np.ndarray:
        """The discrete joint action as ``(1, agents)`` int64, or a ``ValueError`` naming the
        agent."""
        n_actions = self.scenario.actions
        for agent, value in zip(self.agents, joint, strict=True):
            if type(value) is int and 0 <= value < n_actions:  # the common case first
                continue
            integer = isinstance(value, np.integer) and not isinstance(value, bool)
            if not integer or not 0 <= value < n_actions:
                raise ValueError(
                    f"invalid action {value!r} for {agent}: expected an integer in [0, {n_actions})"
                )
        return np.array([joint], dtype=np.int64)

    def state(self) -> np.ndarray:
        """The global state: the vector every agent observes with sensing off."""
        self.game.check("state")
        return self.game.observation()

    def render(self) -> str | np.ndarray | None:
        """A text picture (``ansi``) or an RGB array (``rgb_array``) of the arena."""
        self.game.check("render")
        return self.game.render(self.render_mode)

    def close(self) -> None:
        """Release the simulation; the env then refuses everything but ``close()``."""
        self.game.close()
        self.agents = []

    @property
    def unwrapped(self) -> PursuitParallelEnv:
        """The environment itself (there are no wrappers)."""
        return self


def _commands(joint: list[Any], agents: list[str]) -> np.ndarray:
    """The continuous joint action as ``(1, agents, 2)`` float64, or a ``ValueError``
    naming the agent whose value is not two finite numbers (out-of-range ones are
    clipped)."""
    try:
        commands = np.array([joint], dtype=np.float64)
    except (TypeError, ValueError):
        commands = None
    ok = commands is not None and commands.shape == (1, len(joint), 2)
    if ok and np.isfinite(commands).all():  # the common case
        return commands

    def bad(value: Any) -> bool:
        try:
            pair = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            return True
        return pair.shape != (2,) or not np.isfinite(pair).all()

    k = next((k for k, value in enumerate(joint) if bad(value)), 0)
    raise ValueError(
        f"invalid action {joint[k]!r} for {agents[k]}: expected two finite numbers"
        " (a velocity command as a fraction of max_speed)"
    )


def make_env(
    scenario: str | Path | Scenario = "grid", render_mode: str | None = "ansi", **overrides: Any
) -> PursuitParallelEnv:
    """The parallel env of a named or file scenario; keyword overrides are validated like the
    file (``make_env("grid", max_steps=50, **{"rewards.step": -2})``)."""
    return PursuitParallelEnv(load_scenario(scenario, overrides), render_mode=render_mode)
