"""Every random stream of a run, derived from its one seed (defined here once).

A run's ``seed`` seeds the games (``VectorEnv.reset(seed)``: each game's episodes draw
their seeds from it) and, through numpy's ``SeedSequence`` with a stream number, each
other source of randomness, so that adding one stream never shifts another:

| stream | what it draws |
|---|---|
| 1 | the pursuers' (and a learned evader's) actions: :func:`policy_rng` |
| 2 | a learned evader's initial weights: :func:`evader_weights_generator` |
| 3 | the opponent pool's draws (:func:`opponent_rng`); the descent's visits (:func:`descent_rng`) |
| 4 | the evader's descent visits: :func:`evader_descent_rng` |

The pool and the descent share stream 3, as they did before this module gathered the
streams (each has its own generator; changing either would change existing runs).
"""

from __future__ import annotations

import numpy as np
import torch


def policy_rng(seed: int) -> np.random.Generator:
    """The action-sampling generator of a run, independent of the env's seed stream."""
    return np.random.default_rng([seed, 1])


def evader_weights_generator(seed: int) -> torch.Generator:
    """A torch generator for a learned evader's initial weights, independent of the
    pursuers'."""
    state = np.random.SeedSequence([seed, 2]).generate_state(1, np.uint64)[0]
    return torch.Generator().manual_seed(int(state))


def opponent_rng(seed: int) -> np.random.Generator:
    """The opponent pool's generator (which snapshot plays which update)."""
    return np.random.default_rng([seed, 3])


def descent_rng(seed: int) -> np.random.Generator:
    """The pursuers' exploitability descent's generator (which states it visits)."""
    return np.random.default_rng([seed, 3])


def evader_descent_rng(seed: int) -> np.random.Generator:
    """The evader's exploitability descent's generator: its own stream, so that the
    pursuers' descent is the same whether the evader's runs or not."""
    return np.random.default_rng([seed, 4])
