"""Recurrent actors (``Train.recurrent = "gru"``): a team whose agents remember (SPEC §6c).

When each pursuer senses only what is near (SPEC §6b), what it saw a few steps ago still
says where the evader is. Each actor of :class:`RecurrentActorCritic` puts a GRU cell
between its hidden layers and its output layer::

    observation → Linear → ReLU (→ deeper layers) → GRU cell (memory h) → Linear → outputs

and carries ``h`` from step to step of an episode; ``h`` starts at zero with every episode.
The N cells live in one :class:`StackedGRUCell`, evaluated in one batched op as the stacked
dense layers are.

The critics: A2CM's one shared critic reads the global state, as without memory (the state
is all there is to know, and the critic is not needed to act: centralised training,
decentralised execution). A2C's critic i reads what actor i reads and actor i's memory
(detached: the critic's loss does not train the actor's memory).

**Rollouts** go through :class:`RecurrentPolicy`, a policy with memory: it keeps ``h`` of
every game between calls and forgets a game's when its episode ends. The trainer writes the
memories at the start of each rollout into the batch (``batch["memory"]``, ``(B, N, H)``)
and the checkpoint, so a resumed run continues bit for bit.

**Learning**: :func:`learner_inputs` recomputes the rollout's memories with autograd from
the batch's first memories (truncated back-propagation through time over the rollout's
``batch_size / num_envs`` steps), resetting them where an episode ended, and gives the
learner each observation with the memory it was acted on (``obs ⊕ h``). The learner's pieces
then run as for any model: :meth:`RecurrentActorCritic.actor_outputs` reads the memory part,
and the values of the state after each step (the next observation, a truncated episode's
final observation, the observation after the batch) get the memory that state would have.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .models import ActorCritic, agent_mlp, input_view

__all__ = ["RecurrentActorCritic", "RecurrentPolicy", "StackedGRUCell", "learner_inputs"]


class StackedGRUCell(nn.Module):
    """``n`` independent GRU cells ``in_features → hidden``, computed as
    :class:`torch.nn.GRUCell` computes one (same gates, same initialisation bounds), with
    the agents' parameters stacked: ``weight_ih (n, 3·hidden, in)``, ``weight_hh (n,
    3·hidden, hidden)``, biases ``(n, 3·hidden)``, gates in torch's order (reset, update,
    new)."""

    def __init__(
        self, n: int, in_features: int, hidden: int, generator: torch.Generator | None = None
    ) -> None:
        super().__init__()
        self.n, self.in_features, self.hidden = n, in_features, hidden
        self.weight_ih = nn.Parameter(torch.empty(n, 3 * hidden, in_features))
        self.weight_hh = nn.Parameter(torch.empty(n, 3 * hidden, hidden))
        self.bias_ih = nn.Parameter(torch.empty(n, 3 * hidden))
        self.bias_hh = nn.Parameter(torch.empty(n, 3 * hidden))
        bound = 1.0 / math.sqrt(hidden)
        with torch.no_grad():
            for p in (self.weight_ih, self.weight_hh, self.bias_ih, self.bias_hh):
                nn.init.uniform_(p, -bound, bound, generator=generator)

    def forward(self, x: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """The next memory ``(..., n, hidden)`` of inputs ``(..., n, in)`` and memory ``h``."""
        gi = torch.einsum("...ni,noi->...no", x, self.weight_ih) + self.bias_ih
        gh = torch.einsum("...ni,noi->...no", h, self.weight_hh) + self.bias_hh
        i_r, i_z, i_n = gi.chunk(3, -1)
        h_r, h_z, h_n = gh.chunk(3, -1)
        reset = torch.sigmoid(i_r + h_r)
        update = torch.sigmoid(i_z + h_z)
        new = torch.tanh(i_n + reset * h_n)
        return new + update * (h - new)

    def extra_repr(self) -> str:
        """Shape summary shown by ``print(module)``."""
        return f"n={self.n}, in_features={self.in_features}, hidden={self.hidden}"


class RecurrentActorCritic(ActorCritic):
    """:class:`~a2cm_phys.algos.models.ActorCritic` whose actors remember (module docstring).

    Takes :class:`ActorCritic`'s arguments. The memory has ``hidden`` numbers per agent.
    Its torch methods read observations extended by the memory they were acted on,
    ``obs ⊕ h`` (:meth:`with_memory`): ``(..., obs_dim + N · hidden)``.
    """

    recurrent = True

    def __init__(self, obs_dim: int, n_agents: int, actions: Any, hidden: int = 128, **kw) -> None:
        own = not kw["shared_critic"]
        super().__init__(
            obs_dim, n_agents, actions, hidden, critic_memory=hidden if own else 0, **kw
        )
        self.actor_memory = StackedGRUCell(n_agents, hidden, hidden, kw.get("generator"))

    def memory_shape(self, games: int) -> tuple[int, int, int]:
        """The shape of ``games`` games' memories: ``(games, N, hidden)``."""
        return (games, self.n_agents, self.hidden)

    def with_memory(self, obs: torch.Tensor, memory: torch.Tensor) -> torch.Tensor:
        """``obs (..., obs_dim) ⊕ memory (..., N, hidden)``: what the torch methods read."""
        return torch.cat([obs, memory.flatten(-2)], -1)

    def split(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(obs, memory (..., N, hidden))`` of :meth:`with_memory`'s rows."""
        memory = x[..., self.obs_dim :].unflatten(-1, (self.n_agents, self.hidden))
        return x[..., : self.obs_dim], memory

    def features(self, obs: torch.Tensor) -> torch.Tensor:
        """What the actors' layers before the memory make of ``obs``: ``(..., N, hidden)``."""
        x, own = input_view(self.sensed, obs, self.n_agents)
        x = self._input(x)
        h = F.relu(self.actor_hidden(x) if own else self.actor_hidden.forward_shared(x))
        for layer in self.actor_deep:
            h = F.relu(layer(h))
        return h

    def remember(self, obs: torch.Tensor, memory: torch.Tensor) -> torch.Tensor:
        """The memory after reading ``obs (..., obs_dim)`` with ``memory (..., N, hidden)``."""
        return self.actor_memory(self.features(obs), memory)

    def memories(self, obs: torch.Tensor, first: torch.Tensor, starts: torch.Tensor):
        """The memories ``(T, B, N, hidden)`` each step of a rollout acted on: from ``first``
        (the memories before step 0), reset to zero before step ``t`` where ``starts[t]``
        (``(T, B)`` bool: a new episode began)."""
        feats = self.features(obs)
        keep = (~starts).to(feats.dtype)[..., None, None]
        h, out = first, []
        for t in range(len(obs)):
            h = self.actor_memory(feats[t], h * keep[t])
            out.append(h)
        return torch.stack(out)

    def actor_outputs(self, x: torch.Tensor) -> torch.Tensor:
        """Actor outputs ``(..., N, n_outputs)`` of ``obs ⊕ memory`` rows."""
        return self.actor_out(self.split(x)[1])

    def value(self, x: torch.Tensor) -> torch.Tensor:
        """Critic outputs of ``obs ⊕ memory`` rows: A2CM's of the state, A2C's critic i of
        what actor i reads and its (detached) memory."""
        obs, memory = self.split(x)
        if self.shared_critic:
            return super().value(obs)
        seen, own = input_view(self.sensed, obs, self.n_agents)
        seen = self._input(seen)
        if not own:
            seen = seen.unsqueeze(-2).expand(*seen.shape[:-1], self.n_agents, seen.shape[-1])
        x = torch.cat([seen, memory.detach()], -1)
        out = agent_mlp(self.critic_hidden, self.critic_deep, self.critic_out, x, True)
        return out.squeeze(-1) if self.n_values == 1 else out

    def act(self, obs: np.ndarray, rng: np.random.Generator, greedy: bool = False) -> np.ndarray:
        """Refused: recurrent actors act through :meth:`rollout_policy` (they remember)."""
        raise TypeError("recurrent actors act through rollout_policy(), which keeps memory")

    def rollout_policy(self, greedy: bool = False) -> RecurrentPolicy:
        """A :class:`RecurrentPolicy` of these actors (its memory starts empty)."""
        return RecurrentPolicy(self, greedy)


class RecurrentPolicy:
    """Recurrent actors as a rollout policy with memory (``policy(obs, rng) -> actions``).

    :attr:`memory` holds every game's memory ``(B, N, hidden)`` float32 between calls (zero
    at the first call, or for ``B`` games other than the last call's); whoever steps the
    games calls :meth:`episodes_ended` after each step, which forgets the finished games'.
    """

    def __init__(self, model: RecurrentActorCritic, greedy: bool = False) -> None:
        self.model, self.greedy = model, greedy
        self.memory: np.ndarray | None = None

    def __call__(self, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """One action per agent of each game ``(B, N, ...)``; moves the memories on."""
        model = self.model
        obs = np.asarray(obs, dtype=np.float32)
        memory = self.start(len(obs))
        device = next(model.parameters()).device
        with torch.no_grad():
            h = model.remember(
                torch.as_tensor(obs, device=device), torch.as_tensor(memory, device=device)
            )
            out = model.actor_out(h).cpu().numpy()
        self.memory = h.cpu().numpy()
        if self.greedy:
            return model.dist.greedy(out)
        log_std = None if model.log_std is None else model.log_std.detach().cpu().numpy()
        return model.dist.sample(out, log_std, rng)

    def episodes_ended(self, ended: np.ndarray) -> None:
        """Forget the memories of the games whose episode just ended."""
        if self.memory is not None:
            self.memory[np.asarray(ended, dtype=bool)] = 0.0

    def start(self, games: int) -> np.ndarray:
        """The memories ``(games, N, hidden)`` the next call starts from (allocated at zero if
        there are none yet): what a rollout's batch and a checkpoint keep."""
        if self.memory is None or len(self.memory) != games:
            self.memory = np.zeros(self.model.memory_shape(games), dtype=np.float32)
        return self.memory


def learner_inputs(
    model: RecurrentActorCritic, obs: torch.Tensor, batch: Mapping[str, Any]
) -> tuple[torch.Tensor, dict[str, Any]]:
    """The batch as a recurrent model's learner reads it: the observations ``(T, B, ·)``
    with the memories they were acted on (recomputed with autograd from ``batch["memory"]``,
    the memories at the rollout's start), and a view of ``batch`` whose ``next_obs`` and
    ``final_obs`` carry the memory of the state after the batch and of each truncated
    episode's last state."""
    dev = obs.device
    first = torch.as_tensor(np.asarray(batch["memory"]), device=dev)
    term, trunc = np.asarray(batch["terminated"]), np.asarray(batch["truncated"])
    done = torch.as_tensor(term | trunc, device=dev)
    starts = torch.zeros_like(done)
    starts[1:] = done[:-1]
    memories = model.memories(obs, first, starts)
    with torch.no_grad():
        last = memories[-1] * (~done[-1]).to(memories.dtype)[:, None, None]
        next_obs = torch.as_tensor(np.asarray(batch["next_obs"]), device=dev).float()
        after = model.remember(next_obs, last)
        final = torch.as_tensor(np.asarray(batch["final_obs"]), device=dev).float()
        final_memory = torch.zeros_like(memories)
        cut = torch.as_tensor(trunc, device=dev)
        if trunc.any():
            final_memory[cut] = model.remember(final[cut], memories[cut])
        view = {
            **batch,
            "next_obs": model.with_memory(next_obs, after).cpu().numpy(),
            "final_obs": model.with_memory(final, final_memory).cpu().numpy(),
        }
    return model.with_memory(obs, memories), view
