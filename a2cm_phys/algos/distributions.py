"""Action distributions of the actors: categorical (discrete control) and diagonal Gaussian
(continuous control), as one small interface.

An actor network outputs ``n_outputs`` numbers per agent; a :class:`ActionDistribution`
turns them into a torch distribution for the learner (log-probabilities, entropy) and
samples or picks greedy actions from the same numbers in numpy for rollouts. Nothing else
in the rollout, learner, recorder or evaluation needs to know which kind it is: they ask
for ``action_shape`` and ``action_dtype``.

- :class:`CategoricalActions`: ``softmax(logits)``; sampled by Gumbel-max; greedy = argmax.
- :class:`GaussianActions`: ``Normal(mean, exp(log_std))`` per dimension with a
  state-independent learnable ``log_std`` per agent (CleanRL's ``ppo_continuous_action``,
  SB3's ``DiagGaussianDistribution``); log-probabilities of the *unclipped* sample (the env
  clips); entropy of the Gaussian; greedy = the mean.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import torch
from torch import distributions as D


class ActionDistribution(Protocol):
    """What the model, rollout and learner need to know of an action distribution."""

    n_outputs: int
    """Actor outputs per agent (logits, or means)."""
    action_shape: tuple[int, ...]
    """Shape of one agent's action: ``()`` for discrete, ``(dim,)`` for continuous."""
    action_dtype: np.dtype
    """int64 for discrete actions, float32 for continuous ones."""
    has_log_std: bool
    """Whether the model carries a learnable ``log_std`` per agent."""

    def torch(self, out: torch.Tensor, log_std: torch.Tensor | None) -> D.Distribution:
        """The distribution of ``out (..., N, n_outputs)`` with batch shape ``(..., N)``."""
        ...

    def sample(self, out: np.ndarray, log_std: np.ndarray | None, rng: np.random.Generator):
        """Sampled actions ``(..., N, *action_shape)``; ``rng`` is the only randomness."""
        ...

    def greedy(self, out: np.ndarray) -> np.ndarray:
        """The most probable actions ``(..., N, *action_shape)``."""
        ...


class CategoricalActions:
    """``softmax(logits)`` over ``n_actions`` discrete actions."""

    has_log_std = False
    action_shape: tuple[int, ...] = ()
    action_dtype = np.dtype(np.int64)

    def __init__(self, n_actions: int) -> None:
        self.n_outputs = n_actions

    def torch(self, out: torch.Tensor, log_std: torch.Tensor | None = None) -> D.Categorical:
        """``Categorical(logits=out)``, unvalidated: the learner checks the loss for NaN
        itself, and on a batch of 128 steps torch's argument checks cost about 80 µs of the
        220 µs that building the distribution and its log-probabilities and entropy take."""
        return D.Categorical(logits=out, validate_args=False)

    def sample(
        self, out: np.ndarray, log_std: np.ndarray | None, rng: np.random.Generator
    ) -> np.ndarray:
        """Exact softmax samples by Gumbel-max (see :func:`sample_categorical`)."""
        return sample_categorical(out, rng)

    def greedy(self, out: np.ndarray) -> np.ndarray:
        """``argmax`` of the logits."""
        return out.argmax(-1).astype(np.int64, copy=False)


class GaussianActions:
    """Independent ``Normal(mean, exp(log_std))`` per action dimension."""

    has_log_std = True
    action_dtype = np.dtype(np.float32)

    def __init__(self, dim: int) -> None:
        self.n_outputs = dim
        self.action_shape = (dim,)

    def torch(self, out: torch.Tensor, log_std: torch.Tensor | None) -> D.Independent:
        """A diagonal Gaussian: log-probabilities and entropies summed over dimensions."""
        assert log_std is not None
        normal = D.Normal(out, log_std.expand_as(out).exp(), validate_args=False)
        return D.Independent(normal, 1, validate_args=False)

    def sample(
        self, out: np.ndarray, log_std: np.ndarray | None, rng: np.random.Generator
    ) -> np.ndarray:
        """``mean + std · ε`` with ``ε`` standard normal from ``rng`` (unclipped)."""
        assert log_std is not None
        noise = rng.standard_normal(out.shape, dtype=np.float32)
        return (out + np.exp(log_std) * noise).astype(np.float32, copy=False)

    def greedy(self, out: np.ndarray) -> np.ndarray:
        """The mean."""
        return out.astype(np.float32, copy=False)


def sample_categorical(logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sample one index per row of ``logits (..., A)`` from ``softmax(logits)`` (Gumbel-max).

    ``argmax(logits + Gumbel noise)`` is an exact softmax sample, stable for any logit scale;
    actions with logit ``-inf`` (probability 0) are never picked. Draws exactly
    ``logits.size`` Gumbel variates from ``rng``. Returns int64 of shape ``logits.shape[:-1]``.
    """
    return (logits + rng.gumbel(size=logits.shape)).argmax(-1).astype(np.int64, copy=False)
