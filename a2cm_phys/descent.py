"""Exploitability descent in grid self-play: the pursuers learn against the exact best
response to themselves (``Train.descent_every``).

Self-play's learned evader is far from a best response, so pursuers trained against it
(simultaneously or against a pool, :mod:`a2cm_phys.opponents`) stay exploitable: an evader
that plays the exact best response escapes them for good (``BENCHMARKS.md``). On a grid
the exact best response is computable, and so is the gradient of its value in the
pursuers' policy (:mod:`a2cm_phys.solve.descent`). With ``descent_every = K`` the
pursuers' actors learn from that gradient alone: every K updates
:class:`ExploitabilityDescent` computes it for their current actors and takes
``descent_steps`` Adam steps (step size ``descent_lr``) along it. The rollouts go on as in
any self-play run (the pursuers playing their sampled moves), and the learned evader
learns from every one of them by A2C. The pursuers' learner is not stepped: mixing its
rollout gradient in (``BENCHMARKS.md``, "Exploitability descent") drew the team back
towards the learned evader it co-adapts with and slowed the descent. The quantity
descended is the discounted (γ = ``Train.gamma``) expected episode length that the best
response achieves from the start, logged as ``descent_value``.

The actor loss, over the visited states ``s`` with their discounted visit weights
``w(s)`` (normalised to sum to 1), is

    L = Σ_s w(s) Σ_i Σ_a π_i(a | s) · A_i(s, a),

``A_i`` the exact advantage of pursuer ``i``'s action against the best response: its
gradient is that of the best response's value, divided by the visits' total.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from .algos import ActorCritic
from .config import ConfigError, Scenario, Train
from .solve.model import TooLargeError, UnsupportedError
from .solve.tables import joint_observations, model_table


def check_descent(scenario: Scenario, cfg: Train) -> None:
    """Exploitability descent and one-hot inputs need a grid (and descent one the exact
    solver can hold): a :class:`ConfigError` naming the key if not."""
    if cfg.descent_every:
        if scenario.mode != "grid" or scenario.evader != "learned":
            raise ConfigError(
                "training options: key 'descent_every': exploitability descent needs grid"
                f" self-play, and scenario '{scenario.name}' is in {scenario.mode} mode with"
                f" evader = '{scenario.evader}' (use grid_vs, or descent_every = 0)"
            )
        from .solve.pursuer_step import check_size

        try:
            check_size(scenario, "general")
        except (TooLargeError, UnsupportedError) as err:
            raise ConfigError(f"training options: key 'descent_every': {err}") from None
    if cfg.encoding == "onehot" and scenario.mode != "grid":
        raise ConfigError(
            "training options: key 'encoding': one-hot cells need a grid, and scenario"
            f" '{scenario.name}' is in {scenario.mode} mode (use encoding = 'xy')"
        )


class ExploitabilityDescent:
    """The pursuers' actors stepping down the value of the evader's exact best response.

    ``model`` is the pursuers' actor–critic (its actors are stepped in place). ``seed``
    seeds the simulated games that estimate the visits, independently of the rollouts.
    """

    def __init__(self, scenario: Scenario, cfg: Train, model: ActorCritic, seed: int) -> None:
        from .solve.descent import WorstCaseGradient

        self.scenario, self.model, self.steps = scenario, model, cfg.descent_steps
        self.gradient = WorstCaseGradient(scenario, cfg.gamma)
        actors = [p for name, p in model.named_parameters() if name.startswith("actor_")]
        self.optimizer = torch.optim.Adam(actors, lr=cfg.descent_lr)
        self.rng = np.random.default_rng([seed, 3])
        self.last_value = float("nan")  # descent_value of the last step
        self._obs = torch.from_numpy(joint_observations(scenario))

    def step(self) -> dict[str, float]:
        """One best response and ``descent_steps`` actor steps; the metrics to log."""
        table = model_table(self.scenario, self.model, self.scenario.pursuers)
        value = self.last_value = self.gradient.refresh(table)
        rows, visits = self.gradient.visits(self.rng)
        rows, visits = self.gradient.sample(self.rng, rows, visits)
        advantages = torch.from_numpy(self.gradient.advantages(rows)).float()
        weights = torch.from_numpy(visits / visits.sum()).float()[:, None, None]
        obs = self._obs[rows]
        for _ in range(self.steps):
            probs = torch.softmax(self.model.actor_outputs(obs), dim=-1)
            loss = (weights * probs * advantages).sum()
            self.optimizer.zero_grad()
            loss.backward()
            self.optimizer.step()
        return {"descent_value": value, "descent_states": float(len(rows))}

    def state_dict(self) -> dict[str, Any]:
        """What a resume needs: the optimiser, the sampling generator and the values the
        next best response starts from."""
        return {
            "optimizer": self.optimizer.state_dict(),
            "rng": self.rng.bit_generator.state,
            "values": torch.from_numpy(self.gradient.values.copy()),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict`."""
        self.optimizer.load_state_dict(state["optimizer"])
        self.rng.bit_generator.state = state["rng"]
        self.gradient.values = state["values"].numpy().copy()
