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
   ``mean_bound_coef`` times a soft bound on their means (:func:`mean_bound_loss`), and one
   optimiser step (RMSprop as Keras has it, the paper's, or Adam), with optional gradient
   clipping.

Rewards arrive raw (the team reward, or its components ``reward_parts``), get an optional
shaping term (:mod:`~a2cm_phys.algos.shaping`) and are multiplied by ``reward_scale`` here:
what the learner sees is documented in the run's config.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..config import PRESETS
from .normalize import ValueNorm
from .returns import gae
from .rmsprop import KerasRMSprop

if TYPE_CHECKING:
    from ..config import Train
    from .models import ActorCritic

BATCH_KEYS = ("obs", "actions", "rewards", "terminated", "truncated", "final_obs", "next_obs")
"""Keys :meth:`Learner.update` reads from a batch (all time-major except ``next_obs``); a
batch may add ``reward_parts (T, B, K)``, the reward's components, for ``split_rewards``."""


MEAN_BOUND = 1.1
"""Where the soft bound on Gaussian means starts: a little past the command box's ±1, so a
mean can still command full speed along an axis."""


def mean_bound_loss(means: torch.Tensor) -> torch.Tensor:
    """``Σ_agents,dims mean_batch [relu(μ − b)² + relu(−μ − b)²]`` with ``b = MEAN_BOUND``.

    A Gaussian actor's unbounded mean drifts past the env's clip under the optimiser's
    noise; there every sample is clipped to the same command and the gradient carries no
    information about the game (measured: against a static evader the means ran to −25 and
    the team never captured). This soft bound (rl_games' ``bounds_loss``) pulls them back
    without squashing, so log-probabilities stay those of the plain Gaussian.
    ``means``: ``(T, B, N, dim)``.
    """
    over = (means - MEAN_BOUND).clamp(min=0) ** 2 + (means + MEAN_BOUND).clamp(max=0) ** 2
    return over.mean(dim=(0, 1)).sum()


class NonFiniteLoss(FloatingPointError):
    """The loss or its gradient was NaN/inf; the optimiser was NOT stepped.

    The model and optimiser are exactly as before the failed :meth:`Learner.update`, so a
    trainer can stop and keep its last good checkpoint. ``metrics`` holds what was computed.
    """

    def __init__(self, message: str, metrics: dict[str, float]) -> None:
        super().__init__(message)
        self.metrics = metrics


def make_optimizer(model: torch.nn.Module, cfg: Train) -> torch.optim.Optimizer | KerasRMSprop:
    """RMSprop as the paper's Keras has it (non-centred, no momentum, eps outside the
    square root: torch's RMSprop with ``alpha = rho``, :mod:`.rmsprop`), or Adam."""
    if cfg.optimizer == "adam":
        return torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
    return KerasRMSprop(
        model.parameters(), lr=cfg.lr, alpha=cfg.rmsprop_alpha, eps=cfg.rmsprop_eps
    )


class Learner:
    """Loss and optimiser step for A2C / A2CM over any action distribution.

    Args:
        model: the network to train (its ``n_critics`` decides A2C vs A2CM behaviour and
            its ``n_values`` the number of reward components).
        train_cfg: ``lr``, ``optimizer`` and its constants, ``gamma``, ``gae_lambda``,
            ``entropy_coef``, ``value_coef``, ``reward_scale``, ``max_grad_norm``,
            ``normalize_advantages``, ``value_norm``, ``split_rewards``.
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
        self.model = model
        self.cfg = train_cfg
        entropy = train_cfg.entropy_coef  # None: unresolved (no scenario), the paper's value
        self.entropy_coef = PRESETS["paper"]["entropy_coef"] if entropy is None else entropy
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
        dev = self.device
        obs = torch.as_tensor(np.asarray(batch["obs"]), device=dev, dtype=torch.float32)
        n_steps, n_envs = obs.shape[:2]
        term = np.asarray(batch["terminated"], dtype=bool)
        trunc = np.asarray(batch["truncated"], dtype=bool)
        rewards = self._rewards(batch)  # (T, B, 1 or K), scaled, float64

        with torch.no_grad():  # targets: every value the batch needs, in one forward
            next_obs = torch.as_tensor(np.asarray(batch["next_obs"]), device=dev).float()
            final = torch.as_tensor(np.asarray(batch["final_obs"])[trunc], device=dev).float()
            flat = torch.cat([obs.reshape(n_steps * n_envs, -1), next_obs, final])
            every = self._to_reward_units(self._critic(flat))  # (rows, C, K)
            values = every[: n_steps * n_envs].unflatten(0, (n_steps, n_envs))
            extra = every[n_steps * n_envs :]
            next_values = torch.empty_like(values)
            next_values[:-1] = values[1:]
            next_values[-1] = extra[:n_envs]
            next_values[torch.as_tensor(trunc, device=dev)] = extra[n_envs:]
            adv = gae(  # (T, B, C, K)
                rewards[:, :, None, :],
                values.cpu().numpy(),
                next_values.cpu().numpy(),
                term,
                trunc,
                cfg.gamma,
                cfg.gae_lambda,
            )
            if not np.isfinite(adv).all():  # before anything (normaliser, λ) changes
                raise NonFiniteLoss(
                    "non-finite returns (no step taken)", {"loss": math.nan, "grad_norm": math.nan}
                )
            returns = torch.as_tensor(adv, device=dev) + values.double()
            if self.value_norm is not None:  # rescales the output layer (PopArt)
                self.value_norm.update(returns, model.critic_out)
                targets = self.value_norm.normalize(returns).float()
            else:
                targets = returns.float()
            actor_adv = self._actor_advantage(torch.as_tensor(adv, device=dev))  # (T,B,C)
            if cfg.constrain_collisions:  # dual ascent on λ (after it weighed this batch)
                rate = float(np.mean(batch["collisions"]))
                self.multiplier = max(
                    0.0, self.multiplier + cfg.lagrange_lr * (rate - cfg.collision_budget)
                )

        out = self._critic(obs)  # (T, B, C, K), with gradient
        dist_out = model.actor_outputs(obs)
        dist = model.dist.torch(dist_out, model.log_std)
        actions = torch.as_tensor(np.asarray(batch["actions"]), device=dev)
        if model.log_std is None:
            actions = actions.long()
        log_prob = dist.log_prob(actions)  # (T, B, N)
        entropy = dist.entropy()  # (T, B, N)
        policy_loss = -(actor_adv * log_prob).mean(dim=(0, 1)).sum()
        entropy_sum = entropy.mean(dim=(0, 1)).sum()
        value_loss = (targets - out).pow(2).mean(dim=(0, 1)).sum()
        entropy_coef = self.entropy_coef
        if cfg.entropy_schedule == "linear":  # None: unresolved, the paper's constant
            entropy_coef *= 1.0 - progress
        loss = policy_loss - entropy_coef * entropy_sum + cfg.value_coef * value_loss
        if model.log_std is not None and cfg.mean_bound_coef:  # None (unresolved): off
            loss = loss + cfg.mean_bound_coef * mean_bound_loss(dist_out)

        p_loss, v_loss, ent, total = torch.stack(
            [policy_loss, value_loss, entropy_sum, loss]
        ).tolist()
        metrics = {
            "policy_loss": p_loss,
            "value_loss": v_loss,
            "entropy": ent / model.n_agents,
            "mean_advantage": float(adv.mean()),
            "loss": total,
            "grad_norm": math.nan,
        }
        if cfg.constrain_collisions:
            metrics["multiplier"] = self.multiplier
        if not math.isfinite(total):
            raise NonFiniteLoss(f"non-finite loss {total} (no step taken)", metrics)
        model.zero_grad(set_to_none=True)  # the optimiser's own adds a profiler span
        loss.backward()
        params = [p for p in model.parameters() if p.grad is not None]
        if cfg.max_grad_norm:  # 0, or None (not resolved for a scenario): no clipping
            norm = torch.nn.utils.clip_grad_norm_(params, cfg.max_grad_norm)
        else:
            norm = torch.nn.utils.get_total_norm([p.grad for p in params])
        metrics["grad_norm"] = norm.item()
        if not math.isfinite(metrics["grad_norm"]):
            self.optimizer.zero_grad(set_to_none=True)
            raise NonFiniteLoss(
                f"non-finite gradient norm {metrics['grad_norm']} (no step taken)", metrics
            )
        if cfg.lr_schedule == "linear":
            for group in self.optimizer.param_groups:
                group["lr"] = cfg.lr * (1.0 - progress)
        self.optimizer.step()
        return metrics

    # ------------------------------------------------------------------ pieces
    def _rewards(self, batch: Mapping[str, Any]) -> np.ndarray:
        """Scaled rewards ``(T, B, K)``: the components if the model has K values, else
        the team reward as one component. Under the collision constraint the second
        component is minus the collision count (the constraint's cost), not the penalty."""
        if self.cfg.constrain_collisions:
            parts = np.asarray(batch["reward_parts"], dtype=np.float64).copy()
            parts[..., 1] = -np.asarray(batch["collisions"], dtype=np.float64)
        elif self.model.n_values > 1:
            parts = np.asarray(batch["reward_parts"], dtype=np.float64)
            if parts.shape[-1] != self.model.n_values:
                raise ValueError(
                    f"reward_parts has {parts.shape[-1]} components, the critics predict "
                    f"{self.model.n_values}"
                )
        else:
            parts = np.asarray(batch["rewards"], dtype=np.float64)[..., None]
        if self.shaping is not None:  # added to the time component (a new array: the
            parts = parts.copy()  # batch's own rewards stay raw)
            parts[..., 0] += self.shaping(batch)
        return parts * self.cfg.reward_scale

    def _critic(self, obs: torch.Tensor) -> torch.Tensor:
        """Critic outputs ``(..., C, K)`` (normalised units when ``value_norm``)."""
        out = self.model.value(obs)
        return out if self.model.n_values > 1 else out.unsqueeze(-1)

    def _to_reward_units(self, out: torch.Tensor) -> torch.Tensor:
        """Critic outputs ``(..., K)`` as values in (scaled) reward units."""
        return out if self.value_norm is None else self.value_norm.denormalize(out)

    def _actor_advantage(self, adv: torch.Tensor) -> torch.Tensor:
        """``(T, B, C, K)`` component advantages → ``(T, B, C)`` advantage of the actors."""
        if self.cfg.split_rewards and self.cfg.balance_rewards and self.value_norm is not None:
            _, std = self.value_norm.stats()
            weight = torch.ones_like(std)
            weight[..., 1:] = self.cfg.collision_weight  # the collision component
            adv = adv * (weight / std).to(adv.dtype)
        if self.cfg.constrain_collisions:  # time + λ·(minus collisions), both normalised
            lam = self.multiplier
            combined = (adv[..., 0] + lam * adv[..., 1]) / (1.0 + lam)
        else:
            combined = adv.sum(-1)
        if self.cfg.normalize_advantages and len(combined) * combined.shape[1] > 1:
            # per critic: A2C's actor i sees only its own critic's advantages
            mean = combined.mean(dim=(0, 1), keepdim=True)
            std = combined.std(dim=(0, 1), keepdim=True)
            combined = (combined - mean) / (std + 1e-8)
        return combined.float()

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
