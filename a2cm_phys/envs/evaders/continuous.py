"""Scripted evaders for continuous control (SPEC §3b): ``random``, ``flee`` and ``static``.

Each policy returns the evader's velocity command in every game, as a fraction of
``max_speed`` inside the unit disc, exactly like a pursuer's continuous action; the core
turns it into a servo velocity. The randomness is the discrete evaders' (see
:mod:`.evader`): the draw of step ``t`` is a counter-based hash of the episode seed and
``t``, so an episode re-simulates from its seed and the pursuers' actions alone.

- ``random`` wanders at :data:`RANDOM_SPEED` × ``max_speed``: its heading takes a bounded
  random walk (each control step turns it by a uniform angle in ``±turn``, with ``turn``
  scaled so that the heading diffuses at :data:`HEADING_DIFFUSION` rad²/s whatever
  ``physics.dt``), starting from a uniform random heading. Heading into a wall it bounces
  off (the heading is mirrored), so it never grinds along a wall.
- ``flee`` runs at :data:`FLEE_SPEED` × ``max_speed`` down a distance-weighted potential,
  looking :data:`FLEE_LOOKAHEAD` seconds ahead: of :data:`FLEE_HEADINGS` headings (a fan
  turned by a seeded random angle, which also breaks ties) it takes the one whose end
  point ``e`` (stopped by the walls) has the lowest ``Σ_i 1 / (|e − p_i| − s) + WALL_WEIGHT ·
  Σ_walls 1 / g``: ``p_i`` pursuer ``i``'s position, ``s`` how far a pursuer runs in the
  look-ahead (so the term is large where a pursuer could get first, and the nearest
  pursuers weigh most), ``g`` the end point's gap to each wall. Running into a wall or a
  corner ends where the pursuers arrive, so it slides along walls and breaks out of corners
  before they close, and it keeps off the walls while nothing presses it.
- ``static`` commands zero velocity.
"""

from __future__ import annotations

import math

import numpy as np

from ...config import Scenario
from .scripted import draw

RANDOM_SPEED = 0.8
"""The random evader's speed as a fraction of ``max_speed``: it keeps moving like the grid's
random evader, a little slower than a pursuer, so that one pursuer driving straight at it
always closes in."""

HEADING_DIFFUSION = 2.0
"""rad²/s: how fast the random evader's heading decorrelates (about once a second, like a
grid evader's fresh move every 1 s step). The turn bound per step is ``√(3 · 2 · dt)``."""

FLEE_SPEED = 1.0
"""The fleeing evader's speed as a fraction of ``max_speed``: as fast as a pursuer, as on the
grid, so that one pursuer alone cannot run it down in the open."""

FLEE_LOOKAHEAD = 1.0
"""Seconds the fleeing evader looks ahead: it scores each heading by where it would be after
running that long, against how far each pursuer would still have to run to get there."""

FLEE_HEADINGS = 16
"""Headings the fleeing evader compares each step (a fan, turned by a random offset)."""

WALL_WEIGHT = 0.25
"""Weight of the walls in the flee potential: a wall ``g`` away repels as much as a pursuer
that still has ``4 g`` to run."""


def _uniform(drawn: np.ndarray) -> np.ndarray:
    """Floats in ``[0, 1)`` from uint64 draws (their top 53 bits)."""
    return (drawn >> np.uint64(11)).astype(np.float64) * 2.0**-53


class ContinuousEvader:
    """The scripted evader of ``num_envs`` continuous games; implements
    :class:`~.core.EvaderPolicy`. ``low`` and ``high`` bound the evader's centre (the arena
    shrunk by its radius).

    The random evader's turns are computed ahead, as the discrete :class:`~.evader.Evader`
    computes its draws: each game's next ``horizon`` turns (as cosines and sines) in one
    vectorised call, read one column per step (numpy's fixed cost per call is most of the
    work in small batches). Its heading is kept as a unit vector, rotated each step.
    """

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int,
        low: float,
        high: float,
        horizon: int | None = None,
    ) -> None:
        self.policy = scenario.evader
        self.needs_positions = self.policy != "static"
        self.low, self.high = float(low), float(high)
        self.turn = math.sqrt(3.0 * HEADING_DIFFUSION * scenario.physics.dt)
        self.margin = scenario.physics.max_speed * scenario.physics.dt  # one step's travel
        self.horizon = horizon or max(1, min(64, 4096 // max(num_envs, 1)))
        self.heading = np.zeros((num_envs, 2))  # random: each game's heading, a unit vector
        self.heading[:, 0] = 1.0
        self._cos = np.ones((num_envs, self.horizon))  # the coming turns, one column a step
        self._sin = np.zeros((num_envs, self.horizon))
        self._next = self.horizon  # column of the coming step; ``horizon``: refill first
        self._static = np.zeros((num_envs, 2))
        lookahead = FLEE_LOOKAHEAD * scenario.physics.max_speed
        self._reach, self._chase = FLEE_SPEED * lookahead, lookahead
        self._fan = np.arange(FLEE_HEADINGS) * (2.0 * math.pi / FLEE_HEADINGS)

    def _turns(self, seed: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cosine and sine of the random evader's turn at steps ``t``: its initial heading
        (uniform) at ``t = 0``, a uniform turn in ``±turn`` after."""
        u = _uniform(draw(seed, t))
        angle = np.where(t == 0, 2.0 * math.pi * u, self.turn * (2.0 * u - 1.0))
        return np.cos(angle), np.sin(angle)

    def restart(self, envs: np.ndarray, seeds: np.ndarray) -> None:
        """Games ``envs`` start new episodes (``t = 0``) with episode ``seeds``."""
        if self.policy != "random":
            return
        self.heading[envs] = (1.0, 0.0)
        left = self.horizon - self._next
        if left > 0:
            ahead = np.arange(left)[None]
            cos, sin = self._turns(np.asarray(seeds)[..., None], ahead)
            self._cos[envs, self._next :], self._sin[envs, self._next :] = cos, sin

    def forget(self) -> None:
        """Drop every turn computed ahead (the seeds or steps changed)."""
        self._next = self.horizon

    def moves(
        self,
        seed: np.ndarray,
        t: np.ndarray,
        evader_xy: np.ndarray | None = None,
        pursuer_xy: np.ndarray | None = None,
    ) -> np.ndarray:
        """The evader's command ``(B, 2)`` (fraction of ``max_speed``) in every game at steps
        ``t``, from its position ``(B, 2)`` and the pursuers' ``(B, N, 2)``."""
        if self.policy == "static":
            return self._static.copy()
        if self.policy == "random":
            return self._wander(seed, t, evader_xy)
        return self._flee(seed, t, evader_xy, pursuer_xy)

    def _wander(self, seed: np.ndarray, t: np.ndarray, xy: np.ndarray) -> np.ndarray:
        if self._next == self.horizon:
            self._cos, self._sin = self._turns(seed[:, None], t[:, None] + np.arange(self.horizon))
            self._next = 0
        cos, sin = self._cos[:, self._next], self._sin[:, self._next]
        self._next += 1
        h = self.heading
        # Rotated in place (fewer numpy calls than a stack; the same products and sums).
        x, y = h[:, 0], h[:, 1]
        turned_x = cos * x - sin * y
        y *= cos
        y += sin * x
        x[:] = turned_x
        np.negative(h, out=h, where=self._into_wall(xy, h))  # bounce: mirror what heads into a wall
        return RANDOM_SPEED * h

    def _flee(
        self, seed: np.ndarray, t: np.ndarray, xy: np.ndarray, pursuers: np.ndarray
    ) -> np.ndarray:
        # Candidate headings: a fan of FLEE_HEADINGS, turned by a seeded random offset.
        offset = _uniform(draw(seed, t))[:, None] * (2.0 * math.pi / FLEE_HEADINGS)
        angle = offset + self._fan  # (B, K)
        heading = np.stack((np.cos(angle), np.sin(angle)), axis=-1)  # (B, K, 2)
        ahead = np.clip(xy[:, None] + self._reach * heading, self.low, self.high)
        gap = ahead[:, :, None] - pursuers[:, None]  # (B, K, N, 2)
        left = np.sqrt((gap * gap).sum(-1)) - self._chase  # what each pursuer still has to run
        potential = (1.0 / np.maximum(left, 1e-3)).sum(-1)
        walls = np.minimum(ahead - self.low, self.high - ahead)  # (B, K, 2) gaps
        potential += WALL_WEIGHT * (1.0 / np.maximum(walls, 1e-3)).sum(-1)
        best = potential.argmin(1)
        return FLEE_SPEED * heading[np.arange(len(xy)), best]

    def _into_wall(self, xy: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Which components of ``v`` ``(B, 2)`` head into a wall within one step's travel."""
        return ((v < 0) & (xy < self.low + self.margin)) | (
            (v > 0) & (xy > self.high - self.margin)
        )
