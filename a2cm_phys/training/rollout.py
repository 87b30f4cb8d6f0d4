"""Collect a time-major batch from a :class:`~a2cm_phys.envs.vector.VectorEnv` with a policy.

The batch is a dict of preallocated numpy arrays keyed as the learner reads them
(:data:`~a2cm_phys.algos.learner.BATCH_KEYS`); :func:`collect` overwrites it in place each
update, so the rollout loop allocates nothing of its own. Actions are stored with the shape
and dtype of the policy's distribution (int64 indices, or float32 velocity commands), and
the raw team reward is stored beside its components (``reward_parts``) and the pursuer
collisions of each step, for learners that value them apart or constrain collisions.

``obs_dim`` is the env's (``VectorEnv.obs_dim``): the global state's length, or with sensing
the team vector's (the state, then every agent's own observation; SPEC §6b), from which
each actor reads its own agent's slice.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..envs.core import REWARD_PARTS, reward_parts
from ..envs.tallies import EpisodeBatch
from ..envs.vector import VecStep, VectorEnv

Policy = Callable[[np.ndarray, np.random.Generator], np.ndarray]
"""``policy(obs (B, obs_dim), rng) -> actions (B, N, *action_shape)``.

A policy with memory (a recurrent team, a belief planner) also has a method
``episodes_ended(ended (B,) bool)``: whoever steps the games calls it after every step
(:func:`episodes_ended`), and the policy forgets the games whose episode just ended, since
their next observation starts a new one."""

StepHook = Callable[[np.ndarray, VecStep], None]
"""``hook(actions, step)``, called after every vector step (e.g. the episode recorder)."""


def episodes_ended(policy: Policy, ended: np.ndarray) -> None:
    """Tell ``policy``, if it has memory (an ``episodes_ended`` method), which games'
    episodes ended in the step just taken (``(B,)`` bool: terminated or truncated)."""
    forget = getattr(policy, "episodes_ended", None)
    if forget is not None:
        forget(ended)


def allocate_batch(
    steps: int,
    num_envs: int,
    obs_dim: int,
    n_agents: int,
    action_shape: tuple[int, ...] = (),
    action_dtype: np.dtype | type = np.int64,
) -> dict[str, np.ndarray]:
    """Zeroed arrays for ``steps`` vector steps of ``num_envs`` games (time-major)."""
    return {
        "obs": np.zeros((steps, num_envs, obs_dim), dtype=np.float32),
        "actions": np.zeros((steps, num_envs, n_agents, *action_shape), dtype=action_dtype),
        "rewards": np.zeros((steps, num_envs), dtype=np.float64),
        "reward_parts": np.zeros((steps, num_envs, len(REWARD_PARTS)), dtype=np.float64),
        "collisions": np.zeros((steps, num_envs), dtype=np.int64),
        "terminated": np.zeros((steps, num_envs), dtype=bool),
        "truncated": np.zeros((steps, num_envs), dtype=bool),
        "final_obs": np.zeros((steps, num_envs, obs_dim), dtype=np.float32),
        "next_obs": np.zeros((num_envs, obs_dim), dtype=np.float32),
    }


SHARED_KEYS = ("obs", "terminated", "truncated", "final_obs", "next_obs")
"""Batch arrays that both teams of a game see alike (a learned evader's batch views them)."""


def allocate_evader_batch(
    batch: dict[str, np.ndarray],
    action_shape: tuple[int, ...] = (),
    action_dtype: np.dtype | type = np.int64,
) -> dict[str, np.ndarray]:
    """A learned evader's batch beside the pursuers' ``batch``: its own actions (one agent)
    and rewards, the observations and episode ends shared (views of ``batch``)."""
    steps, num_envs = batch["rewards"].shape
    own = allocate_batch(steps, num_envs, 0, 1, action_shape, action_dtype)
    return {
        **{k: batch[k] for k in SHARED_KEYS},
        **{k: own[k] for k in ("actions", "rewards", "reward_parts", "collisions")},
    }


def collect(
    env: VectorEnv,
    policy: Policy,
    obs: np.ndarray,
    rng: np.random.Generator,
    batch: dict[str, np.ndarray],
    on_step: StepHook | None = None,
    evader: tuple[Policy, dict[str, np.ndarray]] | None = None,
) -> tuple[np.ndarray, EpisodeBatch]:
    """Step ``env`` ``len(batch["obs"])`` times from ``obs``, writing into ``batch``.

    ``evader`` is a learned evader's ``(policy, batch)`` (see :func:`allocate_evader_batch`):
    its policy acts on the same observations after the pursuers' (one agent: actions
    ``(B, 1, ...)``), and its batch gets its actions and its own reward. Returns the
    observations after the last step (also stored as ``batch["next_obs"]``) and the episodes
    that finished meanwhile, in order. ``rng`` is the policies' only randomness.
    """
    b_obs, b_actions, b_rewards = batch["obs"], batch["actions"], batch["rewards"]
    b_term, b_trunc, b_final = batch["terminated"], batch["truncated"], batch["final_obs"]
    b_parts, b_coll = batch["reward_parts"], batch["collisions"]
    scenario = env.scenario
    episodes: list[EpisodeBatch] = []
    for t in range(len(b_obs)):
        b_obs[t] = obs
        actions = policy(obs, rng)
        if evader is None:
            step = env.step(actions, validate=False)
        else:
            e_actions = evader[0](obs, rng)
            step = env.step(actions, e_actions[:, 0], validate=False)
            evader[1]["actions"][t] = e_actions
            evader[1]["rewards"][t] = step.evader_reward
            evader[1]["reward_parts"][t, :, 0] = step.evader_reward
        b_actions[t] = actions
        b_rewards[t] = step.reward
        reward_parts(scenario, step.outcome, b_parts[t])
        b_coll[t] = step.outcome.collisions
        b_term[t] = step.terminated
        b_trunc[t] = step.truncated
        b_final[t] = step.final_obs
        if step.episodes:
            episodes.append(step.episodes)
            ended = step.terminated | step.truncated
            episodes_ended(policy, ended)
            if evader is not None:
                episodes_ended(evader[0], ended)
        if on_step is not None:
            on_step(actions, step)
        obs = step.obs
    batch["next_obs"][:] = obs
    if not episodes:
        return obs, EpisodeBatch.empty(env.learned_evader)
    return obs, EpisodeBatch.concat(episodes)
