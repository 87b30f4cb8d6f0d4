"""One game over a core: seeding, reset options and action checks shared by the single-game
APIs (the PettingZoo-style parallel env and the Gymnasium joint view)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium.error import ClosedEnvironmentError, ResetNeeded

from ..config import Scenario
from .core import Core, StepOutcome, action_shape, check_actions, check_commands
from .factory import make_core
from .render import render_rgb, render_text
from .sensing import agent_observations


class EnvNotReset(ResetNeeded, RuntimeError):
    """A method that needs an episode was called before ``reset()``."""


class EnvClosed(ClosedEnvironmentError, RuntimeError):
    """A method was called after ``close()``."""


class Game:
    """A single game of ``scenario``: one core with ``B = 1`` plus its seed generator.

    With a learned evader (``evader = "learned"``) each :meth:`step` takes its action too.

    ``reset(seed)`` seeds the generator that draws episode seeds; a later ``reset()``
    without a seed draws the next episode seed from it (unseeded at first use: OS entropy).
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.core: Core = make_core(scenario, 1)
        self.names = scenario.agents
        self._seeds: np.random.Generator | None = None
        self.last: StepOutcome | None = None
        self.started = False  # reset() was called
        self.closed = False

    def check(self, method: str, started: bool = True) -> None:
        """Refuse ``method`` after :meth:`close` (:class:`EnvClosed`) and, if it needs an
        episode, before :meth:`reset` (:class:`EnvNotReset`); both are ``RuntimeError`` and
        Gymnasium's own errors, so each API's users catch what they expect."""
        if self.closed:
            raise EnvClosed(f"{method}() called after close(): this env is closed; make a new one")
        if started and not self.started:
            raise EnvNotReset(f"{method}() called before reset(): call reset() first")

    def close(self) -> None:
        """Refuse everything but ``close()`` from now on."""
        self.closed = True

    def reset(self, seed: int | None = None, options: Mapping[str, Any] | None = None) -> int:
        """Start an episode; returns its episode seed. ``options["positions"]`` places agents;
        ``options`` that is not a dict (or ``None``) is a ``TypeError`` naming it."""
        if options is not None and not isinstance(options, Mapping):
            raise TypeError(
                "reset: options must be a dict (e.g. {'positions': {agent: (x, y)}}) or None,"
                f" got {type(options).__name__} {options!r}"
            )
        if seed is not None or self._seeds is None:
            self._seeds = np.random.default_rng(seed)
        episode_seed = int(self._seeds.integers(0, 2**63))
        options = dict(options or {})
        positions = options.pop("positions", None)
        if options:  # PettingZoo's API test passes an unknown option: warn, don't fail
            warnings.warn(
                f"reset: ignoring unknown option(s) {', '.join(sorted(options))}", stacklevel=3
            )
        if positions is not None and not isinstance(positions, Mapping):
            raise ValueError(
                f"options['positions'] must be a dict agent -> (x, y), got {positions!r}"
            )
        self.core.reset(np.array([0]), np.array([episode_seed], dtype=np.uint64), [positions])
        self.last = None
        self.started = True
        return episode_seed

    def step(
        self, joint_action: np.ndarray, checked: bool = False, evader_action: Any = None
    ) -> StepOutcome:
        """Advance the game with the pursuers' actions ``(N,)``, or with continuous control
        their commands ``(N, 2)``; raises on invalid actions unless the caller has ``checked``
        them already (and passes them as ``(1, N)`` int64, or ``(1, N, 2)`` floats).
        ``evader_action`` (a move, or a ``(vx, vy)`` command) is a learned evader's: required
        then, refused otherwise, always checked (a ``ValueError`` naming ``evader``)."""
        evader = None if evader_action is None else np.asarray(evader_action)[None]
        if not checked and self.scenario.continuous:
            actions = np.asarray(joint_action)
            shape = action_shape(self.scenario)
            if actions.shape != shape:
                raise ValueError(
                    f"expected continuous actions of shape {shape} (one (vx, vy) per pursuer),"
                    f" got {joint_action!r}"
                )
            check_commands(actions[None], self.names)
            self.last = self.core.step(actions[None], evader)
            return self.last
        actions = joint_action if checked else np.asarray(joint_action).reshape(1, -1)
        if not checked:
            if actions.shape[1] != len(self.names) or not np.issubdtype(actions.dtype, np.integer):
                raise ValueError(
                    f"expected {len(self.names)} integer actions (one per pursuer),"
                    f" got {joint_action!r}"
                )
            check_actions(actions, self.scenario.actions, self.names)
        self.last = self.core.step(actions, evader)
        return self.last

    def observation(self) -> np.ndarray:
        """The global observation vector (SPEC §5)."""
        return self.core.observe()[0]

    def observations(self) -> np.ndarray:
        """Every agent's own observation ``(N + 1, obs_dim)`` (pursuers, then the evader) with
        sensing on (SPEC §6b, :func:`~.sensing.agent_observations`)."""
        core = self.core
        return agent_observations(self.scenario, core.observe(), core.positions())[0]

    def info(self) -> dict[str, Any]:
        """Per-step facts for ``infos``: captured, collisions, wall contacts, events, t."""
        last = self.last
        info: dict[str, Any] = {"t": int(self.core.t[0])}
        if last is None:
            return info
        info.update(
            captured=bool(last.captured[0]),
            collisions=int(last.collisions[0]),
            wall_contacts=int(last.wall_contacts[0]),
            evader_action=(
                tuple(last.evader_action[0].tolist())
                if self.scenario.continuous
                else int(last.evader_action[0])
            ),
        )
        if last.events is not None:
            info["events"] = list(last.events[0])
        return info

    def render(self, mode: str | None) -> str | np.ndarray | None:
        """A text picture (``ansi``) or an RGB array (``rgb_array``) of the arena, or ``None``."""
        positions = self.core.positions()[0]
        if mode == "ansi":
            return render_text(self.scenario, positions)
        if mode == "rgb_array":
            velocities = self.core.velocities()
            headings = self.core.headings() if self.scenario.differential else None
            return render_rgb(
                self.scenario,
                positions,
                None if velocities is None else velocities[0],
                headings=None if headings is None else headings[0],
            )
        return None
