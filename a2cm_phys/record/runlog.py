"""The log's data model: what a run log holds once read.

:class:`RunLog` (one log, or a run's parts read together: metadata, the episodes' summaries
column-wise, the updates, the logged trajectories) and :class:`Trajectory` (one episode as
logged). Reading one file into them is :mod:`.reader`'s job; reading a run's parts
together, :mod:`.parts`'s.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..base.errors import UserError
from ..config import ConfigError, Scenario, build
from .masks import masks_of, unpacked
from .schemas import SUMMARY_SCHEMA


class LogError(UserError):
    """A run log cannot be read (missing, not an MCAP, not ours); the message says why."""


@dataclass
class Trajectory:
    """One episode as logged: ``positions``/``velocities`` have ``length + 1`` rows (row 0
    is the start), the per-step arrays ``length`` rows. Agents: pursuers, then the evader.

    ``actions`` are ``(L, N + 1)`` int64 moves, or with continuous control ``(L, N + 1, 2)``
    float64 commands, exactly as given to the env (before clipping). ``dt`` is the simulated
    seconds per step (the control period). ``evader_reward`` is a learned evader's reward
    per step (``None`` with a scripted evader, or in a log older than format 2). ``sensed``
    holds each state's sensing masks (SPEC §6b; ``[k, i, j]``: agent ``i`` knows body ``j``
    in state ``k``), in logs of sensing scenarios written since the masks were logged
    (``None`` otherwise; :func:`trajectory_masks` recomputes them). ``headings`` are the
    pursuers' ``(cos θ, sin θ)`` in each state, with differential drive (``None``
    otherwise)."""

    episode: int
    env: int
    seed: int
    t0: float
    dt: float
    positions: np.ndarray  # (L + 1, N + 1, 2)
    actions: np.ndarray  # (L, N + 1) int64 or (L, N + 1, 2) float64: pursuers, then evader
    reward: np.ndarray  # (L,) float64
    captured: np.ndarray  # (L,) bool
    collisions: np.ndarray  # (L,) int64
    wall_contacts: np.ndarray  # (L,) int64
    velocities: np.ndarray | None = None  # (L + 1, N + 1, 2), physics only
    events: list[tuple[str, str, str, int]] | None = None  # physics only
    evader_reward: np.ndarray | None = None  # (L,) float64, learned evader only
    sensed: np.ndarray | None = None  # (L + 1, N + 1, N + 1) bool, sensing scenarios only
    headings: np.ndarray | None = None  # (L + 1, N, 2) cos θ, sin θ; differential drive only

    @property
    def continuous(self) -> bool:
        """Whether the actions are continuous commands (float vectors)."""
        return self.actions.ndim == 3

    @property
    def length(self) -> int:
        """Steps taken."""
        return len(self.reward)

    @staticmethod
    def from_block(doc: dict[str, Any]) -> list[Trajectory]:
        """Split one ``/episodes/trajectories`` message into its episodes."""
        lengths = np.asarray(doc["length"], dtype=np.int64)
        states = np.cumsum(lengths + 1)
        steps = np.cumsum(lengths)
        pos = np.asarray(doc["positions"])
        agents = pos.shape[1] // 2 if pos.ndim == 2 else 0
        pos = pos.reshape(len(pos), agents, 2)
        vel = doc.get("velocities")
        vel = None if vel is None else np.asarray(vel, dtype=np.float64).reshape(pos.shape)
        act = _actions(doc["actions"], agents)
        evader_reward = doc.get("evader_reward")
        if evader_reward is not None:
            evader_reward = np.asarray(evader_reward, dtype=np.float64)
        reward = np.asarray(doc["reward"], dtype=np.float64)
        captured = np.asarray(doc["captured"], dtype=bool)
        collisions = np.asarray(doc["collisions"], dtype=np.int64)
        walls = np.asarray(doc["wall_contacts"], dtype=np.int64)
        events = doc.get("events")
        hdg = doc.get("headings")
        if hdg is not None:
            hdg = np.asarray(hdg, dtype=np.float64).reshape(len(pos), agents - 1, 2)
        masks = doc.get("sensed")
        masks = None if masks is None else unpacked(np.asarray(masks, dtype=np.int64))
        out = []
        for j, length in enumerate(lengths.tolist()):
            a, b = states[j] - length - 1, states[j]
            c, d = steps[j] - length, steps[j]
            out.append(
                Trajectory(
                    episode=int(doc["episode"][j]),
                    env=int(doc["env"][j]),
                    seed=int(doc["seed"][j]),
                    t0=float(doc["t0"][j]),
                    dt=float(doc["dt"]),
                    positions=pos[a:b],
                    actions=act[c:d],
                    reward=reward[c:d],
                    captured=captured[c:d],
                    collisions=collisions[c:d],
                    wall_contacts=walls[c:d],
                    velocities=None if vel is None else vel[a:b],
                    events=None if events is None else [tuple(e) for e in events[j]],
                    evader_reward=None if evader_reward is None else evader_reward[c:d],
                    sensed=None if masks is None else masks[a:b],
                    headings=None if hdg is None else hdg[a:b],
                )
            )
        return out


def _actions(rows: list[list[Any]], agents: int) -> np.ndarray:
    """The ``actions`` rows of a block: ``agents`` moves a row (int64), or ``2 · agents``
    command components a row (float64 ``(steps, agents, 2)``; ``null`` reads as NaN)."""
    width = len(rows[0]) if rows else agents
    if width == 2 * agents:
        return np.asarray(rows, dtype=np.float64).reshape(-1, agents, 2)
    return np.asarray(rows, dtype=np.int64).reshape(-1, agents)


SUMMARY_FIELDS = tuple(k for k in SUMMARY_SCHEMA["required"] if k != "seed")
"""Columns of :attr:`RunLog.episodes` besides ``seed`` (plus ``evader_return`` in logs of
learned-evader runs)."""


@dataclass
class RunLog:
    """Everything read from one run log.

    ``episodes`` holds the summaries column-wise (numpy arrays keyed by
    :data:`SUMMARY_FIELDS` and ``seed``, and ``evader_return`` if the log has it), in
    episode order. ``updates`` is the list of update
    messages. ``metadata`` the run's metadata (values decoded from JSON).
    """

    path: Path
    metadata: dict[str, Any]
    episodes: dict[str, np.ndarray]
    updates: list[dict[str, Any]]
    clean: bool
    error: str | None = None
    damaged: bool = False  # closed cleanly, but a record fails its checks (not a crash)
    parts: list[Path] = field(default_factory=list)  # the files read (a run folder: all parts)
    topic_counts: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)  # parts unreadable, damaged or missing
    _blocks: list[bytes] = field(default_factory=list, repr=False)
    _where: dict[int, int] = field(default_factory=dict, repr=False)
    _cache: tuple[int, dict[int, Trajectory]] | None = field(default=None, repr=False)

    @property
    def n_episodes(self) -> int:
        """Episodes recovered (one summary each)."""
        return len(self.episodes["episode"])

    @property
    def scenario(self) -> Scenario:
        """The run's resolved scenario, rebuilt from the metadata (validated)."""
        data = self.metadata.get("scenario")
        if not isinstance(data, dict):
            raise LogError(f"{self.path}: the metadata holds no scenario")
        try:
            return build(Scenario, data, f"{self.path} metadata")
        except ConfigError as err:
            raise LogError(str(err)) from None

    @property
    def label(self) -> str:
        """A short name for plots: metadata ``label``, else the algorithm, else the file."""
        train = self.metadata.get("train")
        algo = self.metadata.get("algo") or (train.get("algo") if isinstance(train, dict) else None)
        return str(self.metadata.get("label") or (algo.upper() if algo else self.path.parent.name))

    @property
    def logged_episodes(self) -> list[int]:
        """Ids of the episodes whose trajectory is in the log, ascending."""
        return sorted(self._where)

    def trajectory(self, episode: int) -> Trajectory:
        """The logged trajectory of ``episode``; ``KeyError`` if it is not in the log."""
        block = self._where[episode]
        if self._cache is None or self._cache[0] != block:
            trajs = Trajectory.from_block(json.loads(self._blocks[block]))
            self._cache = (block, {t.episode: t for t in trajs})
        return self._cache[1][episode]

    def trajectories(self) -> Iterator[Trajectory]:
        """Every logged trajectory of the run once, in the order they were written (in a run
        of several parts, not those a later part superseded)."""
        for block, data in enumerate(self._blocks):
            for traj in Trajectory.from_block(json.loads(data)):
                if self._where.get(traj.episode) == block:
                    yield traj


def trajectory_masks(scenario: Scenario, traj: Trajectory) -> np.ndarray | None:
    """Every state's masks ``(L + 1, N + 1, N + 1)``: the logged ones, else recomputed from
    the positions (an older log, an episode played for a picture); ``None`` without sensing."""
    if not scenario.sensing.on:
        return None
    if traj.sensed is not None:
        return traj.sensed
    return masks_of(scenario, traj.positions)


def state_masks(scenario: Scenario, traj: Trajectory, k: int) -> np.ndarray | None:
    """State ``k``'s masks ``(N + 1, N + 1)`` (as :func:`trajectory_masks`, for one state)."""
    if not scenario.sensing.on:
        return None
    if traj.sensed is not None:
        return traj.sensed[k]
    return masks_of(scenario, traj.positions[k : k + 1])[0]
