"""The A2C / A2CM loss and optimiser step over one time-major batch (SPEC §6).

A :class:`Learner` owns the RMSprop optimiser of an :class:`~a2cm_phys.algos.models.ActorCritic`
and turns one rollout batch into one gradient step:

1. values of ``obs`` (with grad) and, without grad, of ``next_obs`` (bootstrap) and of the
   final observations of truncated steps, all targets computed in one extra forward;
2. team returns by eq. 13 (:func:`~a2cm_phys.algos.returns.discounted_returns`): A2CM feeds
   them to its one critic, A2C broadcasts the same team reward to each agent's critic, which
   bootstraps with its own values; advantages ``G − V`` per critic (eq. 12), detached;
3. loss ``Σ_i [−mean(A_i · log π_i(a_i|s)) − entropy_coef · H(π_i)] + value_coef · Σ_c MSE_c``
   where ``A_i`` is agent i's critic's advantage (A2C) or the shared one (A2CM).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import torch

from a2cm_phys.algos.returns import advantages, discounted_returns

if TYPE_CHECKING:
    from a2cm_phys.algos.models import ActorCritic
    from a2cm_phys.config import Train

BATCH_KEYS = ("obs", "actions", "rewards", "terminated", "truncated", "final_obs", "next_obs")
"""Keys :meth:`Learner.update` reads from a batch (all time-major except ``next_obs``)."""


class NonFiniteLoss(FloatingPointError):
    """The loss or its gradient was NaN/inf; the optimiser was NOT stepped.

    The model and optimiser are exactly as before the failed :meth:`Learner.update`, so a
    trainer can stop and keep its last good checkpoint. ``metrics`` holds what was computed.
    """

    def __init__(self, message: str, metrics: dict[str, float]) -> None:
        super().__init__(message)
        self.metrics = metrics


class Learner:
    """Loss and RMSprop step for A2C / A2CM.

    Args:
        model: the network to train (its ``n_critics`` decides A2C vs A2CM behaviour).
        train_cfg: hyperparameters: ``lr``, ``rmsprop_alpha`` (Keras rho), ``rmsprop_eps``,
            ``gamma``, ``entropy_coef``, ``value_coef``, ``reward_scale``, ``max_grad_norm``.
    """

    def __init__(self, model: ActorCritic, train_cfg: Train) -> None:
        self.model = model
        self.cfg = train_cfg
        # torch RMSprop = Keras RMSprop (non-centred, no momentum, eps outside the sqrt)
        self.optimizer = torch.optim.RMSprop(
            model.parameters(),
            lr=train_cfg.lr,
            alpha=train_cfg.rmsprop_alpha,
            eps=train_cfg.rmsprop_eps,
        )
        self.device = next(model.parameters()).device

    def update(self, batch: Mapping[str, Any]) -> dict[str, float]:
        """One gradient step on a rollout batch; returns scalar metrics.

        Args:
            batch: tensors (or arrays) keyed as in :data:`BATCH_KEYS`: ``obs (T,B,obs_dim)``,
                ``actions (T,B,N)`` int64, ``rewards (T,B)`` raw team reward (multiplied by
                ``reward_scale`` here), ``terminated (T,B)`` and ``truncated (T,B)`` bool,
                ``final_obs (T,B,obs_dim)`` (the episode's last observation where it ended;
                only read where truncated), ``next_obs (B,obs_dim)`` (after the batch).

        Returns:
            ``policy_loss`` (Σ over agents), ``value_loss`` (Σ over critics of the MSE, before
            ``value_coef``), ``entropy`` (mean over agents and steps), ``mean_advantage``,
            ``grad_norm`` (total, before clipping) and ``loss`` (the optimised total).

        Raises:
            NonFiniteLoss: the loss or the gradient norm is NaN/inf (no step was taken).
        """
        b = {k: torch.as_tensor(batch[k], device=self.device) for k in BATCH_KEYS}
        obs = b["obs"].float()
        truncated = b["truncated"].bool()
        n_envs = obs.shape[1]

        logits, values = self.model(obs)  # (T,B,N,A), (T,B,C)
        with torch.no_grad():
            # one critic forward for the bootstrap state and every truncated final obs
            extra = torch.cat([b["next_obs"].float(), b["final_obs"].float()[truncated]])
            extra_values = self.model.value(extra)
            boot = extra_values[:n_envs]
            trunc_values = values.new_zeros(values.shape)
            trunc_values[truncated] = extra_values[n_envs:]
            returns = discounted_returns(
                b["rewards"].float() * self.cfg.reward_scale,
                b["terminated"],
                truncated,
                boot,
                trunc_values,
                self.cfg.gamma,
            ).to(values.dtype)  # (T,B,C): A2C broadcasts the team reward to every critic
            adv = advantages(returns, values.detach())  # (T,B,C), broadcasts over agents

        log_probs = torch.log_softmax(logits, -1)
        taken = log_probs.gather(-1, b["actions"].long().unsqueeze(-1)).squeeze(-1)  # (T,B,N)
        entropy = -(log_probs.exp() * log_probs).sum(-1)  # (T,B,N)
        policy_loss = -(adv * taken).mean(dim=(0, 1)).sum()
        entropy_sum = entropy.mean(dim=(0, 1)).sum()
        value_loss = (returns - values).pow(2).mean(dim=(0, 1)).sum()
        loss = policy_loss - self.cfg.entropy_coef * entropy_sum + self.cfg.value_coef * value_loss

        metrics = {
            "policy_loss": policy_loss.item(),
            "value_loss": value_loss.item(),
            "entropy": entropy_sum.item() / self.model.n_agents,
            "mean_advantage": adv.mean().item(),
            "loss": loss.item(),
            "grad_norm": math.nan,
        }
        if not math.isfinite(metrics["loss"]):
            raise NonFiniteLoss(f"non-finite loss {metrics['loss']} (no step taken)", metrics)

        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        params = [p for p in self.model.parameters() if p.grad is not None]
        if self.cfg.max_grad_norm > 0:
            norm = torch.nn.utils.clip_grad_norm_(params, self.cfg.max_grad_norm)
        else:
            norm = torch.nn.utils.get_total_norm([p.grad for p in params])
        metrics["grad_norm"] = norm.item()
        if not math.isfinite(metrics["grad_norm"]):
            self.optimizer.zero_grad(set_to_none=True)
            raise NonFiniteLoss(
                f"non-finite gradient norm {metrics['grad_norm']} (no step taken)", metrics
            )
        self.optimizer.step()
        self.model.refresh_snapshot()
        return metrics

    def state_dict(self) -> dict[str, Any]:
        """Model and optimiser state, for a bit-exact resume.

        A deep copy: torch's own state dicts alias the live tensors, so an in-memory "last
        good checkpoint" would otherwise change with every later update.
        """
        return copy.deepcopy(
            {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict()}
        )

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned (model weights and RMSprop averages).

        ``state`` is copied, never aliased, so it can be loaded again later.
        """
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(copy.deepcopy(state["optimizer"]))
        self.model.refresh_snapshot()
