"""Batched actor–critic networks for A2C and A2CM (SPEC §6).

Every agent of a team observes the same global state, so one input row feeds all N actors
and all critics. Each actor is ``Linear(obs, hidden) → ReLU → Linear(hidden, n_outputs)``
and each critic ``Linear(obs, hidden) → ReLU → Linear(hidden, n_values)`` (the paper's
networks, SPEC §6). The N actors (and A2C's N critics) live in :class:`StackedLinear`
layers whose parameters carry a leading agent dimension, so all of them are evaluated in
one batched op, not a Python loop.

Two options go beyond the paper (``Train.layers``, ``Train.encoding``): more hidden layers
of the same width, and, on grids, the input as one one-hot of each coordinate's cell
(:class:`OneHotCells`) instead of the coordinates themselves. With the defaults (one layer,
the raw observation) the networks are the paper's, weight for weight.

- **A2C** (``shared_critic=False``): N actors and N critics, critic i learns agent i's returns.
- **A2CM** (``shared_critic=True``): N actors and ONE critic trained on the team return.

The only difference between the two is the critic's shape. What an actor's outputs mean is
the :mod:`~a2cm_phys.algos.distributions` object's business: logits of a categorical
(discrete control) or the mean of a diagonal Gaussian with a learnable state-independent
``log_std`` per agent (continuous control). A critic may predict several values per state
(``n_values``): one per reward component, when the learner splits the team reward.

For rollouts :meth:`ActorCritic.act` computes the actor outputs from a numpy snapshot of
the actor weights (several times faster than torch for 1–64 rows), refreshed automatically
whenever the torch parameters change in place (optimiser step, ``load_state_dict``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import distributions as D
from torch import nn

from ..envs.core import REWARD_PARTS
from .distributions import (
    ActionDistribution,
    CategoricalActions,
    GaussianActions,
    sample_categorical,
)

if TYPE_CHECKING:
    from ..config import Scenario, Train

__all__ = ["ActorCritic", "OneHotCells", "StackedLinear", "make_model", "sample_categorical"]


class OneHotCells:
    """A grid observation (SPEC §5: every coordinate divided by ``size − 1``) as one one-hot
    vector of ``size`` per coordinate: ``(..., d) → (..., d · size)``. A network then tells
    "next to the evader" from "two cells away" with one weight per cell, where the raw
    coordinates make it carve the arena with ReLUs."""

    def __init__(self, size: int) -> None:
        if size < 2:
            raise ValueError(f"one-hot cells need an arena of size >= 2, got {size}")
        self.size = size
        self._eye = np.eye(size, dtype=np.float32)

    def features(self, obs_dim: int) -> int:
        """Length of the encoded input."""
        return obs_dim * self.size

    def torch(self, obs: torch.Tensor) -> torch.Tensor:
        """Encode a float tensor of observations."""
        cells = torch.round(obs * (self.size - 1)).long().clamp_(0, self.size - 1)
        return F.one_hot(cells, self.size).to(obs.dtype).flatten(-2)

    def numpy(self, obs: np.ndarray) -> np.ndarray:
        """Encode observations in numpy (float32), as :meth:`torch` does."""
        cells = np.rint(np.asarray(obs, dtype=np.float32) * (self.size - 1)).astype(np.intp)
        np.clip(cells, 0, self.size - 1, out=cells)
        return self._eye[cells].reshape(*cells.shape[:-1], -1)


class StackedLinear(nn.Module):
    """``n`` independent dense layers ``in_features → out_features`` with stacked parameters.

    ``weight`` has shape ``(n, out_features, in_features)`` and ``bias`` ``(n, out_features)``;
    slice ``i`` is initialised exactly as ``nn.Linear(in_features, out_features)`` would be
    (kaiming-uniform weight with ``a=√5``, bias uniform in ``±1/√in_features``).
    """

    def __init__(
        self,
        n: int,
        in_features: int,
        out_features: int,
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        self.n, self.in_features, self.out_features = n, in_features, out_features
        self.weight = nn.Parameter(torch.empty(n, out_features, in_features))
        self.bias = nn.Parameter(torch.empty(n, out_features))
        self.reset_parameters(generator)

    def reset_parameters(self, generator: torch.Generator | None = None) -> None:
        """Initialise every slice like ``nn.Linear.reset_parameters``."""
        bound = 1.0 / math.sqrt(self.in_features)
        with torch.no_grad():
            for i in range(self.n):
                nn.init.kaiming_uniform_(self.weight[i], a=math.sqrt(5), generator=generator)
                nn.init.uniform_(self.bias[i], -bound, bound, generator=generator)

    def forward_shared(self, x: torch.Tensor) -> torch.Tensor:
        """Apply all ``n`` layers to the same input: ``(..., in) → (..., n, out)`` (one matmul)."""
        flat = F.linear(
            x,
            self.weight.reshape(self.n * self.out_features, self.in_features),
            self.bias.reshape(self.n * self.out_features),
        )
        return flat.unflatten(-1, (self.n, self.out_features))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Apply layer ``i`` to row ``i`` of the agent dim: ``(..., n, in) → (..., n, out)``."""
        return torch.einsum("...ni,noi->...no", x, self.weight) + self.bias

    def extra_repr(self) -> str:
        """Shape summary shown by ``print(module)``."""
        return f"n={self.n}, in_features={self.in_features}, out_features={self.out_features}"


class ActorCritic(nn.Module):
    """N actors and C critics (C = 1 for A2CM, C = N for A2C) over one global observation.

    Args:
        obs_dim: length of the observation vector every agent sees.
        n_agents: number of agents N (one actor each).
        actions: the action distribution, or an int ``A`` for ``A`` discrete actions.
        hidden: width of the hidden layers of every actor and critic.
        shared_critic: ``True`` for A2CM (one critic), ``False`` for A2C (N critics).
        n_values: values each critic predicts (one per reward component).
        log_std_init: initial ``log_std`` of Gaussian actors.
        generator: optional torch generator for a reproducible initialisation.
        layers: hidden layers of every actor and critic (the paper's: 1).
        encoding: the networks' input: the observation itself, or :class:`OneHotCells`.
    """

    def __init__(
        self,
        obs_dim: int,
        n_agents: int,
        actions: ActionDistribution | int,
        hidden: int = 128,
        *,
        shared_critic: bool,
        n_values: int = 1,
        log_std_init: float = 0.0,
        generator: torch.Generator | None = None,
        layers: int = 1,
        encoding: OneHotCells | None = None,
    ) -> None:
        super().__init__()
        if layers < 1:
            raise ValueError(f"layers must be >= 1, got {layers}")
        dist = CategoricalActions(actions) if isinstance(actions, int) else actions
        self.dist = dist
        self.obs_dim, self.n_agents, self.hidden = obs_dim, n_agents, hidden
        self.shared_critic, self.n_values = shared_critic, n_values
        self.encoding = encoding
        inputs = obs_dim if encoding is None else encoding.features(obs_dim)
        c = 1 if shared_critic else n_agents
        self.actor_hidden = StackedLinear(n_agents, inputs, hidden, generator)
        self.actor_out = StackedLinear(n_agents, hidden, dist.n_outputs, generator)
        self.critic_hidden = StackedLinear(c, inputs, hidden, generator)
        self.critic_out = StackedLinear(c, hidden, n_values, generator)
        # Layers beyond the first are made last, so that one layer draws the paper's weights.
        self.actor_deep = nn.ModuleList(
            StackedLinear(n_agents, hidden, hidden, generator) for _ in range(layers - 1)
        )
        self.critic_deep = nn.ModuleList(
            StackedLinear(c, hidden, hidden, generator) for _ in range(layers - 1)
        )
        self.log_std = (
            nn.Parameter(torch.full((n_agents, dist.n_outputs), float(log_std_init)))
            if dist.has_log_std
            else None
        )
        self._snapshot: tuple[Any, ...] | None = None
        self._snapshot_key: tuple[int, ...] | None = None
        self._cache_actor_params()

    @property
    def n_critics(self) -> int:
        """Number of critics C: 1 for A2CM, N for A2C."""
        return self.critic_out.n

    @property
    def n_actions(self) -> int:
        """Actor outputs per agent (the number of discrete actions, or the command's size)."""
        return self.dist.n_outputs

    # ------------------------------------------------------------------ torch forward
    @property
    def layers(self) -> int:
        """Hidden layers of every actor and critic."""
        return 1 + len(self.actor_deep)

    def _input(self, obs: torch.Tensor) -> torch.Tensor:
        return obs if self.encoding is None else self.encoding.torch(obs)

    def actor_outputs(self, obs: torch.Tensor) -> torch.Tensor:
        """Actor outputs ``(..., N, n_outputs)`` (logits or means) for ``(..., obs_dim)``."""
        h = F.relu(self.actor_hidden.forward_shared(self._input(obs)))
        for layer in self.actor_deep:
            h = F.relu(layer(h))
        return self.actor_out(h)


    def distribution(self, obs: torch.Tensor) -> D.Distribution:
        """The policy of every agent at ``obs``: a distribution of batch shape ``(..., N)``."""
        return self.dist.torch(self.actor_outputs(obs), self.log_std)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        """Critic outputs ``(..., C)``, or ``(..., C, n_values)`` when ``n_values > 1``."""
        h = F.relu(self.critic_hidden.forward_shared(self._input(obs)))
        for layer in self.critic_deep:
            h = F.relu(layer(h))
        out = self.critic_out(h)
        return out.squeeze(-1) if self.n_values == 1 else out

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(actor outputs (..., N, n_outputs), values)`` for observations ``(..., obs_dim)``."""
        return self.actor_outputs(obs), self.value(obs)

    # ------------------------------------------------------------------ fast rollout path
    def act(self, obs: np.ndarray, rng: np.random.Generator, greedy: bool = False) -> np.ndarray:
        """One action per agent for each observation row, for rollouts (no autograd).

        Args:
            obs: ``(B, obs_dim)`` or ``(obs_dim,)`` observations (any float dtype).
            rng: the only source of sampling randomness (unused when ``greedy``), so a
                seeded generator gives a bit-exact run.
            greedy: the most probable action (argmax, or the Gaussian's mean).

        Returns:
            Actions ``(B, N, *action_shape)`` (``(N, ...)`` for a 1-D ``obs``), int64 for
            discrete actions, float32 (unclipped) for continuous ones.
        """
        out = self.outputs_np(obs)
        if greedy:
            return self.dist.greedy(out)
        return self.dist.sample(out, self._snapshot_log_std, rng)

    def outputs_np(self, obs: np.ndarray) -> np.ndarray:
        """Actor outputs as numpy ``(B, N, n_outputs)`` (``(N, n_outputs)`` for 1-D ``obs``)."""
        w1, b1, w2, b2, deep = self._numpy_snapshot()
        x = np.asarray(obs, dtype=np.float32)
        if self.encoding is not None:
            x = self.encoding.numpy(x)
        h = x @ w1
        h += b1
        np.maximum(h, 0.0, out=h)
        if deep:  # agent by agent: (N, B, H) through each agent's own weights
            lead = h.shape[:-1]
            h = np.moveaxis(h.reshape(-1, self.n_agents, self.hidden), 1, 0)
            for w, b in deep:
                h = np.matmul(h, w)
                h += b
                np.maximum(h, 0.0, out=h)
            h = np.moveaxis(h, 0, 1).reshape(*lead, self.n_agents * self.hidden)
        out = h @ w2
        out += b2
        return out.reshape(*out.shape[:-1], self.n_agents, self.dist.n_outputs)

    def action_probs_np(self, obs: np.ndarray) -> np.ndarray:
        """Softmax action probabilities ``(B, N, A)`` of discrete actors, as numpy float64."""
        if not isinstance(self.dist, CategoricalActions):
            raise TypeError("action probabilities exist for discrete actions only")
        logits = self.outputs_np(obs).astype(np.float64)
        e = np.exp(logits - logits.max(-1, keepdims=True))
        return e / e.sum(-1, keepdims=True)

    def refresh_snapshot(self) -> None:
        """Rebuild the numpy copy of the actor weights used by :meth:`act` now."""
        n, h, o = self.n_agents, self.hidden, self.dist.n_outputs
        d = self.actor_hidden.in_features
        with torch.no_grad():
            t_w1, t_b1, t_w2, t_b2 = (p.detach().cpu().numpy() for p in self._actor_params[:4])
            deep = [
                (
                    np.ascontiguousarray(layer.weight.detach().cpu().numpy().transpose(0, 2, 1)),
                    layer.bias.detach().cpu().numpy()[:, None, :].copy(),
                )
                for layer in self.actor_deep
            ]
            log_std = self.log_std
            self._snapshot_log_std = (
                None if log_std is None else log_std.detach().cpu().numpy().copy()
            )
        # the second layer as one block-diagonal (N·H, N·O) matrix: a single small matmul
        w2 = np.zeros((n * h, n * o), dtype=np.float32)
        for i in range(n):
            w2[i * h : (i + 1) * h, i * o : (i + 1) * o] = t_w2[i].T
        self._snapshot = (
            np.ascontiguousarray(t_w1.reshape(n * h, d).T),
            t_b1.reshape(n * h).copy(),
            w2,
            t_b2.reshape(n * o).copy(),
            deep,
        )
        self._snapshot_key = self._actor_versions()

    def _actor_versions(self) -> tuple[int, ...]:
        # In-place updates (optimiser steps, load_state_dict, no_grad copies) bump the
        # version counter of a parameter, so a changed key means a stale snapshot.
        return tuple(p._version for p in self._actor_params)

    def _apply(self, fn, *args, **kwargs):  # type: ignore[override]
        """Invalidate the numpy snapshot when parameters are moved or converted (``.to``)."""
        out = super()._apply(fn, *args, **kwargs)
        self._cache_actor_params()
        return out

    def _cache_actor_params(self) -> None:
        params = [
            self.actor_hidden.weight,
            self.actor_hidden.bias,
            self.actor_out.weight,
            self.actor_out.bias,
        ]
        for layer in self.actor_deep:
            params += [layer.weight, layer.bias]
        if self.log_std is not None:
            params.append(self.log_std)
        self._actor_params = tuple(params)
        self._snapshot = None
        self._snapshot_log_std = None

    def _numpy_snapshot(self) -> tuple[Any, ...]:
        if self._snapshot is None or self._snapshot_key != self._actor_versions():
            self.refresh_snapshot()
        assert self._snapshot is not None
        return self._snapshot


def action_distribution(scenario: Scenario) -> ActionDistribution:
    """The actors' distribution for a scenario: categorical over its discrete actions, or a
    diagonal Gaussian over the 2-D velocity command of continuous control."""
    if getattr(scenario, "control", "discrete") == "continuous":
        return GaussianActions(2)
    return CategoricalActions(scenario.actions)


def make_model(
    train_cfg: Train,
    scenario: Scenario,
    generator: torch.Generator | None = None,
    *,
    n_agents: int | None = None,
    shared_critic: bool | None = None,
) -> ActorCritic:
    """Build the network ``train_cfg.algo`` asks for, sized by ``scenario``, on its device.

    ``n_agents`` defaults to the scenario's pursuers and ``shared_critic`` to A2CM's (a
    team of one, such as a learned evader, passes its own). The initial weights come from
    ``generator`` if given, otherwise from a torch generator seeded with ``train_cfg.seed``
    (independent of the global torch RNG). With ``split_rewards`` each critic predicts one
    value per reward component (:data:`~a2cm_phys.envs.core.REWARD_PARTS`).
    """
    from ..config import resolve_train

    if generator is None:
        generator = torch.Generator().manual_seed(train_cfg.seed)
    model = ActorCritic(
        scenario.obs_dim,
        scenario.pursuers if n_agents is None else n_agents,
        action_distribution(scenario),
        train_cfg.hidden,
        shared_critic=train_cfg.algo == "a2cm" if shared_critic is None else shared_critic,
        n_values=len(REWARD_PARTS) if train_cfg.split_rewards else 1,
        log_std_init=resolve_train(scenario, train_cfg).log_std_init,
        generator=generator,
        layers=train_cfg.layers,
        encoding=OneHotCells(scenario.size) if train_cfg.encoding == "onehot" else None,
    )
    return model.to(train_cfg.device)
