"""The networks a run's settings ask for: :func:`make_model` and the actors' distribution.

A resolved :class:`~a2cm_phys.config.Train` and a :class:`~a2cm_phys.config.Scenario` decide
everything: A2C or A2CM (the critics' shape), the actions' distribution, hidden layers,
inputs (one-hot cells, each agent's sensed vector) and whether the actors remember
(``recurrent = "gru"``: :class:`~a2cm_phys.algos.recurrent.RecurrentActorCritic`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from ..envs.core import REWARD_PARTS
from ..envs.sensing import team_dim
from .distributions import ActionDistribution, CategoricalActions, GaussianActions
from .encoding import OneHotCells, RelativePositions
from .models import ActorCritic, SensedInputs
from .recurrent import RecurrentActorCritic

if TYPE_CHECKING:
    from ..config import Encoding, Scenario, Train

__all__ = ["action_distribution", "make_model"]


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
    """Build the network a resolved ``train_cfg`` (:func:`~a2cm_phys.config.resolve_train`)
    asks for, sized by ``scenario``, on its device.

    ``n_agents`` defaults to the scenario's pursuers and ``shared_critic`` to A2CM's (a
    team of one, such as a learned evader, passes its own). The initial weights come from
    ``generator`` if given, otherwise from a torch generator seeded with ``train_cfg.seed``
    (independent of the global torch RNG). With ``split_rewards`` each critic predicts one
    value per reward component (:data:`~a2cm_phys.envs.core.REWARD_PARTS`). With sensing the
    input is the team vector (:func:`~a2cm_phys.envs.sensing.team_dim`), and a team of one
    (``n_agents = 1``) in a scenario with a learned evader is that evader: it reads its own
    (last) slot. With ``recurrent = "gru"`` the actors remember
    (:class:`~a2cm_phys.algos.recurrent.RecurrentActorCritic`).
    """
    if generator is None:
        generator = torch.Generator().manual_seed(train_cfg.seed)
    agents = scenario.pursuers if n_agents is None else n_agents
    sensed = None
    if scenario.sensing.on:
        evader = n_agents == 1 and scenario.evader == "learned"  # the evader's slot is last
        first = scenario.pursuers if evader else 0
        sensed = SensedInputs(scenario.state_dim, scenario.obs_dim, first)
    network = RecurrentActorCritic if train_cfg.recurrent == "gru" else ActorCritic
    model = network(
        team_dim(scenario),
        agents,
        action_distribution(scenario),
        train_cfg.hidden,
        shared_critic=train_cfg.algo == "a2cm" if shared_critic is None else shared_critic,
        n_values=len(REWARD_PARTS) if train_cfg.split_rewards else 1,
        log_std_init=train_cfg.log_std_init,
        generator=generator,
        layers=train_cfg.layers,
        encoding=OneHotCells(scenario.size) if train_cfg.encoding == "onehot" else None,
        sensed=sensed,
        relative=relative_positions(scenario, agents, train_cfg.encoding),
    )
    return model.to(train_cfg.device)


def relative_positions(
    scenario: Scenario, agents: int, encoding: Encoding
) -> RelativePositions | None:
    """Each of a team's ``agents`` actors' view from its own body: the pursuers' (the
    first bodies), or a team of one in a scenario with a learned evader, that evader's;
    with ``encoding = "metric"`` the offsets in metres or cells
    (:attr:`~a2cm_phys.config.Scenario.position_unit`); ``None`` for any other encoding."""
    if encoding not in ("relative", "metric"):
        return None
    evader = agents == 1 and scenario.evader == "learned"
    first = scenario.pursuers if evader else 0
    scale = scenario.position_unit if encoding == "metric" else 1.0
    return RelativePositions(scenario.pursuers + 1, scenario.state_dim, first, agents, scale)
