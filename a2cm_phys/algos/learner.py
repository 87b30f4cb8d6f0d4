"""The A2C / A2CM loss and optimiser step over one time-major batch (SPEC §6).

One autograd learner for every action type (the policy is a distribution object, see
:mod:`~a2cm_phys.algos.distributions`) and for both algorithms (A2CM has one critic, A2C
one per agent: the only difference). An update is a sequence of small pieces:

1. **values** of the batch's observations and, as targets, of the state after each step
   (the next observation, the final observation of a truncated episode, the observation
   after the batch), in reward units (:class:`~a2cm_phys.algos.normalize.ValueNorm`
   un-normalises them when ``value_norm`` is on);
2. **advantages** by GAE(γ, λ) (:func:`~a2cm_phys.algos.returns.gae`; ``λ = 1`` gives the
   paper's eq. 13 returns), per critic and per reward component; terminated and truncated
   steps are kept apart all the way (a truncated step is bootstrapped, never terminal);
3. **the actors' advantage**: the components' advantages summed (each divided by its own
   scale when ``split_rewards``, so that a rare catastrophic cost and a small running cost
   both reach the policy), optionally normalised over the batch; A2C gives actor i its own
   critic's advantage, A2CM the shared one. With ``constrain_collisions`` the collision
   component is a constraint instead of a cost: the actors maximise the time objective
   subject to at most ``collision_budget`` collisions per step, ``A = (A_time + λ·A_coll) /
   (1 + λ)``, with the Lagrange multiplier ``λ ≥ 0`` learned by dual ascent (``λ += lagrange_lr
   · (collisions per step − budget)`` after each batch): it starts at 0, so the team first
   learns to catch, and rises only as long as collisions happen;
4. **loss** ``Σ_i [−mean(A_i · log π_i(a_i|s)) − entropy_coef · H(π_i)] + value_coef ·
   Σ_c MSE_c`` (critics regress their normalised targets; ``entropy_coef`` annealed
   linearly to 0 when ``entropy_schedule = "linear"``), plus for Gaussian actors
   ``mean_bound_coef`` times a soft bound on their means
   (:func:`~a2cm_phys.algos.losses.mean_bound_loss`), and one optimiser step (RMSprop as
   Keras has it, the paper's, or Adam), with optional gradient clipping.

Rewards arrive raw (the team reward, or its components ``reward_parts``), get an optional
shaping term (:mod:`~a2cm_phys.algos.shaping`) and are multiplied by ``reward_scale`` here:
what the learner sees is documented in the run's config.

The pieces live beside this module: the batch's rewards, values and advantages in
:mod:`.targets`, the loss in :mod:`.losses`, the optimiser and the gradient in
:mod:`.optimizer`; :class:`Learner` holds the state between updates and runs them in order.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from .losses import Losses, NonFiniteLoss, a2c_losses, entropy_coef, loss_metrics
from .normalize import ValueNorm
from .optimizer import backpropagate, make_optimizer, set_learning_rate
from .recurrent import learner_inputs
from .targets import (
    actor_advantage,
    advantages_and_targets,
    critic_values,
    dual_ascent,
    scaled_rewards,
)

if TYPE_CHECKING:
    from ..config import Train
    from .models import ActorCritic

__all__ = ["BATCH_KEYS", "Learner"]

BATCH_KEYS = ("obs", "actions", "rewards", "terminated", "truncated", "final_obs", "next_obs")
"""Keys :meth:`Learner.update` reads from a batch (all time-major except ``next_obs``); a
batch may add ``reward_parts (T, B, K)``, the reward's components, for ``split_rewards``,
and a recurrent model's needs ``memory (B, N, hidden)``, the memories at the rollout's start
(:func:`~a2cm_phys.algos.recurrent.learner_inputs`)."""


class Learner:
    """Loss and optimiser step for A2C / A2CM over any action distribution.

    Args:
        model: the network to train (its ``n_critics`` decides A2C vs A2CM behaviour and
            its ``n_values`` the number of reward components).
        train_cfg: a resolved config (:func:`~a2cm_phys.config.resolve_train`): ``lr``,
            ``optimizer`` and its constants, ``gamma``, ``gae_lambda``, ``entropy_coef``,
            ``value_coef``, ``reward_scale``, ``max_grad_norm``, ``normalize_advantages``,
            ``value_norm``, ``split_rewards``.
        shaping: optional shaping term ``shaping(batch) -> (T, B)`` added to the (first)
            reward component before scaling, e.g.
            :class:`~a2cm_phys.algos.shaping.ProgressShaping`.
    """

    def __init__(
        self,
        model: ActorCritic,
        train_cfg: Train,
        shaping: Callable[[Mapping[str, Any]], np.ndarray] | None = None,
    ) -> None:
        self.model, self.cfg = model, train_cfg
        self.entropy_coef = train_cfg.entropy_coef
        self.shaping = shaping
        self.optimizer = make_optimizer(model, train_cfg)
        self.device = next(model.parameters()).device
        self.value_norm = (
            ValueNorm((model.n_critics, model.n_values), beta=train_cfg.value_norm_beta)
            if train_cfg.value_norm
            else None
        )
        self.multiplier = 0.0  # the collision constraint's Lagrange multiplier λ ≥ 0

    def update(self, batch: Mapping[str, Any], progress: float = 0.0) -> dict[str, float]:
        """One gradient step on a rollout batch; returns scalar metrics.

        Args:
            batch: arrays keyed as in :data:`BATCH_KEYS`: ``obs (T,B,obs_dim)``, ``actions
                (T,B,N,*action_shape)``, ``rewards (T,B)`` raw team reward (or
                ``reward_parts (T,B,K)`` when the model has K values per critic),
                ``terminated``/``truncated (T,B)`` bool, ``final_obs (T,B,obs_dim)`` (only
                read where truncated), ``next_obs (B,obs_dim)``.
            progress: the fraction of the run done before this update, in ``[0, 1)``: the
                learning rate is ``lr · (1 − progress)`` when ``lr_schedule = "linear"``,
                and the entropy coefficient likewise under ``entropy_schedule``.

        Returns:
            ``policy_loss`` (Σ over agents), ``value_loss`` (Σ over critics and components
            of the MSE of normalised targets, before ``value_coef``), ``entropy`` (mean over
            agents and steps), ``mean_advantage`` (reward units), ``grad_norm`` (before
            clipping) and ``loss`` (the optimised total).

        Raises:
            NonFiniteLoss: the loss or the gradient norm is NaN/inf (no step was taken).
        """
        cfg, model = self.cfg, self.model
        obs = torch.as_tensor(np.asarray(batch["obs"]), device=self.device, dtype=torch.float32)
        states = batch  # where the values are read: with recurrent actors, with memories
        if model.recurrent:  # each observation with the memory it was acted on
            obs, states = learner_inputs(model, obs, batch)
        adv, targets, actor_adv = self._targets(batch, obs, states)
        losses = a2c_losses(
            model,
            self._critic,
            obs,
            batch["actions"],
            actor_adv,
            targets,
            entropy_coef=entropy_coef(self.entropy_coef, cfg.entropy_schedule, progress),
            value_coef=cfg.value_coef,
            mean_bound_coef=cfg.mean_bound_coef,
            mean_bound=cfg.mean_bound,
        )
        metrics = loss_metrics(losses, adv, model.n_agents)
        if cfg.constrain_collisions:
            metrics["multiplier"] = self.multiplier
        if not math.isfinite(metrics["loss"]):
            raise NonFiniteLoss(f"non-finite loss {metrics['loss']} (no step taken)", metrics)
        self._step(losses, metrics, progress)
        return metrics

    # ------------------------------------------------------------------ pieces
    def _targets(
        self, batch: Mapping[str, Any], obs: torch.Tensor, states: Mapping[str, Any]
    ) -> tuple[np.ndarray, torch.Tensor, torch.Tensor]:
        """The batch's component advantages ``(T, B, C, K)`` (reward units), the critics'
        targets and the actors' advantage ``(T, B, C)``, the values read from ``obs`` and
        ``states`` (the batch, or its view with memories); moves the value normaliser and
        the multiplier on by this batch."""
        rewards = self._rewards(batch)  # (T, B, 1 or K), scaled, float64
        with torch.no_grad():
            adv, targets = advantages_and_targets(
                self._values, obs, states, rewards, self.cfg, self.value_norm, self.model.critic_out
            )
            actor_adv = self._actor_advantage(torch.as_tensor(adv, device=self.device))
            if self.cfg.constrain_collisions:  # dual ascent on λ (after it weighed this batch)
                self.multiplier = dual_ascent(self.multiplier, batch["collisions"], self.cfg)
        return adv, targets, actor_adv

    def _step(self, losses: Losses, metrics: dict[str, float], progress: float) -> None:
        """Backpropagate, record the gradient norm in ``metrics`` and step the optimiser
        (at the scheduled learning rate), unless the norm is NaN/inf."""
        cfg = self.cfg
        metrics["grad_norm"] = backpropagate(self.model, losses.total, cfg.max_grad_norm)
        if not math.isfinite(metrics["grad_norm"]):
            self.optimizer.zero_grad(set_to_none=True)
            raise NonFiniteLoss(
                f"non-finite gradient norm {metrics['grad_norm']} (no step taken)", metrics
            )
        if cfg.lr_schedule == "linear":
            set_learning_rate(self.optimizer, cfg.lr * (1.0 - progress))
        self.optimizer.step()

    def _rewards(self, batch: Mapping[str, Any]) -> np.ndarray:
        """Scaled rewards ``(T, B, K)``, :func:`~a2cm_phys.algos.targets.scaled_rewards`."""
        return scaled_rewards(batch, self.cfg, self.model.n_values, self.shaping)

    def _critic(self, obs: torch.Tensor) -> torch.Tensor:
        """Critic outputs ``(..., C, K)`` (normalised units when ``value_norm``)."""
        return critic_values(self.model, obs)

    def _values(self, obs: torch.Tensor) -> torch.Tensor:
        """Critic outputs ``(..., C, K)`` as values in (scaled) reward units."""
        out = self._critic(obs)
        return out if self.value_norm is None else self.value_norm.denormalize(out)

    def _actor_advantage(self, adv: torch.Tensor) -> torch.Tensor:
        """``(T, B, C, K)`` component advantages → ``(T, B, C)`` advantage of the actors."""
        return actor_advantage(adv, self.cfg, self.value_norm, self.multiplier)

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        """Model, optimiser and normaliser state, for a bit-exact resume (a deep copy:
        torch's own state dicts alias the live tensors)."""
        state = {
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "multiplier": self.multiplier,
        }
        if self.value_norm is not None:
            state["value_norm"] = self.value_norm.state_dict()
        return copy.deepcopy(state)

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned (copied, never aliased)."""
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(copy.deepcopy(state["optimizer"]))
        if self.value_norm is not None and "value_norm" in state:
            self.value_norm.load_state_dict(state["value_norm"])
        self.multiplier = float(state.get("multiplier", 0.0))
