"""TorchRL over our batched games: :class:`PursuitEnv`, an ``EnvBase`` whose batch is a
:class:`~a2cm_phys.envs.vector.VectorEnv` of ``num_envs`` games, stepped together.

Groups, as TorchRL's multi-agent environments (VMAS, PettingZoo) lay them out:

- ``"pursuers"`` (``N`` agents): ``("pursuers", "observation")`` ``(B, N, obs + N)``: each
  pursuer's own observation (the global state with sensing off, its sensed vector with
  sensing on) followed by its one-hot index, so that a policy shared between the
  pursuers can tell them apart; ``("pursuers", "action")``: a move in ``[0, actions)``
  (``Categorical``) or a command in ``[-1, 1]²`` (continuous control);
  ``("pursuers", "reward")`` ``(B, N, 1)``: the team reward, the same for each pursuer;
- ``"evader"`` (one agent), only with a learned evader (``evader = "learned"``): its own
  observation, action and reward (:func:`~a2cm_phys.envs.core.evader_reward`), its
  actions taken from the input like the pursuers';
- ``"state"`` ``(B, state_dim)``: the global state, for centralised critics (MAPPO).

``terminated`` (capture, or a collision that ends the game) and ``truncated`` (the step
limit) are kept apart, at the root ``(B, 1)`` and in each group ``(B, N, 1)``, with
``done`` their union. Our games restart inside a step; here a step returns the finished
episode's last observation, as TorchRL expects, and ``reset`` with a ``"_reset"`` mask
hands back the episodes the step already started (games asked to reset that had not
finished are restarted). Episode seeds come from one generator, as in the trainer: a run
is reproducible from ``seed``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ..config import Scenario
from ..envs.sensing import agent_slice
from ..envs.vector import VecStep, VectorEnv

PURSUERS, EVADER, STATE = "pursuers", "evader", "state"
"""The group names and the key of the global state."""


def agent_observations(scenario: Scenario, obs: np.ndarray) -> dict[str, torch.Tensor]:
    """Each group's observations from the games' ``obs`` ``(B, team_dim)`` (what
    :class:`VectorEnv` returns): ``{"pursuers": (B, N, dim + N)}``, with a learned evader
    also ``{"evader": (B, 1, dim)}``, and ``{"state": (B, state_dim)}``."""
    n, b = scenario.pursuers, len(obs)
    state = obs[:, : scenario.state_dim]
    if scenario.sensing.on:
        own = np.stack([obs[:, agent_slice(scenario, i)] for i in range(n + 1)], axis=1)
    else:
        own = np.repeat(state[:, None, :], n + 1, axis=1)
    ids = np.broadcast_to(np.eye(n, dtype=np.float32), (b, n, n))
    out = {
        PURSUERS: torch.from_numpy(np.concatenate([own[:, :n], ids], axis=2).astype(np.float32)),
        STATE: torch.from_numpy(np.ascontiguousarray(state, dtype=np.float32)),
    }
    if scenario.evader == "learned":
        out[EVADER] = torch.from_numpy(np.ascontiguousarray(own[:, n:], dtype=np.float32))
    return out


def team_policy(
    scenario: Scenario, module: Callable[[TensorDictBase], TensorDictBase], greedy: bool = True
) -> Callable[[np.ndarray, np.random.Generator], np.ndarray]:
    """A TorchRL policy ``module`` (reading ``("pursuers", "observation")``, writing
    ``("pursuers", "action")``) as the package's rollout policy ``policy(obs, rng) ->
    actions`` over :class:`VectorEnv` observations, so that ``evaluate``'s measures (e.g.
    :func:`a2cm_phys.analysis.evaluation.play`) play it as any team; ``greedy``: the
    distribution's mode (TorchRL's deterministic exploration), else a sample."""
    mode = ExplorationType.DETERMINISTIC if greedy else ExplorationType.RANDOM

    def policy(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        parts = agent_observations(scenario, obs)
        b = (len(obs),)
        td = TensorDict({STATE: parts[STATE]}, batch_size=b)
        td.set(
            PURSUERS,
            TensorDict({"observation": parts[PURSUERS]}, batch_size=(*b, scenario.pursuers)),
        )
        with torch.no_grad(), set_exploration_type(mode):
            action = module(td).get((PURSUERS, "action")).numpy()
        return action.astype(np.float64) if scenario.continuous else action.astype(np.int64)

    return policy


class PursuitEnv(EnvBase):
    """``num_envs`` games of ``scenario`` as one TorchRL environment of batch ``(num_envs,)``
    (see the module docs); ``workers`` physics processes as in training; ``seed`` seeds the
    episodes until :meth:`set_seed` reseeds them."""

    def __init__(
        self, scenario: Scenario, num_envs: int = 16, workers: int = 1, seed: int = 0
    ) -> None:
        super().__init__(device="cpu", batch_size=torch.Size([num_envs]))
        self.scenario = scenario
        self.games = VectorEnv(scenario, num_envs, workers)
        self.learned_evader = self.games.learned_evader
        self._groups = {PURSUERS: scenario.pursuers, **({EVADER: 1} if self.learned_evader else {})}
        self._make_specs()
        self._set_seed(seed)

    @property
    def group_map(self) -> dict[str, list[str]]:
        """The agents of each group by name (``pursuer_0`` …, ``evader``)."""
        names = {PURSUERS: [f"pursuer_{i}" for i in range(self.scenario.pursuers)]}
        return {**names, **({EVADER: [EVADER]} if self.learned_evader else {})}

    def _make_specs(self) -> None:
        sc, b = self.scenario, self.batch_size[0]
        obs = agent_observations(sc, np.zeros((b, self.games.obs_dim)))
        flag = {"dtype": torch.bool, "n": 2}
        observation, action, reward = (
            Composite(shape=(b,)),
            Composite(shape=(b,)),
            Composite(shape=(b,)),
        )
        done = Composite(shape=(b,), **{k: Categorical(shape=(b, 1), **flag) for k in _FLAGS})
        for group, n in self._groups.items():
            shape = (b, n)
            observation[group] = Composite(
                observation=Unbounded(shape=obs[group].shape, dtype=torch.float32), shape=shape
            )
            if sc.continuous:
                act = Bounded(-1.0, 1.0, shape=(b, n, 2), dtype=torch.float32)
            else:
                act = Categorical(n=sc.actions, shape=shape, dtype=torch.int64)
            action[group] = Composite(action=act, shape=shape)
            reward[group] = Composite(reward=Unbounded(shape=(b, n, 1)), shape=shape)
            done[group] = Composite(
                shape=shape, **{k: Categorical(shape=(b, n, 1), **flag) for k in _FLAGS}
            )
        observation[STATE] = Unbounded(shape=obs[STATE].shape, dtype=torch.float32)
        self.observation_spec, self.action_spec = observation, action
        self.reward_spec, self.done_spec = reward, done

    def _set_seed(self, seed: int | None) -> None:
        self._obs = self.games.reset(int(seed or 0))
        self._fresh = np.ones(self.batch_size[0], dtype=bool)  # games at an episode's start

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: object) -> TensorDictBase:
        wanted = np.ones(self.batch_size[0], dtype=bool)
        if tensordict is not None and "_reset" in tensordict:
            wanted = tensordict.get("_reset").reshape(-1).numpy().astype(bool)
        restart = wanted & ~self._fresh
        if restart.any():
            self._obs = self.games.restart(np.flatnonzero(restart))
        self._fresh[:] = True
        out = self._observations(self._obs)
        for group, n in self._groups.items():
            flags = torch.zeros((self.batch_size[0], n, 1), dtype=torch.bool)
            out.update({(group, k): flags.clone() for k in _FLAGS})
        out.update({k: torch.zeros((self.batch_size[0], 1), dtype=torch.bool) for k in _FLAGS})
        return out

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get((PURSUERS, "action")).numpy()
        evader = tensordict.get((EVADER, "action")).numpy()[:, 0] if self.learned_evader else None
        if self.scenario.continuous:
            actions = actions.astype(np.float64)
            evader = None if evader is None else evader.astype(np.float64)
        step = self.games.step(actions, evader)
        self._obs, self._fresh = step.obs, step.terminated | step.truncated
        return self._outcome(step)

    def _outcome(self, step: VecStep) -> TensorDictBase:
        out = self._observations(step.final_obs)
        flags = {
            "terminated": torch.from_numpy(step.terminated.copy()),
            "truncated": torch.from_numpy(step.truncated.copy()),
        }
        flags["done"] = flags["terminated"] | flags["truncated"]
        rewards = {PURSUERS: step.reward}
        if self.learned_evader:
            rewards[EVADER] = step.evader_reward
        for group, n in self._groups.items():
            r = torch.as_tensor(rewards[group], dtype=torch.float32)
            out.set((group, "reward"), r.reshape(-1, 1, 1).expand(-1, n, 1).clone())
            for k, v in flags.items():
                out.set((group, k), v.reshape(-1, 1, 1).expand(-1, n, 1).clone())
        out.update({k: v.reshape(-1, 1) for k, v in flags.items()})
        return out

    def _observations(self, obs: np.ndarray) -> TensorDict:
        parts = agent_observations(self.scenario, obs)
        b = self.batch_size
        out = TensorDict({STATE: parts.pop(STATE)}, batch_size=b)
        for group, value in parts.items():
            out.set(group, TensorDict({"observation": value}, batch_size=(*b, value.shape[1])))
        return out

    def close(self, *, raise_if_closed: bool = True) -> None:
        """Stop the games' worker processes, if any."""
        self.games.close()
        super().close(raise_if_closed=raise_if_closed)


_FLAGS = ("done", "terminated", "truncated")
