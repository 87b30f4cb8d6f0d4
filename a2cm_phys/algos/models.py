"""Batched actor–critic networks for A2C and A2CM (SPEC §6).

Every pursuer observes the same global state, so one input row feeds all N actors and all
critics. Each actor is ``Linear(obs, hidden) → ReLU → Linear(hidden, n_actions)`` (softmax in
the distribution) and each critic ``Linear(obs, hidden) → ReLU → Linear(hidden, 1)``. The N
actors (and A2C's N critics) live in :class:`StackedLinear` layers whose parameters carry a
leading agent dimension, so all of them are evaluated in one batched op, not a Python loop.

- **A2C** (``shared_critic=False``): N actors and N critics, critic i learns agent i's returns.
- **A2CM** (``shared_critic=True``): N actors and ONE critic trained on the team return.

All parameters live in one contiguous float buffer (:meth:`ActorCritic.packed`), laid out so
that the first layers of every actor and critic form a single ``(K·H, obs_dim)`` matrix: the
learner's fast path (:mod:`a2cm_phys.algos.learner`) evaluates and differentiates the whole
network with a handful of matmuls and steps RMSprop on the buffer in one go. They remain
separate ``nn.Parameter`` objects (names, shapes and counts as without the packing).

For rollouts :meth:`ActorCritic.act` samples actions from a numpy snapshot of the actor
weights (measured faster than torch for 1–16 rows; see ``backend``), refreshed automatically
whenever the torch parameters change in place (optimiser step, ``load_state_dict``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal, NamedTuple

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


class PackedParams(NamedTuple):
    """Views of one flat buffer laid out like :meth:`ActorCritic.packed` (K = N + C)."""

    flat: torch.Tensor
    """Every parameter, contiguous: the order of the fields below."""
    w1: torch.Tensor
    """``(K·H, obs_dim)``: ``actor_hidden.weight`` rows, then ``critic_hidden.weight`` rows."""
    b1: torch.Tensor
    """``(K·H,)``: ``actor_hidden.bias`` then ``critic_hidden.bias``."""
    w2_actor: torch.Tensor
    """``(N, A, H)``: ``actor_out.weight``."""
    w2_critic: torch.Tensor
    """``(C, 1, H)``: ``critic_out.weight``."""
    b2: torch.Tensor
    """``(N·A + C,)``: ``actor_out.bias`` then ``critic_out.bias``."""


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
        self._pack_parameters()
        self._snapshot: tuple[np.ndarray, ...] | None = None
        self._snapshot_arrays: tuple[np.ndarray, ...] | None = None  # reused by every refresh
        self._snapshot_key: tuple[int, ...] | None = None
        self._cache_actor_params()

    @property
    def n_critics(self) -> int:
        """Number of critics C: 1 for A2CM, N for A2C."""
        return self.critic_out.n

    # ------------------------------------------------------------------ packed parameters
    def _pack_parameters(self) -> None:
        """Re-home every parameter (values unchanged) into one contiguous buffer ``_flat``.

        Each parameter becomes a new ``nn.Parameter`` viewing its slice of the buffer, so it
        also shares the buffer's version counter. Done at construction, before any optimiser
        holds the parameters.
        """
        ah, ch, ao, co = self.actor_hidden, self.critic_hidden, self.actor_out, self.critic_out
        slots = (  # the field order of PackedParams
            (ah, "weight"),
            (ch, "weight"),
            (ah, "bias"),
            (ch, "bias"),
            (ao, "weight"),
            (co, "weight"),
            (ao, "bias"),
            (co, "bias"),
        )
        old = [getattr(layer, name) for layer, name in slots]
        flat = torch.empty(sum(p.numel() for p in old), dtype=old[0].dtype, device=old[0].device)
        views = self._split(flat)
        with torch.no_grad():
            for view, p in zip(views, old, strict=True):
                view.copy_(p)
        for (layer, name), view, p in zip(slots, views, old, strict=True):
            setattr(layer, name, nn.Parameter(view, requires_grad=p.requires_grad))
        self._flat = flat
        self._flat_slots = tuple((layer._parameters, name) for layer, name in slots)
        self._flat_params = tuple(getattr(layer, name) for layer, name in slots)
        self._flat_offsets = tuple(v.data_ptr() - flat.data_ptr() for v in views)  # bytes
        self._packed = self.packed_views(flat)

    def _split(self, buffer: torch.Tensor) -> list[torch.Tensor]:
        """Per-parameter views of a packed buffer, in :class:`PackedParams` field order."""
        n, c, h, a, d = self.n_agents, self.n_critics, self.hidden, self.n_actions, self.obs_dim
        shapes = ((n, h, d), (c, h, d), (n, h), (c, h), (n, a, h), (c, 1, h), (n, a), (c, 1))
        sizes = [math.prod(shape) for shape in shapes]
        return [part.view(shape) for part, shape in zip(buffer.split(sizes), shapes, strict=True)]

    def packed_views(self, buffer: torch.Tensor) -> PackedParams:
        """View a flat buffer of ``_flat``'s size with the packed layout (e.g. gradients)."""
        kh = (self.n_agents + self.n_critics) * self.hidden
        d, b2_size = self.obs_dim, self.n_agents * self.n_actions + self.n_critics
        parts = self._split(buffer)
        return PackedParams(
            flat=buffer,
            w1=buffer[: kh * d].view(kh, d),
            b1=buffer[kh * d : kh * (d + 1)],
            w2_actor=parts[4],
            w2_critic=parts[5],
            b2=buffer[buffer.numel() - b2_size :],
        )

    def param_views(self, buffer: torch.Tensor) -> list[tuple[nn.Parameter, torch.Tensor]]:
        """``(parameter, its slice of buffer)`` pairs, e.g. to make gradients packed views."""
        return list(zip(self._flat_params, self._split(buffer), strict=True))

    def packed(self) -> PackedParams | None:
        """Views of the buffer holding every parameter, or ``None`` if it no longer does.

        The packing is lost when parameters are replaced or converted (``.to(dtype)``, a move
        to another device, ``load_state_dict(assign=True)``); the model still works, only the
        learner's fast path needs it.
        """
        base = self._flat.data_ptr()
        for (params, name), p, offset in zip(
            self._flat_slots, self._flat_params, self._flat_offsets, strict=True
        ):
            if params[name] is not p or p.data_ptr() != base + offset:
                return None
        return self._packed

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
        n, h, a, d = self.n_agents, self.hidden, self.n_actions, self.obs_dim
        if self._snapshot_arrays is None:
            # the second layer as one block-diagonal (N·H, N·A) matrix: a single small matmul
            w2 = np.zeros((n * h, n * a), dtype=np.float32)
            row, item = w2.strides[0], w2.itemsize
            blocks = np.lib.stride_tricks.as_strided(
                w2, (n, h, a), (h * row + a * item, row, item), writeable=True
            )  # blocks[i] is agent i's (H, A) diagonal block
            self._snapshot_arrays = (
                np.empty((d, n * h), dtype=np.float32),
                np.empty(n * h, dtype=np.float32),
                w2,
                np.empty(n * a, dtype=np.float32),
                blocks,
            )
        w1, b1, w2, b2, blocks = self._snapshot_arrays
        with torch.no_grad():
            t_w1, t_b1, t_w2, t_b2 = (p.detach().cpu().numpy() for p in self._actor_params)
        np.copyto(w1, t_w1.reshape(n * h, d).T)
        np.copyto(b1, t_b1.reshape(n * h))
        np.copyto(blocks, t_w2.transpose(0, 2, 1))
        np.copyto(b2, t_b2.reshape(n * a))
        self._snapshot = (w1, b1, w2, b2)
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
