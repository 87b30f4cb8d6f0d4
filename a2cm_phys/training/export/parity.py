"""How closely an exported team reproduces the run's own actors: :func:`parity` compares
their outputs (logits, or means and log-stds) and greedy actions on given observations."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch

from ...config import Scenario
from ...deploy import Team
from ...deploy.spec import LOG_STD, LOGITS, MEAN

if TYPE_CHECKING:
    from ...algos import ActorCritic
    from ..runs import TrainedRun

TOLERANCE = 1e-5
"""The largest difference of an output allowed between an exported actor and torch's."""


@dataclass(frozen=True)
class Parity:
    """An exported team against the run's actors on ``observations`` observations."""

    observations: int
    max_abs_diff: float
    """Largest absolute difference of any output (ONNX against torch's forward pass and
    against the numpy copy the rollouts use)."""
    max_scaled_diff: float
    """Largest difference relative to the output's size where it exceeds 1:
    ``|Δ| / max(1, |x|)`` (float32 holds a logit of 100 to about 8e-6 only)."""
    agreement: float
    """Fraction of (observation, agent) greedy actions that are the same (continuous: the
    clipped means within :data:`TOLERANCE`)."""

    @property
    def ok(self) -> bool:
        """Every output within :data:`TOLERANCE` (relative beyond 1) and every greedy
        action the same."""
        return self.max_scaled_diff <= TOLERANCE and self.agreement == 1.0

    def __str__(self) -> str:
        return (
            f"{self.observations} observations: max |difference| {self.max_abs_diff:.2e}"
            f" (relative beyond 1: {self.max_scaled_diff:.2e}), greedy actions agree"
            f" {100 * self.agreement:.2f}%"
        )


def sample_observations(scenario: Scenario, n: int, seed: int = 0) -> np.ndarray:
    """``n`` observations ``(n, obs_dim)`` float32 spread over what the env can give: random
    cells on grids; random positions, and velocities up to ``max_speed``, in physics (and
    random headings with differential drive)."""
    rng = np.random.default_rng(seed)
    agents = scenario.pursuers + 1
    if scenario.mode == "grid":
        cells = rng.integers(0, scenario.size, size=(n, 2 * agents))
        return (cells / (scenario.size - 1)).astype(np.float32)
    positions = rng.uniform(0.0, 1.0, size=(n, 2 * agents))
    velocities = rng.uniform(-1.0, 1.0, size=(n, 2 * agents))
    parts = [positions, velocities]
    if scenario.differential:  # the pursuers' headings (cos θ, sin θ)
        angle = rng.uniform(-np.pi, np.pi, size=(n, scenario.pursuers))
        parts.append(np.stack([np.cos(angle), np.sin(angle)], axis=-1).reshape(n, -1))
    return np.concatenate(parts, axis=1).astype(np.float32)


def _torch_outputs(model: ActorCritic, obs: np.ndarray) -> list[np.ndarray]:
    """The actors' outputs ``(B, N, O)`` by torch's forward pass and by the rollouts' numpy
    copy, and (continuous) ``log_std`` broadcast to ``(B, N, O)``."""
    with torch.no_grad():
        forward = model.actor_outputs(torch.from_numpy(obs)).numpy()
    outs = [forward, model.outputs_np(obs)]
    if model.log_std is not None:
        outs.append(np.broadcast_to(model.log_std.detach().numpy(), forward.shape))
    return outs


def _compare(model: ActorCritic, team: Team, agents: list[str], obs: np.ndarray):
    """``(max |difference|, max scaled difference, greedy actions equal, greedy actions
    compared)`` of ``agents``' exported actors against ``model``'s."""
    forward, rollout, *log_std = _torch_outputs(model, obs)
    diff, scaled, same = 0.0, 0.0, 0
    for i, agent in enumerate(agents):
        got = team.actors[agent].outputs(obs)
        pairs = [(got[MEAN] if team.continuous else got[LOGITS], forward[:, i])]
        pairs.append((pairs[0][0], rollout[:, i]))
        if log_std:
            pairs.append((got[LOG_STD], log_std[0][:, i]))
        for mine, theirs in pairs:
            gap = np.abs(mine - theirs)
            diff = max(diff, float(gap.max()))
            scaled = max(scaled, float((gap / np.maximum(1.0, np.abs(theirs))).max()))
        mine = team.actors[agent].act(obs, greedy=True)
        theirs = model.dist.greedy(rollout[:, i])
        if team.continuous:
            close = np.abs(mine - team.actors[agent].clip(theirs)) <= TOLERANCE
            same += int(close.all(-1).sum())
        else:
            same += int((mine == theirs).sum())
    return diff, scaled, same, len(obs) * len(agents)


def parity(trained: TrainedRun, team: Team, obs: np.ndarray) -> Parity:
    """The exported ``team`` against ``trained``'s actors (the pursuers', and a learned
    evader's) on observations ``(B, obs_dim)``."""
    obs = np.ascontiguousarray(obs, dtype=np.float32)
    diff, scaled, same, total = _compare(trained.pursuers, team, team.pursuers, obs)
    if trained.evader is not None and "evader" in team.actors:
        d, r, s, t = _compare(trained.evader, team, ["evader"], obs)
        diff, scaled, same, total = max(diff, d), max(scaled, r), same + s, total + t
    return Parity(len(obs), diff, scaled, same / total)
