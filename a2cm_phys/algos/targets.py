"""What a batch teaches (SPEC §6): its rewards as the learner sees them, the critics' values
and their bootstrap values, the critics' regression targets and the actors' advantage.

The advantages themselves are GAE's (:func:`~a2cm_phys.algos.returns.gae`); these are the
pieces around it, each a plain function of the batch, the config and the learner's state.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from .losses import NonFiniteLoss
from .returns import gae

if TYPE_CHECKING:
    from ..config import Train
    from .models import ActorCritic
    from .normalize import ValueNorm


def scaled_rewards(
    batch: Mapping[str, Any],
    cfg: Train,
    n_values: int,
    shaping: Callable[[Mapping[str, Any]], np.ndarray] | None,
) -> np.ndarray:
    """Scaled rewards ``(T, B, K)``: the components if the critics predict ``n_values > 1``,
    else the team reward as one component. Under the collision constraint the second
    component is minus the collision count (the constraint's cost), not the penalty."""
    if cfg.constrain_collisions:
        parts = np.asarray(batch["reward_parts"], dtype=np.float64).copy()
        parts[..., 1] = -np.asarray(batch["collisions"], dtype=np.float64)
    elif n_values > 1:
        parts = np.asarray(batch["reward_parts"], dtype=np.float64)
        if parts.shape[-1] != n_values:
            raise ValueError(
                f"reward_parts has {parts.shape[-1]} components, the critics predict {n_values}"
            )
    else:
        parts = np.asarray(batch["rewards"], dtype=np.float64)[..., None]
    if shaping is not None:  # added to the time component (a new array: the
        parts = parts.copy()  # batch's own rewards stay raw)
        parts[..., 0] += shaping(batch)
    return parts * cfg.reward_scale


def critic_values(model: ActorCritic, obs: torch.Tensor) -> torch.Tensor:
    """Critic outputs ``(..., C, K)`` (normalised units when the learner normalises values)."""
    out = model.value(obs)
    return out if model.n_values > 1 else out.unsqueeze(-1)


def bootstrapped_values(
    values_of: Callable[[torch.Tensor], torch.Tensor],
    obs: torch.Tensor,
    batch: Mapping[str, Any],
    trunc: np.ndarray,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The values ``(T, B, C, K)`` of the batch's observations and, as targets, of the state
    after each step: the next observation, the final observation where an episode was
    truncated, the observation after the batch. ``values_of`` maps observation rows to
    values; every row the batch needs goes through it in one call."""
    n_steps, n_envs = obs.shape[:2]
    dev = obs.device
    next_obs = torch.as_tensor(np.asarray(batch["next_obs"]), device=dev).float()
    final = torch.as_tensor(np.asarray(batch["final_obs"])[trunc], device=dev).float()
    flat = torch.cat([obs.reshape(n_steps * n_envs, -1), next_obs, final])
    every = values_of(flat)  # (rows, C, K)
    values = every[: n_steps * n_envs].unflatten(0, (n_steps, n_envs))
    extra = every[n_steps * n_envs :]
    next_values = torch.empty_like(values)
    next_values[:-1] = values[1:]
    next_values[-1] = extra[:n_envs]
    next_values[torch.as_tensor(trunc, device=dev)] = extra[n_envs:]
    return values, next_values


def advantages_and_targets(
    values_of: Callable[[torch.Tensor], torch.Tensor],
    obs: torch.Tensor,
    batch: Mapping[str, Any],
    rewards: np.ndarray,
    cfg: Train,
    value_norm: ValueNorm | None,
    critic_out: torch.nn.Module,
) -> tuple[np.ndarray, torch.Tensor]:
    """The batch's advantages ``(T, B, C, K)`` by GAE(γ, λ), per critic and reward component
    (reward units), and the critics' targets (:func:`critic_targets`).

    Args:
        values_of: observation rows → critic outputs ``(rows, C, K)`` in reward units.
        obs: the batch's observations ``(T, B, obs_dim)``.
        batch: the rest of the batch (``terminated``, ``truncated``, ``next_obs``,
            ``final_obs``).
        rewards: the scaled rewards ``(T, B, K)`` (:func:`scaled_rewards`).
        cfg: ``gamma`` and ``gae_lambda``.
        value_norm: the critics' value normaliser, or ``None``.
        critic_out: the critics' output layer, which the normaliser rescales.

    Raises:
        NonFiniteLoss: a return is NaN/inf (before the normaliser changes).
    """
    term = np.asarray(batch["terminated"], dtype=bool)
    trunc = np.asarray(batch["truncated"], dtype=bool)
    values, next_values = bootstrapped_values(values_of, obs, batch, trunc)
    adv = gae(
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
    returns = torch.as_tensor(adv, device=obs.device) + values.double()
    return adv, critic_targets(returns, value_norm, critic_out)


def critic_targets(
    returns: torch.Tensor, value_norm: ValueNorm | None, critic_out: torch.nn.Module
) -> torch.Tensor:
    """What the critics regress (float32): the returns, normalised when ``value_norm`` is on
    (which first takes in these returns and rescales ``critic_out``, PopArt)."""
    if value_norm is not None:
        value_norm.update(returns, critic_out)
        return value_norm.normalize(returns).float()
    return returns.float()


def actor_advantage(
    adv: torch.Tensor, cfg: Train, value_norm: ValueNorm | None, multiplier: float
) -> torch.Tensor:
    """``(T, B, C, K)`` component advantages → ``(T, B, C)`` advantage of the actors.

    The components are summed, each divided by its own scale (and the collision component
    weighed by ``collision_weight``) under ``split_rewards`` and ``balance_rewards``; under
    the collision constraint they are ``(A_time + λ·A_coll) / (1 + λ)`` with ``λ`` the
    ``multiplier``. Optionally normalised over the batch, per critic.
    """
    if cfg.split_rewards and cfg.balance_rewards and value_norm is not None:
        _, std = value_norm.stats()
        weight = torch.ones_like(std)
        weight[..., 1:] = cfg.collision_weight  # the collision component
        adv = adv * (weight / std).to(adv.dtype)
    if cfg.constrain_collisions:  # time + λ·(minus collisions), both normalised
        lam = multiplier
        combined = (adv[..., 0] + lam * adv[..., 1]) / (1.0 + lam)
    else:
        combined = adv.sum(-1)
    if cfg.normalize_advantages and len(combined) * combined.shape[1] > 1:
        # per critic: A2C's actor i sees only its own critic's advantages
        mean = combined.mean(dim=(0, 1), keepdim=True)
        std = combined.std(dim=(0, 1), keepdim=True)
        combined = (combined - mean) / (std + 1e-8)
    return combined.float()


def dual_ascent(multiplier: float, collisions: Any, cfg: Train) -> float:
    """The collision constraint's Lagrange multiplier after a batch with these collisions:
    ``max(0, λ + lagrange_lr · (collisions per step − collision_budget))``."""
    rate = float(np.mean(collisions))
    return max(0.0, multiplier + cfg.lagrange_lr * (rate - cfg.collision_budget))
