"""The learning sides of a run: the pursuers' team and, with a learned evader, the evader.

Pursuers and evader are the same kind of agent with their own reward (SPEC §1b): each side
is a :class:`Team` with its own actor–critic model, learner and rollout buffer. The
pursuers are trained by A2C or A2CM (``Train.algo``); a learned evader is a team of one
with its own A2C actor–critic, trained with the pursuers' settings on its own reward
(minus the team reward by default), without the pursuers' collision-specific options.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..algos import ActorCritic, Learner, make_model
from ..algos.shaping import ProgressShaping
from ..config import Scenario, Train
from ..envs.sensing import team_dim
from .rollout import Policy, allocate_batch, allocate_evader_batch
from .seeding import evader_weights_generator


@dataclass
class Team:
    """One learning side: its name, model, learner, rollout buffer and the policy its
    rollouts act through (with recurrent actors, a policy with memory: the batch's
    ``memory`` keeps its memories at each rollout's start)."""

    name: str
    model: ActorCritic
    learner: Learner
    batch: dict[str, np.ndarray]
    policy: Policy = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        self.policy = self.model.rollout_policy()
        if self.model.recurrent:
            games = len(self.batch["rewards"][0])
            self.batch["memory"] = np.zeros(self.model.memory_shape(games), dtype=np.float32)

    def start_rollout(self) -> None:
        """Note in the batch the memories the rollout starts from (recurrent actors)."""
        if self.model.recurrent:
            self.batch["memory"][:] = self.policy.start(len(self.batch["memory"]))


def evader_train_cfg(cfg: Train) -> Train:
    """The learned evader's training settings: the pursuers', as A2C of one agent on its one
    reward (no reward components, no collision constraint: collisions are the pursuers')."""
    return dataclasses.replace(cfg, algo="a2c", split_rewards=False, constrain_collisions=False)


def make_teams(scenario: Scenario, cfg: Train) -> tuple[Team, Team | None]:
    """The pursuers' team and, if the scenario's evader is learned, the evader's, for a
    resolved ``cfg`` (:func:`~a2cm_phys.config.resolve_train`)."""
    model = make_model(cfg, scenario)
    batch = allocate_batch(
        cfg.steps_per_env,
        cfg.num_envs,
        team_dim(scenario),
        scenario.pursuers,
        model.dist.action_shape,
        model.dist.action_dtype,
    )
    pursuers = Team("pursuers", model, Learner(model, cfg, _shaping(scenario, cfg)), batch)
    if scenario.evader != "learned":
        return pursuers, None
    ecfg = evader_train_cfg(cfg)
    emodel = make_model(ecfg, scenario, evader_weights_generator(cfg.seed), n_agents=1)
    ebatch = allocate_evader_batch(batch, emodel.dist.action_shape, emodel.dist.action_dtype)
    learner = Learner(emodel, ecfg, _shaping(scenario, ecfg, sign=-1.0))
    return pursuers, Team("evader", emodel, learner, ebatch)


def _shaping(scenario: Scenario, cfg: Train, sign: float = 1.0) -> ProgressShaping | None:
    """The learner's progress shaping, if ``distance_shaping`` or ``area_shaping`` is on
    (None, not resolved for a scenario, is off)."""
    distance, area = cfg.distance_shaping or 0.0, cfg.area_shaping or 0.0
    if not (distance or area):
        return None
    return ProgressShaping(scenario, distance, area, sign)
