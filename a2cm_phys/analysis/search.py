"""``search``: a scripted team for partially observed continuous physics (SPEC §6b).

Each pursuer sweeps a lawnmower (boustrophedon) path over its own vertical strip of the
arena until the team sights the evader, then every pursuer drives at it; it reads only
what the pursuers sense (their own slices of the team vector), never the global state.

- **Strips**: the arena is split into ``N`` vertical strips of equal width. A game's
  pursuers take them in the order of their ``x`` at the episode's first step (ties by
  index), so that nobody crosses the arena to reach its strip.
- **Lanes**: vertical, equally spaced across the strip, as few as cover it: every point of
  the strip lies within the sensing radius of the path (:func:`sweep_waypoints`). Their
  ends, like every waypoint, are kept inside the walls by the body's half side.
- **Sweep**: a pursuer starts at the end of its path nearer to it, goes through the
  waypoints to the other end, then back again (ping-pong), forever. A waypoint is
  reached within one step's travel (``max_speed · dt``).
- **Sighting**: the team sights the evader when any pursuer's mask bit for it is set
  (pooled, whatever ``sensing.share``); the sighting is the evader's sensed position,
  updated at every step it is in view. Then every pursuer heads for it at full command.
- **Lost sighting** (our rule): when a pursuer reaches the last sighting (its centre
  within half a body side plus one step of it) and nobody senses the evader, the sighting
  is dropped and every pursuer resumes its sweep where it left it: it heads again for the
  waypoint it was heading for, in the same direction.

Commands are unit vectors (the continuous ``pursuit`` baseline's convention: a fraction
of ``max_speed``, length 1, zero on the target itself); with differential drive, the
``(forward, turn)`` commands that steer along them (:func:`~.baselines.steer`), from each
pursuer's own heading in its slice. The policy has memory per game
(sweep progress, strips, sighting), forgotten by :meth:`SearchPolicy.episodes_ended`.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import ConfigError, Scenario
from ..envs.sensing import agent_slice, features, team_dim
from ..training.rollout import Policy
from .baselines import steer

__all__ = ["SearchPolicy", "search_policy", "strip_bounds", "sweep_waypoints"]


def _check(scenario: Scenario) -> None:
    """A :class:`ConfigError` (a ``ValueError``) naming the scenario unless it is physics
    with continuous control and sensing."""
    if scenario.mode != "physics" or not scenario.continuous:
        raise ConfigError(
            f"search policy: scenario '{scenario.name}' is not physics with continuous"
            " control (search steers with velocity commands)"
        )
    if not scenario.sensing.on:
        raise ConfigError(
            f"search policy: scenario '{scenario.name}' has no sensing (every pursuer sees"
            " the whole state; use pursuit): search needs a [sensing] radius"
        )


def strip_bounds(scenario: Scenario) -> np.ndarray:
    """The ``N`` vertical strips ``(N, 2)``: ``[x_low, x_high]`` in metres, left to right."""
    edges = np.linspace(0.0, float(scenario.size), scenario.pursuers + 1)
    return np.stack([edges[:-1], edges[1:]], axis=1)


def _lanes(scenario: Scenario) -> int:
    """How many lanes cover one strip: a lane covers ``h`` metres either side, where a
    point ``h`` to the side of a lane's end (itself ``r`` from the wall, and reached only
    within one step) is still within the sensing radius of the path."""
    size, n = float(scenario.size), scenario.pursuers
    radius = float(scenario.sensing.radius) - scenario.physics.max_speed * scenario.physics.dt
    inset = scenario.physics.box_side / 2
    if radius <= inset:  # no path covers the arena's corners: lanes a radius apart
        half = max(float(scenario.sensing.radius), 1e-6) / 2
    else:
        half = math.sqrt(radius * radius - inset * inset)
    return max(1, math.ceil((size / n) / (2 * half) - 1e-9))


def sweep_waypoints(scenario: Scenario) -> np.ndarray:
    """Every strip's lawnmower path ``(N, 2 L, 2)`` in metres (strip ``s`` of
    :func:`strip_bounds`, ``L`` lanes each): up the first lane, across, down the second,
    and so on. Lanes are equally spaced in the strip; every waypoint lies at least half a
    body side from the walls."""
    size = float(scenario.size)
    inset = scenario.physics.box_side / 2
    low, high = min(inset, size / 2), max(size - inset, size / 2)
    lanes = _lanes(scenario)
    strips = strip_bounds(scenario)
    offsets = (np.arange(lanes) + 0.5) / lanes  # lane centres, as fractions of the strip
    xs = np.clip(strips[:, :1] + offsets[None] * (strips[:, 1:] - strips[:, :1]), low, high)
    ends = np.array([[low, high], [high, low]])[np.arange(lanes) % 2]  # (L, 2): up, down, …
    ys = np.broadcast_to(ends, (len(strips), lanes, 2))
    xs = np.broadcast_to(xs[:, :, None], ys.shape)
    return np.stack([xs, ys], axis=-1).reshape(len(strips), 2 * lanes, 2)


def _towards(gap: np.ndarray) -> np.ndarray:
    """Unit commands along ``gap`` ``(..., 2)`` (zero where the gap is zero), float32."""
    norm = np.sqrt((gap * gap).sum(-1, keepdims=True))
    return np.divide(gap, norm, out=np.zeros_like(gap), where=norm > 0).astype(np.float32)


class SearchPolicy:
    """The ``search`` team (see the module docstring): ``policy(obs (B, team_dim), rng)
    -> commands (B, N, 2)`` float32, with memory per game (a call with another number of
    games ``B`` than the last starts every game afresh)."""

    def __init__(self, scenario: Scenario) -> None:
        _check(scenario)
        self.scenario = scenario
        self.waypoints = sweep_waypoints(scenario)  # (N strips, M, 2)
        self.reach = scenario.physics.max_speed * scenario.physics.dt
        self.sighting_reach = scenario.physics.box_side / 2 + self.reach
        n, k = scenario.pursuers, features(scenario)
        self._evader = k + (n - 1) * (1 + k)  # the evader's mask bit in a pursuer's slice
        self._games = 0

    def _allocate(self, games: int) -> None:
        n = self.scenario.pursuers
        self._games = games
        self.started = np.zeros(games, dtype=bool)  # sweep set up this episode
        self.strip = np.zeros((games, n), dtype=np.intp)
        self.index = np.zeros((games, n), dtype=np.intp)  # the waypoint headed for
        self.step_dir = np.ones((games, n), dtype=np.intp)  # +1 / -1 along the path
        self.sighted = np.zeros(games, dtype=bool)
        self.target = np.zeros((games, 2), dtype=np.float64)  # the last sighting (m)

    def episodes_ended(self, ended: np.ndarray) -> None:
        """Forget the sweep and the sighting of the games whose episode ``ended`` ``(B,)``."""
        if self._games:
            ended = np.asarray(ended, dtype=bool)
            self.started[ended] = False
            self.sighted[ended] = False

    def sense(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the team senses in ``obs`` ``(B, team_dim)``: the pursuers' own positions
        ``(B, N, 2)``, whether any pursuer senses the evader ``(B,)`` and where (metres;
        ``(B, 2)``, meaningful where sensed). Reads only the pursuers' slices."""
        scenario = self.scenario
        obs = np.asarray(obs, dtype=np.float64)
        if obs.ndim != 2 or obs.shape[1] != team_dim(scenario):
            raise ValueError(
                f"search policy: observations of shape {obs.shape}, expected"
                f" (B, {team_dim(scenario)}) for scenario '{scenario.name}'"
            )
        rows = np.stack(
            [obs[:, agent_slice(scenario, i)] for i in range(scenario.pursuers)], axis=1
        )  # (B, N, obs_dim)
        own = rows[:, :, :2] * scenario.size
        masks = rows[:, :, self._evader] > 0.5
        first = masks.argmax(1)  # the first pursuer that senses it (all sense the same body)
        seen = rows[np.arange(len(obs)), first, self._evader + 1 : self._evader + 3]
        return own, masks.any(1), seen * scenario.size

    def _start(self, games: np.ndarray, own: np.ndarray) -> None:
        """Set up the sweep of ``games`` (bool ``(B,)``): strips by ``x``, the nearer end."""
        rows = np.flatnonzero(games)
        order = np.argsort(own[rows, :, 0], axis=1, kind="stable")
        strip = np.empty_like(order)
        np.put_along_axis(strip, order, np.arange(order.shape[1])[None], axis=1)
        path = self.waypoints[strip]  # (G, N, M, 2)
        first = np.linalg.norm(path[:, :, 0] - own[rows], axis=-1)
        last = np.linalg.norm(path[:, :, -1] - own[rows], axis=-1)
        at_end = last < first
        self.strip[rows] = strip
        self.index[rows] = np.where(at_end, path.shape[2] - 1, 0)
        self.step_dir[rows] = np.where(at_end, -1, 1)
        self.started[rows] = True

    def _advance(self, own: np.ndarray, sweeping: np.ndarray) -> None:
        """Move on the waypoint of every sweeping pursuer that has reached its own."""
        last = self.waypoints.shape[1] - 1
        goal = self.waypoints[self.strip, self.index]  # (B, N, 2)
        done = (np.linalg.norm(goal - own, axis=-1) <= self.reach) & sweeping[:, None]
        turn = done & ((self.index + self.step_dir < 0) | (self.index + self.step_dir > last))
        self.step_dir = np.where(turn, -self.step_dir, self.step_dir)
        self.index = np.where(done, self.index + self.step_dir, self.index)

    def __call__(self, obs: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Commands ``(B, N, 2)`` float32 for the team vectors ``obs`` ``(B, team_dim)``
        (``rng`` unused: the team is deterministic)."""
        own, seen, where = self.sense(obs)
        if self._games != len(own):
            self._allocate(len(own))
        if not self.started.all():
            self._start(~self.started, own)
        self.target = np.where(seen[:, None], where, self.target)
        self.sighted |= seen
        there = np.linalg.norm(own - self.target[:, None], axis=-1) <= self.sighting_reach
        self.sighted &= seen | ~there.any(1)  # reached without seeing it: the trail is cold
        self._advance(own, ~self.sighted)
        goal = np.where(
            self.sighted[:, None, None],
            self.target[:, None, :],
            self.waypoints[self.strip, self.index],
        )
        unit = _towards(goal - own)
        if not self.scenario.differential:
            return unit
        k = self.scenario.body_features  # a pursuer's own heading: its slice's (cos θ, sin θ)
        rows = [np.asarray(obs)[:, agent_slice(self.scenario, i)] for i in range(len(own[0]))]
        return steer(self.scenario, unit, np.stack(rows, axis=1)[:, :, k - 2 : k])


def search_policy(scenario: Scenario) -> Policy:
    """The ``search`` team for ``scenario`` (physics, continuous control, sensing on; else
    a :class:`~a2cm_phys.config.ConfigError`, a ``ValueError``, naming the scenario)."""
    return SearchPolicy(scenario)
