"""Scripted evader policies (SPEC §1): ``random``, ``flee`` and ``static``.

Randomness is counter-based: the evader's draw at step ``t`` of an episode is a hash
(SplitMix64) of the episode seed, ``t`` and a stream number. A batch of games thus draws
its random numbers in one vectorised operation, and any single episode is reproduced
exactly from its seed, in any batch, in any order — which is what ``replay --verify`` and
the batched-vs-single property tests rely on.
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario

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
    lanes = np.arange(1, streams + 1, dtype=np.uint64) * _GOLDEN
    return mix64(draw(seed, t)[:, None] + lanes)


def random_actions(seed: np.ndarray, t: np.ndarray, n_actions: int) -> np.ndarray:
    """Uniform actions in ``[0, n_actions)`` for each game."""
    return ((draw(seed, t) >> np.uint64(33)) % np.uint64(n_actions)).astype(np.int64)


def flee_actions(
    seed: np.ndarray,
    t: np.ndarray,
    evader_xy: np.ndarray,
    pursuer_xy: np.ndarray,
    n_actions: int,
    low: float,
    high: float,
) -> np.ndarray:
    """The move maximising the Manhattan distance to the nearest pursuer after the move.

    ``evader_xy`` is ``(B, 2)``, ``pursuer_xy`` ``(B, N, 2)`` (the pursuers' positions at the
    start of the step: moves are simultaneous). Moves are clipped to ``[low, high]`` as the
    arena does. Ties are broken uniformly at random by a random rank per action.
    """
    deltas = _DELTAS_F[:n_actions]
    cand = np.clip(evader_xy[:, None, :] + deltas[None], low, high)  # (B, A, 2)
    dist = np.abs(cand[:, :, None, :] - pursuer_xy[:, None, :, :]).sum(-1).min(-1)  # (B, A)
    rank = (draws(seed, t, n_actions) >> np.uint64(12)).astype(np.float64) / 2.0**52
    best = dist.max(axis=1, keepdims=True)
    score = np.where(np.isclose(dist, best, rtol=0.0, atol=1e-9), rank, -1.0)
    return score.argmax(axis=1).astype(np.int64)


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
    otherwise; ``[low, high]`` is the range the arena clips positions to.
    """
    if scenario.evader == "random":
        return random_actions(seed, t, scenario.actions)
    if scenario.evader == "flee":
        return flee_actions(seed, t, evader_xy, pursuer_xy, scenario.actions, low, high)
    return np.full(len(seed), STAY, dtype=np.int64)


_DELTAS_F = np.array([(0, 1), (0, -1), (-1, 0), (1, 0), (0, 0)], dtype=np.float64)
