"""Exploitability descent in grid self-play: the pursuers learn against the exact best
response to themselves (``Train.descent_every``).

Self-play's learned evader is far from a best response, so pursuers trained against it
(simultaneously or against a pool, :mod:`a2cm_phys.training.opponents`) stay exploitable: an evader
that plays the exact best response escapes them for good (``BENCHMARKS.md``). On a grid
the exact best response is computable, and so is the gradient of its value in the
pursuers' policy (:mod:`a2cm_phys.solve.worst_case`). With ``descent_every = K`` the
pursuers' actors learn from that gradient alone: every K updates
:class:`ExploitabilityDescent` computes it for their current actors and takes
``descent_steps`` Adam steps (step size ``descent_lr``, or with ``descent_schedule =
"linear"`` that size annealed linearly to 0 over the run, as ``lr_schedule`` anneals the
learner's) along it. The rollouts go on as in
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

With ``descent_teams = "both"`` the evader learns the same way, from the other side: at
the same steps the pursuers' exact best response to its current actor is solved (the
oracle's backup, warm-started), and the evader's actor takes ``descent_steps`` Adam steps
*up* its value (``L = −Σ_s w(s) Σ_b σ(b | s) · A(s, b)``), logged as
``evader_descent_value``; its rollout learner is not stepped either. Both teams then
descend their exploitability at once, as in Lockhart et al.'s exploitability descent.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..algos import ActorCritic
from ..algos.optimizer import set_learning_rate
from ..config import ConfigError, Scenario, Train
from ..solve.tables import joint_observations, model_table, uniform_table
from ..solve.transitions import TooLargeError, UnsupportedError
from .seeding import descent_rng, evader_descent_rng


def check_descent(scenario: Scenario, cfg: Train) -> None:
    """Whether the exact solvers that descent needs can hold the arena: a
    :class:`ConfigError` naming ``descent_every`` (or ``descent_teams`` for the evader's
    descent) if not. Every other check of the options is
    :func:`~a2cm_phys.config.resolve_train`'s; this one is made when descent is set up,
    since only the solvers know their limits."""
    if not cfg.descent_every:
        return
    from ..solve.model import GridModel
    from ..solve.pursuer_step import check_size

    try:
        check_size(scenario, "general")
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"training options: key 'descent_every': {err}") from None
    if cfg.descent_teams == "both":  # the oracle's backup against the evader's table
        try:
            GridModel(scenario, evader_probs=uniform_table(scenario, 1))
        except (TooLargeError, UnsupportedError) as err:
            raise ConfigError(f"training options: key 'descent_teams': {err}") from None


class ExploitabilityDescent:
    """The pursuers' actors stepping down the value of the evader's exact best response
    (and with ``descent_teams = "both"`` the evader's actor stepping up the value of the
    pursuers' exact best response).

    ``model`` is the pursuers' actor–critic, ``evader`` the learned evader's (their actors
    are stepped in place; ``evader`` is needed with ``"both"`` only). ``seed`` seeds the
    simulated games that estimate the visits, independently of the rollouts.
    """

    def __init__(
        self,
        scenario: Scenario,
        cfg: Train,
        model: ActorCritic,
        seed: int,
        evader: ActorCritic | None = None,
    ) -> None:
        from ..solve.worst_case import EvaderGradient, WorstCaseGradient

        check_descent(scenario, cfg)
        self.scenario, self.model, self.steps = scenario, model, cfg.descent_steps
        self.lr, self.schedule = cfg.descent_lr, cfg.descent_schedule
        self.gradient = WorstCaseGradient(scenario, cfg.gamma)
        self.optimizer = _actor_adam(model, cfg.descent_lr)
        self.rng = descent_rng(seed)
        self.last_value = float("nan")  # descent_value of the last step
        self.last_evader_value = float("nan")  # evader_descent_value of the last step
        self._obs = torch.from_numpy(joint_observations(scenario))
        self.evader = evader if cfg.descent_teams == "both" else None
        if cfg.descent_teams == "both" and evader is None:
            raise ValueError("descent_teams = 'both' needs the evader's model")
        if self.evader is not None:
            self.evader_gradient = EvaderGradient(scenario, cfg.gamma, self.gradient)
            self.evader_optimizer = _actor_adam(self.evader, cfg.descent_lr)
            self.evader_rng = evader_descent_rng(seed)

    def step(self, progress: float = 0.0) -> dict[str, float]:
        """One best response to each learning team and ``descent_steps`` actor steps each,
        ``progress`` (the run's fraction done) through it setting the step size under a
        linear ``descent_schedule``; the metrics to log."""
        if self.schedule == "linear":
            set_learning_rate(self.optimizer, self.lr * (1.0 - progress))
            if self.evader is not None:
                set_learning_rate(self.evader_optimizer, self.lr * (1.0 - progress))
        table = model_table(self.scenario, self.model, self.scenario.pursuers)
        value = self.last_value = self.gradient.refresh(table)
        rows, visits = self.gradient.visits(self.rng)
        rows, visits = self.gradient.sample(self.rng, rows, visits)
        advantages = self.gradient.advantages(rows)
        self._actor_steps(self.model, self.optimizer, rows, visits, advantages, sign=1.0)
        metrics = {"descent_value": value, "descent_states": float(len(rows))}
        if self.evader is not None:
            e = self.evader_gradient
            value = self.last_evader_value = e.refresh(model_table(self.scenario, self.evader, 1))
            rows, visits = self.gradient.sample(self.evader_rng, *e.visits(self.evader_rng))
            advantages = e.advantages(rows)[:, None, :]  # one agent
            self._actor_steps(self.evader, self.evader_optimizer, rows, visits, advantages, -1.0)
            metrics.update(evader_descent_value=value, evader_descent_states=float(len(rows)))
        return metrics

    def _actor_steps(
        self,
        model: ActorCritic,
        optimizer: torch.optim.Optimizer,
        rows: np.ndarray,
        visits: np.ndarray,
        advantages: np.ndarray,
        sign: float,
    ) -> None:
        """``descent_steps`` steps on ``sign · Σ w π A``: down (+1) or up (−1) the value."""
        adv = torch.from_numpy(advantages).float()
        weights = torch.from_numpy(visits / visits.sum()).float()[:, None, None]
        obs = self._obs[rows]
        for _ in range(self.steps):
            probs = torch.softmax(model.actor_outputs(obs), dim=-1)
            loss = sign * (weights * probs * adv).sum()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()

    def state_dict(self) -> dict[str, Any]:
        """What a resume needs: the optimisers, the sampling generator and the values the
        next best responses start from."""
        state = {
            "optimizer": self.optimizer.state_dict(),
            "rng": self.rng.bit_generator.state,
            "values": torch.from_numpy(self.gradient.values.copy()),
        }
        if self.evader is not None:
            values = self.evader_gradient.values
            state["evader_optimizer"] = self.evader_optimizer.state_dict()
            state["evader_rng"] = self.evader_rng.bit_generator.state
            state["evader_values"] = None if values is None else torch.from_numpy(values.copy())
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state_dict`."""
        self.optimizer.load_state_dict(state["optimizer"])
        self.rng.bit_generator.state = state["rng"]
        self.gradient.values = state["values"].numpy().copy()
        if self.evader is not None:
            self.evader_optimizer.load_state_dict(state["evader_optimizer"])
            self.evader_rng.bit_generator.state = state["evader_rng"]
            values = state["evader_values"]
            self.evader_gradient.values = None if values is None else values.numpy().copy()


def _actor_adam(model: ActorCritic, lr: float) -> torch.optim.Adam:
    """Adam over a model's actors (the critics are not descended)."""
    actors = [p for name, p in model.named_parameters() if name.startswith("actor_")]
    return torch.optim.Adam(actors, lr=lr)
