"""Batched actor–critic networks for A2C and A2CM (SPEC §6).

Every pursuer observes the same global state, so one input row feeds all N actors and all
critics. Each actor is ``Linear(obs, hidden) → ReLU → Linear(hidden, n_actions)`` (softmax in
the distribution) and each critic ``Linear(obs, hidden) → ReLU → Linear(hidden, 1)``. The N
actors (and A2C's N critics) live in :class:`StackedLinear` layers whose parameters carry a
leading agent dimension, so all of them are evaluated in one batched op, not a Python loop.

- **A2C** (``shared_critic=False``): N actors and N critics, critic i learns agent i's returns.
- **A2CM** (``shared_critic=True``): N actors and ONE critic trained on the team return.

For rollouts :meth:`ActorCritic.act` samples actions from a numpy snapshot of the actor
weights (measured faster than torch for 1–16 rows; see ``backend``), refreshed automatically
whenever the torch parameters change in place (optimiser step, ``load_state_dict``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

if TYPE_CHECKING:
    from a2cm_phys.config import Scenario, Train

Backend = Literal["numpy", "torch"]


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
        obs_dim: length of the observation vector every pursuer sees.
        n_agents: number of pursuers N (one actor each).
        n_actions: size of each actor's discrete action space.
        hidden: width of the single hidden layer of every actor and critic.
        shared_critic: ``True`` for A2CM (one critic), ``False`` for A2C (N critics).
        generator: optional torch generator for a reproducible initialisation.
    """

    def __init__(
        self,
        obs_dim: int,
        n_agents: int,
        n_actions: int,
        hidden: int = 128,
        *,
        shared_critic: bool,
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        self.obs_dim, self.n_agents, self.n_actions = obs_dim, n_agents, n_actions
        self.hidden, self.shared_critic = hidden, shared_critic
        c = 1 if shared_critic else n_agents
        self.actor_hidden = StackedLinear(n_agents, obs_dim, hidden, generator)
        self.actor_out = StackedLinear(n_agents, hidden, n_actions, generator)
        self.critic_hidden = StackedLinear(c, obs_dim, hidden, generator)
        self.critic_out = StackedLinear(c, hidden, 1, generator)
        self._snapshot: tuple[np.ndarray, ...] | None = None
        self._snapshot_key: tuple[int, ...] | None = None
        self._cache_actor_params()

    @property
    def n_critics(self) -> int:
        """Number of critics C: 1 for A2CM, N for A2C."""
        return self.critic_out.n

    # ------------------------------------------------------------------ torch forward
    def policy_logits(self, obs: torch.Tensor) -> torch.Tensor:
        """Actor logits ``(..., N, n_actions)`` for observations ``(..., obs_dim)``."""
        return self.actor_out(F.relu(self.actor_hidden.forward_shared(obs)))

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        """Critic values ``(..., C)`` for observations ``(..., obs_dim)``."""
        return self.critic_out(F.relu(self.critic_hidden.forward_shared(obs))).squeeze(-1)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return ``(logits (..., N, A), values (..., C))`` for observations ``(..., obs_dim)``."""
        return self.policy_logits(obs), self.value(obs)

    # ------------------------------------------------------------------ fast rollout path
    def act(
        self,
        obs: np.ndarray,
        rng: np.random.Generator,
        greedy: bool = False,
        backend: Backend = "numpy",
    ) -> np.ndarray:
        """Pick one action per agent for each observation row, for rollouts (no autograd).

        Args:
            obs: ``(B, obs_dim)`` or ``(obs_dim,)`` observations (any float dtype).
            rng: the only source of sampling randomness; draws ``B·N·A`` Gumbel variates per
                call (none when ``greedy``), so a seeded generator gives a bit-exact run.
            greedy: take the most probable action instead of sampling.
            backend: ``"numpy"`` (default, a cached float32 copy of the actor weights) or
                ``"torch"`` (``inference_mode`` forward); both sample identically.

        Returns:
            int64 actions ``(B, N)``, or ``(N,)`` for a 1-D ``obs``.
        """
        logits = self.logits_np(obs, backend)
        if greedy:
            return logits.argmax(-1).astype(np.int64, copy=False)
        return sample_categorical(logits, rng)

    def logits_np(self, obs: np.ndarray, backend: Backend = "numpy") -> np.ndarray:
        """Actor logits as numpy ``(B, N, A)`` (or ``(N, A)`` for 1-D ``obs``), no autograd."""
        if backend == "torch":
            with torch.inference_mode():
                x = torch.as_tensor(obs, dtype=torch.float32, device=self.actor_out.weight.device)
                return self.policy_logits(x).cpu().numpy()
        w1, b1, w2, b2 = self._numpy_snapshot()
        h = np.asarray(obs, dtype=np.float32) @ w1
        h += b1
        np.maximum(h, 0.0, out=h)
        out = h @ w2
        out += b2
        return out.reshape(*out.shape[:-1], self.n_agents, self.n_actions)

    def action_probs_np(self, obs: np.ndarray, backend: Backend = "numpy") -> np.ndarray:
        """Softmax action probabilities ``(B, N, A)`` as numpy, no autograd."""
        logits = self.logits_np(obs, backend).astype(np.float64)
        e = np.exp(logits - logits.max(-1, keepdims=True))
        return e / e.sum(-1, keepdims=True)

    def refresh_snapshot(self) -> None:
        """Rebuild the numpy copy of the actor weights used by :meth:`act` now."""
        n, h, a = self.n_agents, self.hidden, self.n_actions
        with torch.no_grad():
            w1 = self.actor_hidden.weight.reshape(n * h, self.obs_dim).T.cpu().numpy()
            b1 = self.actor_hidden.bias.reshape(n * h).cpu().numpy()
            # second layer as one block-diagonal (N·H, N·A) matrix: a single small matmul
            w2 = np.zeros((n * h, n * a), dtype=np.float32)
            w2_stack = self.actor_out.weight.transpose(1, 2).cpu().numpy()  # (N, H, A)
            for i in range(n):
                w2[i * h : (i + 1) * h, i * a : (i + 1) * a] = w2_stack[i]
            b2 = self.actor_out.bias.reshape(n * a).cpu().numpy()
        self._snapshot = tuple(np.ascontiguousarray(x, dtype=np.float32) for x in (w1, b1, w2, b2))
        self._snapshot_key = self._actor_versions()

    def _actor_versions(self) -> tuple[int, ...]:
        # In-place updates (optimiser steps, load_state_dict, no_grad copies) bump the
        # version counter of a parameter, so a changed key means a stale snapshot. The
        # parameters are cached in a plain tuple: nn.Module attribute lookup costs ~1 µs each.
        return tuple(p._version for p in self._actor_params)

    def _apply(self, fn, *args, **kwargs):  # type: ignore[override]
        """Invalidate the numpy snapshot when parameters are moved or converted (``.to``)."""
        out = super()._apply(fn, *args, **kwargs)
        self._cache_actor_params()
        return out

    def _cache_actor_params(self) -> None:
        self._actor_params = (
            self.actor_hidden.weight,
            self.actor_hidden.bias,
            self.actor_out.weight,
            self.actor_out.bias,
        )
        self._snapshot = None

    def _numpy_snapshot(self) -> tuple[np.ndarray, ...]:
        if self._snapshot is None or self._snapshot_key != self._actor_versions():
            self.refresh_snapshot()
        assert self._snapshot is not None
        return self._snapshot


def sample_categorical(logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sample one index per row of ``logits (..., A)`` from ``softmax(logits)`` (Gumbel-max).

    ``argmax(logits + Gumbel noise)`` is an exact softmax sample, stable for any logit scale;
    actions with logit ``-inf`` (probability 0) are never picked. Draws exactly
    ``logits.size`` Gumbel variates from ``rng``. Returns int64 of shape ``logits.shape[:-1]``.
    """
    return (logits + rng.gumbel(size=logits.shape)).argmax(-1).astype(np.int64, copy=False)


def make_model(
    train_cfg: Train, scenario: Scenario, generator: torch.Generator | None = None
) -> ActorCritic:
    """Build the network ``train_cfg.algo`` asks for, sized by ``scenario``, on its device.

    The initial weights come from ``generator`` if given, otherwise from a torch generator
    seeded with ``train_cfg.seed`` (independent of the global torch RNG).
    """
    if generator is None:
        generator = torch.Generator().manual_seed(train_cfg.seed)
    model = ActorCritic(
        scenario.obs_dim,
        scenario.pursuers,
        scenario.actions,
        train_cfg.hidden,
        shared_critic=train_cfg.algo == "a2cm",
        generator=generator,
    )
    return model.to(train_cfg.device)
