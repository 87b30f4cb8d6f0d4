"""Scripted evader policies (SPEC §1): ``random``, ``flee`` and ``static``.

Randomness is counter-based: the evader's draw at step ``t`` of an episode is a hash
(SplitMix64) of the episode seed, ``t`` and a stream number. A batch of games thus draws
its random numbers in one vectorised operation, and any single episode is reproduced
exactly from its seed, in any batch, in any order — which is what ``replay --verify`` and
the batched-vs-single property tests rely on. Being counter-based, the draws can also be
computed ahead: :class:`Evader` (what the cores use) fills each game's next draws in one
vectorised call; :func:`random_actions` and :func:`flee_actions` are the step-by-step
policies it reproduces.
"""

from __future__ import annotations

import numpy as np

from ...config import Scenario

STAY = 4
"""The static evader's action: stay. Cores accept it for the evader even with 4 actions."""

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser: a bijective, well-mixed hash of uint64 values."""
    x = x ^ (x >> np.uint64(30))
    x = x * _MIX1
    x = x ^ (x >> np.uint64(27))
    x = x * _MIX2
    return x ^ (x >> np.uint64(31))


def draw(seed: np.ndarray, t: np.ndarray) -> np.ndarray:
    """One uniform uint64 per game for step ``t``: SplitMix64's ``t``-th output from ``seed``."""
    # uint64 array arithmetic wraps modulo 2**64 (numpy warns only for scalars)
    return mix64(seed + (t.astype(np.uint64) + np.uint64(1)) * _GOLDEN)


def draws(seed: np.ndarray, t: np.ndarray, streams: int) -> np.ndarray:
    """``(B, streams)`` independent uniform uint64 draws for step ``t``."""
    return _lanes(draw(seed, t), streams)


def _lanes(drawn: np.ndarray, streams: int) -> np.ndarray:
    lanes = np.arange(1, streams + 1, dtype=np.uint64) * _GOLDEN
    return mix64(drawn[:, None] + lanes)


def random_actions(seed: np.ndarray, t: np.ndarray, n_actions: int) -> np.ndarray:
    """Uniform actions in ``[0, n_actions)`` for each game."""
    return _uniform_action(draw(seed, t), n_actions)


def _uniform_action(drawn: np.ndarray, n_actions: int) -> np.ndarray:
    return ((drawn >> np.uint64(33)) % np.uint64(n_actions)).astype(np.int64)


def flee_actions(
    seed: np.ndarray,
    t: np.ndarray,
    evader_xy: np.ndarray,
    pursuer_xy: np.ndarray,
    n_actions: int,
    low: float,
    high: float,
    blocked: np.ndarray | None = None,
) -> np.ndarray:
    """The move maximising the Manhattan distance to the nearest pursuer after the move.

    ``evader_xy`` is ``(B, 2)``, ``pursuer_xy`` ``(B, N, 2)`` (the pursuers' positions at the
    start of the step: moves are simultaneous). Moves are clipped to ``[low, high]`` as the
    arena does. Ties are broken uniformly at random by a random rank per action.

    ``blocked`` (grid only): the cells obstacles block, ``(size, size)`` bool indexed
    ``[y, x]`` (:func:`blocked_grid`); a move from a free cell into one stays put, as in
    :class:`~a2cm_phys.envs.grid.GridRules`. ``None``: no cell is blocked (physics, where
    the obstacles' shapes stop the evader).
    """
    return flee_moves(draw(seed, t), evader_xy, pursuer_xy, n_actions, low, high, blocked)


def flee_moves(
    drawn: np.ndarray,
    evader_xy: np.ndarray,
    pursuer_xy: np.ndarray,
    n_actions: int,
    low: float,
    high: float,
    blocked: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`flee_actions` given the step's draws ``drawn = draw(seed, t)``."""
    deltas = _DELTAS_F[:n_actions]
    cand = np.clip(evader_xy[:, None, :] + deltas[None], low, high)  # (B, A, 2)
    if blocked is not None:
        cand = _stay_out(cand, evader_xy, blocked)
    dist = np.abs(cand[:, :, None, :] - pursuer_xy[:, None, :, :]).sum(-1).min(-1)  # (B, A)
    rank = (_lanes(drawn, n_actions) >> np.uint64(12)).astype(np.float64) / 2.0**52
    best = dist.max(axis=1, keepdims=True)
    score = np.where(np.isclose(dist, best, rtol=0.0, atol=1e-9), rank, -1.0)
    return score.argmax(axis=1).astype(np.int64)


def blocked_grid(scenario: Scenario) -> np.ndarray | None:
    """The cells a grid scenario's obstacles block as :func:`flee_actions` takes them,
    ``(size, size)`` bool indexed ``[y, x]``; ``None`` without any (and in physics mode)."""
    if scenario.mode != "grid" or not scenario.obstacles:
        return None
    return scenario.blocked_cells().reshape(scenario.size, scenario.size)


def _stay_out(cand: np.ndarray, evader_xy: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """Candidate cells ``(B, A, 2)`` (integer-valued floats, grid), each blocked one replaced
    by the evader's own cell ``(B, 2)``, unless that is blocked too (the rules' moves)."""
    x, y = cand[..., 0].astype(np.int64), cand[..., 1].astype(np.int64)
    ex, ey = evader_xy[:, 0].astype(np.int64), evader_xy[:, 1].astype(np.int64)
    stays = blocked[y, x] & ~blocked[ey, ex][:, None]
    return np.where(stays[..., None], evader_xy[:, None, :], cand)


def evader_actions(
    scenario: Scenario,
    seed: np.ndarray,
    t: np.ndarray,
    evader_xy: np.ndarray | None,
    pursuer_xy: np.ndarray | None,
    low: float,
    high: float,
) -> np.ndarray:
    """The evader's action in every game, by the scenario's evader policy.

    Positions (``(B, 2)`` and ``(B, N, 2)``) are read only by ``flee`` and may be ``None``
    otherwise; ``[low, high]`` is the range the arena clips positions to (and on a grid,
    cells the obstacles block are avoided, :func:`blocked_grid`). This is :class:`Evader`
    without look-ahead: each call hashes step ``t`` itself.
    """
    evader = Evader(scenario, len(seed), low, high, horizon=1)
    return evader.moves(seed, t, evader_xy, pursuer_xy)


class Evader:
    """The evader of a batch of ``num_envs`` games, as the cores use it: the moves of
    :func:`evader_actions`, with the random draws computed ahead.

    Each game's draws for its next ``horizon`` steps are filled in one vectorised call and
    read one column per step. For small batches, where numpy's fixed cost per call is most
    of the work, this is several times cheaper than hashing every step; the default
    horizon shrinks as batches grow (to 1 from 4096 games, i.e. no look-ahead). The core
    owns the seed and step arrays it passes to :meth:`moves`: it must call :meth:`restart`
    for games it resets (they start at ``t = 0`` with new seeds) and :meth:`forget` when it
    changes them in any other way (loading a state).
    """

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int,
        low: float,
        high: float,
        horizon: int | None = None,
    ) -> None:
        self.policy, self.n_actions = scenario.evader, scenario.actions
        self.needs_positions = self.policy == "flee"  # the others ignore positions
        self.low, self.high = low, high
        self.blocked = blocked_grid(scenario)  # grid obstacles; physics shapes stop it there
        self.horizon = horizon or max(1, min(64, 4096 // max(num_envs, 1)))
        random = self.policy == "random"  # store the moves themselves, else the draws
        self._ahead = np.zeros((num_envs, self.horizon), np.int64 if random else np.uint64)
        self._next = self.horizon  # column of the coming step; ``horizon``: refill first

    def _fill(self, seed: np.ndarray, t: np.ndarray) -> np.ndarray:
        drawn = draw(seed, t)
        return _uniform_action(drawn, self.n_actions) if self.policy == "random" else drawn

    def restart(self, envs: np.ndarray, seeds: np.ndarray) -> None:
        """Games ``envs`` start new episodes (``t = 0``) with episode ``seeds``."""
        left = self.horizon - self._next
        if left > 0 and self.policy != "static":
            ahead = np.arange(left)[None]
            self._ahead[envs, self._next :] = self._fill(np.asarray(seeds)[..., None], ahead)

    def forget(self) -> None:
        """Drop every draw computed ahead (the seeds or steps changed)."""
        self._next = self.horizon

    def moves(
        self,
        seed: np.ndarray,
        t: np.ndarray,
        evader_xy: np.ndarray | None = None,
        pursuer_xy: np.ndarray | None = None,
    ) -> np.ndarray:
        """The evader's action in every game at steps ``t`` (see :func:`evader_actions`)."""
        if self.policy == "static":
            return np.full(len(seed), STAY, dtype=np.int64)
        if self._next == self.horizon:
            self._ahead = self._fill(seed[:, None], t[:, None] + np.arange(self.horizon))
            self._next = 0
        column = self._ahead[:, self._next].copy()
        self._next += 1
        if self.policy == "random":
            return column
        return flee_moves(
            column, evader_xy, pursuer_xy, self.n_actions, self.low, self.high, self.blocked
        )


_DELTAS_F = np.array([(0, 1), (0, -1), (-1, 0), (1, 0), (0, 0)], dtype=np.float64)
