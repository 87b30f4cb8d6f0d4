"""Batched actor–critic networks for A2C and A2CM (SPEC §6).

Every agent of a team observes the same global state, so one input row feeds all N actors
and all critics. Each actor is ``Linear(obs, hidden) → ReLU → Linear(hidden, n_outputs)``
and each critic ``Linear(obs, hidden) → ReLU → Linear(hidden, n_values)`` (the paper's
networks, SPEC §6). The N actors (and A2C's N critics) live in
:class:`~a2cm_phys.algos.layers.StackedLinear` layers whose parameters carry a leading agent
dimension, so all of them are evaluated in one batched op, not a Python loop.

Two options go beyond the paper (``Train.layers``, ``Train.encoding``): more hidden layers
of the same width, and, on grids, the input as one one-hot of each coordinate's cell
(:class:`~a2cm_phys.algos.encoding.OneHotCells`) instead of the coordinates themselves, or
each actor's input seen from its own body, the others' positions as offsets
(:class:`~a2cm_phys.algos.encoding.RelativePositions`, ``encoding = "relative"``, or in
metres or cells, ``"metric"``).
With the defaults (one layer, the raw observation) the networks are the paper's, weight for
weight.

- **A2C** (``shared_critic=False``): N actors and N critics, critic i learns agent i's returns.
- **A2CM** (``shared_critic=True``): N actors and ONE critic trained on the team return.

The only difference between the two is the critic's shape. What an actor's outputs mean is
the :mod:`~a2cm_phys.algos.distributions` object's business: logits of a categorical
(discrete control) or the mean of a diagonal Gaussian with a learnable state-independent
``log_std`` per agent (continuous control). A critic may predict several values per state
(``n_values``): one per reward component, when the learner splits the team reward.

**Sensing** (SPEC §6b, ``Scenario.sensing``): the team's input is the vector of
:func:`~a2cm_phys.envs.sensing.team_observation` (the global state, then each agent's own
masked observation). Each actor then reads only its own agent's observation (decentralised
execution: what the agent sensed, or with ``share`` what its team did). A2CM's one shared
critic reads the global state (centralised training: the critic is not needed to act);
A2C's critic i reads agent i's own observation, as its actor does. Without sensing every
network reads the global state, as before, weight for weight.

For rollouts :meth:`ActorCritic.act` computes the actor outputs from a numpy snapshot of
the actor weights (:class:`~a2cm_phys.algos.snapshot.ActorSnapshot`, several times faster
than torch for 1–64 rows), refreshed automatically whenever the torch parameters change in
place (optimiser step, ``load_state_dict``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .distributions import ActionDistribution, CategoricalActions
from .encoding import OneHotCells, RelativePositions
from .layers import StackedLinear, stacked_mlp
from .snapshot import ActorSnapshot

__all__ = ["ActorCritic", "SensedInputs", "agent_mlp", "critics", "input_view"]


@dataclass(frozen=True)
class SensedInputs:
    """Where a team's networks read a sensing scenario's team vector (SPEC §6b): the global
    state's ``state_dim`` numbers first, then one ``obs_dim`` observation per agent of the
    game; this team's agents are those from slot ``first`` on (pursuers 0, an evader N)."""

    state_dim: int
    obs_dim: int
    first: int = 0

    def agents(self, x, n: int):
        """The ``n`` agents' observations ``(..., n, obs_dim)`` of team vectors ``(..., d)``."""
        start = self.state_dim + self.first * self.obs_dim
        if x.shape[-1] < start + n * self.obs_dim:
            raise ValueError(
                f"observations of length {x.shape[-1]}: a sensing team reads team vectors"
                f" (the state, then every agent's observation; VectorEnv.obs)"
            )
        return x[..., start : start + n * self.obs_dim].reshape(*x.shape[:-1], n, self.obs_dim)


def input_view(
    sensed: SensedInputs | None,
    obs,
    n: int,
    state: bool = False,
    relative: RelativePositions | None = None,
):
    """What a team's networks read of ``obs``, and whether one row per agent: the whole
    vector (sensing off), the global state (``state``: A2CM's critic), or each agent's own
    (with sensing, or each actor's ``relative`` view; torch or numpy as ``obs`` is)."""
    if sensed is None:
        if relative is not None and not state:
            return relative.view(obs), True
        return obs, False
    if state:
        return obs[..., : sensed.state_dim], False
    return sensed.agents(obs, n), True


def _features(encoding: OneHotCells | None, length: int) -> int:
    return length if encoding is None else encoding.features(length)


def _input_sizes(obs_dim: int, encoding, sensed: SensedInputs | None, shared_critic: bool):
    """How many numbers an actor and a critic read: the (encoded) observation, or with
    sensing the agent's own, and A2CM's critic the state."""
    inputs = critic = _features(encoding, obs_dim if sensed is None else sensed.obs_dim)
    if sensed is not None and shared_critic:
        critic = _features(encoding, sensed.state_dim)
    return inputs, critic


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
        sensed: with sensing, where the agents' observations and the state lie in the input.
        relative: each actor's view from its own body (:class:`RelativePositions`).
        critic_memory: numbers each critic reads beside its input (a recurrent A2C critic:
            its actor's memory, :mod:`~a2cm_phys.algos.recurrent`).
    """

    recurrent = False
    """Whether the actors carry a memory across steps (:mod:`~a2cm_phys.algos.recurrent`)."""

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
        sensed: SensedInputs | None = None,
        critic_memory: int = 0,
        relative: RelativePositions | None = None,
    ) -> None:
        super().__init__()
        if layers < 1:
            raise ValueError(f"layers must be >= 1, got {layers}")
        dist = CategoricalActions(actions) if isinstance(actions, int) else actions
        self.dist = dist
        self.obs_dim, self.n_agents, self.hidden = obs_dim, n_agents, hidden
        self.shared_critic, self.n_values = shared_critic, n_values
        self.encoding, self.sensed, self.relative = encoding, sensed, relative
        # inputs that hold the trained arena's size (one-hot cells, metric offsets) play it only
        self.arena_bound = encoding is not None or (relative is not None and relative.scale != 1)
        c = critics(n_agents, shared_critic)
        inputs, critic_inputs = _input_sizes(obs_dim, encoding, sensed, shared_critic)
        critic_inputs += critic_memory
        # The creation order is the draw order of ``generator``: the paper's two layers of
        # the actors, then of the critics; layers beyond the first last, so that one layer
        # draws the paper's weights.
        self.actor_hidden = StackedLinear(n_agents, inputs, hidden, generator)
        self.actor_out = StackedLinear(n_agents, hidden, dist.n_outputs, generator)
        self.critic_hidden = StackedLinear(c, critic_inputs, hidden, generator)
        self.critic_out = StackedLinear(c, hidden, n_values, generator)
        self.actor_deep = nn.ModuleList(
            StackedLinear(n_agents, hidden, hidden, generator) for _ in range(layers - 1)
        )
        self.critic_deep = nn.ModuleList(
            StackedLinear(c, hidden, hidden, generator) for _ in range(layers - 1)
        )
        shape, std = (n_agents, dist.n_outputs), log_std_init
        self.log_std = nn.Parameter(torch.full(shape, float(std))) if dist.has_log_std else None
        self._numpy_actors = self._snapshot()

    @property
    def n_critics(self) -> int:
        """Number of critics C: 1 for A2CM, N for A2C."""
        return self.critic_out.n

    @property
    def n_actions(self) -> int:
        """Actor outputs per agent (the number of discrete actions, or the command's size)."""
        return self.dist.n_outputs

    @property
    def layers(self) -> int:
        """Hidden layers of every actor and critic."""
        return 1 + len(self.actor_deep)

    # ------------------------------------------------------------------ torch forward
    def _input(self, obs: torch.Tensor) -> torch.Tensor:
        return obs if self.encoding is None else self.encoding.torch(obs)

    def actor_outputs(self, obs: torch.Tensor) -> torch.Tensor:
        """Actor outputs ``(..., N, n_outputs)`` (logits or means) for ``(..., obs_dim)``."""
        x, own = input_view(self.sensed, obs, self.n_agents, relative=self.relative)
        return agent_mlp(self.actor_hidden, self.actor_deep, self.actor_out, self._input(x), own)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        """Critic outputs ``(..., C)``, or ``(..., C, n_values)`` when ``n_values > 1``."""
        x, own = input_view(self.sensed, obs, self.n_agents, state=self.shared_critic)
        out = agent_mlp(self.critic_hidden, self.critic_deep, self.critic_out, self._input(x), own)
        return out.squeeze(-1) if self.n_values == 1 else out

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(actor outputs (..., N, n_outputs), values)`` for observations ``(..., obs_dim)``."""
        return self.actor_outputs(obs), self.value(obs)

    # ------------------------------------------------------------------ fast rollout path
    def act(self, obs: np.ndarray, rng: np.random.Generator, greedy: bool = False) -> np.ndarray:
        """Actions ``(B, N, *action_shape)`` (``(N, ...)`` for a 1-D ``obs``) of observations
        ``(B, obs_dim)`` for rollouts (no autograd): int64 for discrete actions, float32
        (unclipped) for continuous ones. ``rng`` is the only randomness (unused when
        ``greedy``: the argmax, or the Gaussian's mean): a seeded one gives a bit-exact run."""
        out = self.outputs_np(obs)
        if greedy:
            return self.dist.greedy(out)
        return self.dist.sample(out, self._numpy_actors.log_std, rng)

    def rollout_policy(self, greedy: bool = False):
        """The actors as a rollout policy ``policy(obs, rng) -> actions`` (sampled, or the
        most probable action); a recurrent model's keeps its memory between calls."""
        return lambda obs, rng: self.act(obs, rng, greedy=greedy)

    def outputs_np(self, obs: np.ndarray) -> np.ndarray:
        """Actor outputs as numpy ``(B, N, n_outputs)`` (``(N, n_outputs)`` for 1-D ``obs``)."""
        obs = np.asarray(obs, dtype=np.float32)
        x = input_view(self.sensed, obs, self.n_agents, relative=self.relative)[0]
        if self.encoding is not None:
            x = self.encoding.numpy(x)
        return self._numpy_actors.outputs(x)

    def action_probs_np(self, obs: np.ndarray) -> np.ndarray:
        """Softmax action probabilities ``(B, N, A)`` of discrete actors, as numpy float64."""
        if not isinstance(self.dist, CategoricalActions):
            raise TypeError("action probabilities exist for discrete actions only")
        logits = self.outputs_np(obs).astype(np.float64)
        e = np.exp(logits - logits.max(-1, keepdims=True))
        return e / e.sum(-1, keepdims=True)

    def refresh_snapshot(self) -> None:
        """Rebuild the numpy copy of the actor weights used by :meth:`act` now."""
        self._numpy_actors.refresh()

    def _apply(self, fn, *args, **kwargs):  # type: ignore[override]
        """Invalidate the numpy snapshot when parameters are moved or converted (``.to``)."""
        out = super()._apply(fn, *args, **kwargs)
        self._numpy_actors = self._snapshot()
        return out

    def _snapshot(self) -> ActorSnapshot:
        parts = (self.actor_hidden, self.actor_out, self.actor_deep, self.log_std)
        return ActorSnapshot(*parts, per_agent=self.sensed is not None or self.relative is not None)


def agent_mlp(first: StackedLinear, deep, last: StackedLinear, x: torch.Tensor, own: bool):
    """``n`` MLPs on one shared input (:func:`stacked_mlp`), or with ``own`` each on its own
    input row: ``(..., n, in) → (..., n, out)``."""
    if not own:
        return stacked_mlp(first, deep, last, x)
    h = F.relu(first(x))
    for layer in deep:
        h = F.relu(layer(h))
    return last(h)


def critics(n_agents: int, shared_critic: bool) -> int:
    """How many critics a team of ``n_agents`` has: A2CM's one shared critic, or A2C's one
    per agent."""
    return 1 if shared_critic else n_agents
