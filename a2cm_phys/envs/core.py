"""What every simulation core (grid, physics) shares: the step outcome and start positions.

A *core* steps a batch of ``B`` independent games; the parallel, Gymnasium and vector APIs
are thin layers over it. Each core implements :class:`Core`: ``reset(envs, seeds,
positions)`` (re)starts some of its games, ``step(actions)`` advances all of them and
returns a :class:`StepOutcome`, ``observe()`` gives the global observations.

Each game carries its own *episode seed*: every random number of an episode (the evader's
moves) is a pure function of that seed and the step counter (see :mod:`.evader`), so an
episode can be re-simulated from its seed and the pursuers' actions alone, whatever batch
it was played in.

The evader is a policy injected into the core (:class:`EvaderPolicy`): each step the core
asks it for every game's command and plays it by the mode's rules, written once. A learned
evader (SPEC §1b) is the policy :class:`~.evaders.learned.LearnedEvader`, which plays the
actions given with the step: ``step(actions, evader_actions)``. Pursuer actions are
``(B, N)`` integer moves, or with continuous control (SPEC §3b) ``(B, N, 2)`` float velocity
commands as fractions of ``max_speed``, which the core clips to the unit disc; the
evader's are ``(B,)`` moves or ``(B, 2)`` commands.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..config import CollisionMode, Rewards, Scenario, default_start

ACTION_NAMES = ("up", "down", "left", "right", "stay")
"""Discrete actions (SPEC §1): 0 up (+y), 1 down (−y), 2 left (−x), 3 right (+x), 4 stay."""

ACTION_DELTAS = np.array([(0, 1), (0, -1), (-1, 0), (1, 0), (0, 0)], dtype=np.int64)
"""Unit displacement ``(dx, dy)`` of each action, indexed by action."""


@dataclass
class StepOutcome:
    """What happened in one step of every game of a batch (arrays of length ``B``).

    ``events`` is, in physics mode, one list per game of contact events
    ``(kind, a, b, step)`` that began in this step; in grid mode it is ``None``.
    """

    reward: np.ndarray  # float64, raw team reward
    terminated: np.ndarray  # bool: capture, or a collision in "terminate" mode
    truncated: np.ndarray  # bool: reached max_steps without termination
    captured: np.ndarray  # bool
    collisions: np.ndarray  # int64: pursuer pairs that collided in this step
    wall_contacts: np.ndarray  # int64: pursuer moves or contacts against a wall
    evader_action: np.ndarray  # the evader's command, for logs and replays: int64 (B,)
    # moves, or with continuous control float64 (B, 2) velocities as fractions of max_speed
    events: list[list[tuple[str, str, str, int]]] | None = None
    # int64: the wall contacts that were with an obstacle (physics; None without obstacles)
    obstacle_contacts: np.ndarray | None = None


def team_reward(
    rewards: Rewards, mode: CollisionMode, captured, collisions, wall_contacts, obstacles=0
):
    """The team reward of a step (SPEC §4), for scalars or arrays alike.

    ``step + collision × collisions + capture × captured + wall × wall_contacts + obstacle
    × obstacles``, where collisions cost nothing in ``off`` mode and ``obstacles`` counts
    the wall contacts that were with an obstacle (so an obstacle costs ``wall + obstacle``).
    Zero-weight terms are skipped (a scalar may come back when every weight but ``step``
    is zero).
    """
    reward = rewards.step
    for weight, count in (
        (rewards.collision if mode != "off" else 0.0, collisions),
        (rewards.capture, captured),
        (rewards.wall, wall_contacts),
        (rewards.obstacle, obstacles),
    ):
        if weight:
            reward = reward + weight * count
    return reward


def evader_reward(scenario: Scenario, outcome: StepOutcome) -> np.ndarray:
    """A learned evader's reward in every game of a step, ``(B,)`` float64 (SPEC §1b):
    minus the team reward (``rewards.evader = "zero_sum"``), or 1 for each step that does
    not end in its capture (``"survival"``)."""
    if scenario.rewards.evader == "survival":
        return (~outcome.captured).astype(np.float64)
    return -outcome.reward


def ends_episode(mode: CollisionMode, captured, collisions):
    """Termination (SPEC §4): capture, or any collision in ``terminate`` mode."""
    return captured | (collisions > 0) if mode == "terminate" else captured


def settle(
    scenario: Scenario,
    t: np.ndarray,
    captured: np.ndarray,
    collisions: np.ndarray,
    wall_contacts: np.ndarray,
    evader_action: np.ndarray,
    events: list[list[tuple[str, str, str, int]]] | None = None,
    obstacle_contacts: np.ndarray | None = None,
) -> StepOutcome:
    """Team reward, termination and truncation from a step's counts (SPEC §4), both modes.

    ``t`` is the step counter after the step. In ``off`` mode collisions are counted but
    neither penalised nor terminal; in ``terminate`` mode any collision ends the episode.
    ``obstacle_contacts`` are the wall contacts that were with an obstacle.
    """
    mode = scenario.collisions.mode
    obstacles = 0 if obstacle_contacts is None else obstacle_contacts
    reward = team_reward(scenario.rewards, mode, captured, collisions, wall_contacts, obstacles)
    terminated = ends_episode(mode, captured, collisions)
    truncated = np.greater(t >= scenario.max_steps, terminated)  # at the limit and not ended
    if not isinstance(reward, np.ndarray):  # only the step reward: one number for all games
        reward, scalar = np.empty(len(t)), reward
        reward.fill(scalar)
    return StepOutcome(
        reward=reward,
        terminated=terminated,
        truncated=truncated,
        captured=captured,
        collisions=collisions,
        wall_contacts=wall_contacts,
        evader_action=evader_action,
        events=events,
        obstacle_contacts=obstacle_contacts,
    )


class EvaderPolicy(Protocol):
    """The evader of a batch of games, as a core plays it (scripted: :mod:`.evader`,
    :mod:`.evaders.continuous`). A core owns the seed and step arrays it passes in; it calls
    :meth:`restart` for the games it resets and :meth:`forget` when it changes those arrays
    in any other way (loading a state). ``needs_positions`` says whether :meth:`moves`
    reads the positions (a core may pass ``None`` otherwise). A policy with a method
    ``give(evader_actions)`` takes its actions from outside (a learned evader): the core
    gives it the actions passed with each step, before asking for its moves."""

    needs_positions: bool

    def restart(self, envs: np.ndarray, seeds: np.ndarray) -> None:
        """Games ``envs`` start new episodes (``t = 0``) with episode ``seeds``."""

    def forget(self) -> None:
        """Drop anything computed ahead from the seed and step arrays."""

    def moves(
        self,
        seed: np.ndarray,
        t: np.ndarray,
        evader_xy: np.ndarray | None,
        pursuer_xy: np.ndarray | None,
    ) -> np.ndarray:
        """The evader's command in every game at steps ``t`` (the games' episode ``seed``,
        the evader's ``(B, 2)`` and the pursuers' ``(B, N, 2)`` positions): ``(B,)`` moves,
        or ``(B, 2)`` velocity fractions with continuous control."""


class Core(Protocol):
    """A batch of ``num_envs`` games of one scenario; see the module docstring."""

    scenario: Scenario
    num_envs: int
    t: np.ndarray  # (B,) steps taken in the current episode
    episode_seed: np.ndarray  # (B,) uint64

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Mapping[str, Sequence[float]] | None] | None = None,
    ) -> None:
        """Start new episodes in games ``envs`` with episode ``seeds``."""

    def step(self, actions: np.ndarray, evader_actions: np.ndarray | None = None) -> StepOutcome:
        """Advance every game by one step with pursuer ``actions`` ``(B, N)``, or ``(B, N, 2)``
        with continuous control; ``evader_actions`` ``(B,)`` or ``(B, 2)`` are required with a
        learned evader and refused otherwise (``ValueError``)."""

    def observe(self) -> np.ndarray:
        """Global observations, float32 of shape ``(B, obs_dim)`` (SPEC §5)."""

    def positions(self) -> np.ndarray:
        """Agent positions ``(B, N + 1, 2)``: pursuers, then the evader (cells or metres)."""

    def velocities(self) -> np.ndarray | None:
        """Agent velocities ``(B, N + 1, 2)`` in m/s (physics mode), else ``None``."""


def agent_names(scenario: Scenario) -> list[str]:
    """All agents of a game, pursuers first and the evader last."""
    return [*scenario.agents, "evader"]


def parse_positions(
    scenario: Scenario, positions: Mapping[str, Sequence[float]], low: float, high: float
) -> np.ndarray:
    """Validate ``reset(options={"positions": …})`` and return ``(N + 1, 2)`` float positions.

    Agents not named keep their default start. Positions must lie in ``[low, high]`` on
    both axes; grid positions must be integer cells. Raises ``ValueError`` naming the
    agent and the value at fault.
    """
    names = agent_names(scenario)
    out = default_start(scenario.size, scenario.pursuers).astype(np.float64)
    if scenario.mode == "physics":
        out += 0.5
    unknown = sorted(set(positions) - set(names))
    if unknown:
        raise ValueError(f"positions: unknown agent {unknown[0]!r} (agents: {', '.join(names)})")
    for agent, value in positions.items():
        try:
            xy = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"positions[{agent!r}] = {value!r} is not an (x, y) pair") from None
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise ValueError(f"positions[{agent!r}] = {value!r} is not an (x, y) pair")
        if scenario.mode == "grid" and not np.all(xy == np.round(xy)):
            raise ValueError(f"positions[{agent!r}] = {value!r} is not an integer cell")
        if np.any(xy < low) or np.any(xy > high):
            raise ValueError(
                f"positions[{agent!r}] = {value!r} is off the arena (each coordinate in "
                f"[{low:g}, {high:g}])"
            )
        out[names.index(agent)] = xy
    return out


def action_shape(scenario: Scenario) -> tuple[int, ...]:
    """One game's joint action: ``(N,)`` moves, or ``(N, 2)`` commands with continuous control."""
    n = scenario.pursuers
    return (n, 2) if scenario.continuous else (n,)


def clip_to_disc(commands: np.ndarray) -> np.ndarray:
    """Velocity commands ``(..., 2)`` as float64, vectors longer than 1 scaled back onto the
    unit circle (SPEC §3b: out-of-range commands are clipped, not refused)."""
    commands = np.asarray(commands, dtype=np.float64)
    squared = (commands * commands).sum(-1, keepdims=True)
    if not (squared > 1.0).any():  # the common case: nothing to clip (same result)
        return commands
    return commands / np.sqrt(np.maximum(squared, 1.0))


def check_commands(actions: np.ndarray, names: Sequence[str]) -> None:
    """Raise ``ValueError`` naming the agent of the first continuous command ``(B, N, 2)``
    that is not a pair of finite numbers (NaN or inf); out-of-range values are fine."""
    if actions.ndim != 3 or actions.shape[1:] != (len(names), 2):
        raise ValueError(
            f"expected continuous actions of shape (B, {len(names)}, 2), got {actions.shape}"
        )
    if actions.dtype.kind not in "iuf":  # integers and floats
        raise ValueError(f"expected real-valued continuous actions, got dtype {actions.dtype}")
    bad = ~np.isfinite(actions).all(-1)
    if bad.any():
        env, agent = (int(i) for i in np.argwhere(bad)[0])
        where = f" in env {env}" if actions.shape[0] > 1 else ""
        raise ValueError(
            f"invalid action {actions[env, agent].tolist()} for {names[agent]}{where}:"
            " expected a finite (vx, vy) command"
        )


def check_joint_actions(
    scenario: Scenario, actions: object, num_envs: int | None = None
) -> np.ndarray:
    """The pursuers' actions of a batch as an array (``actions`` itself if it is one), or a
    ``ValueError``: of the wrong shape (naming the expected ``(B, N)``, or ``(B, N, 2)``
    with continuous control; ``B`` is ``num_envs`` if given), moves that are not integers
    (NaN, floats, bools) or out of range, or commands that are not finite numbers (the
    checks of :func:`check_commands` and :func:`check_actions`). Cheap: one shape and one
    dtype comparison, then one vectorised range or finiteness test."""
    array = np.asarray(actions)
    n = scenario.pursuers
    if scenario.continuous:
        shape, what = f"(B, {n}, 2)", "one finite (vx, vy) command per pursuer"
        ok = array.ndim == 3 and array.shape[1:] == (n, 2)
    else:
        shape, what = f"(B, {n})", f"one integer move in [0, {scenario.actions}) per pursuer"
        ok = array.ndim == 2 and array.shape[1] == n
    if num_envs is not None:
        shape = shape.replace("B", f"B = {num_envs}")
        ok = ok and array.shape[0] == num_envs
    if not ok:
        raise ValueError(f"expected actions of shape {shape} ({what}), got shape {array.shape}")
    if scenario.continuous:
        check_commands(array, scenario.agents)
        return array
    if array.dtype.kind not in "iu":  # NaN, floats and bools would index the move table
        nan = " holding NaN" if array.dtype.kind == "f" and np.isnan(array).any() else ""
        raise ValueError(
            f"expected integer moves in [0, {scenario.actions}) of shape {shape}, got"
            f" dtype {array.dtype}{nan}"
        )
    check_actions(array, scenario.actions, scenario.agents)
    return array


def check_actions(actions: np.ndarray, n_actions: int, names: Sequence[str]) -> None:
    """Raise ``ValueError`` naming the agent and value of the first action out of range."""
    bad = (actions < 0) | (actions >= n_actions)
    if bad.any():
        env, agent = (int(i) for i in np.argwhere(bad)[0])
        where = f" in env {env}" if actions.shape[0] > 1 else ""
        raise ValueError(
            f"invalid action {int(actions[env, agent])} for {names[agent]}{where}:"
            f" expected an integer in [0, {n_actions})"
        )


REWARD_PARTS = ("time", "collision")
"""The team reward's components (SPEC §4): ``time`` is the step reward with the capture and
wall terms, ``collision`` the collision penalty (zero in ``off`` mode)."""


def reward_parts(scenario: Scenario, outcome: StepOutcome, out: np.ndarray) -> None:
    """Write the step's reward split into :data:`REWARD_PARTS` into ``out (B, 2)``.

    The parts sum to the team reward (the collision part is exact; the time part is the
    rest, so the sum equals ``outcome.reward`` up to float rounding of the subtraction).
    """
    weight = scenario.rewards.collision if scenario.collisions.mode != "off" else 0.0
    np.multiply(outcome.collisions, weight, out=out[:, 1])
    np.subtract(outcome.reward, out[:, 1], out=out[:, 0])
