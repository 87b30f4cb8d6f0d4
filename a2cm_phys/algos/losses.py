"""The A2C / A2CM loss of one batch (SPEC §6) and the soft bound on Gaussian means.

``Σ_i [−mean(A_i · log π_i(a_i|s)) − entropy_coef · H(π_i)] + value_coef · Σ_c MSE_c``,
plus for Gaussian actors ``mean_bound_coef`` times :func:`mean_bound_loss`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import torch

if TYPE_CHECKING:
    from .models import ActorCritic


def mean_bound_loss(means: torch.Tensor, bound: float) -> torch.Tensor:
    """``Σ_agents,dims mean_batch [relu(μ − b)² + relu(−μ − b)²]`` with ``b = bound``
    (``Train.mean_bound``).

    A Gaussian actor's unbounded mean drifts past the env's clip under the optimiser's
    noise; there every sample is clipped to the same command and the gradient carries no
    information about the game (measured: against a static evader the means ran to −25 and
    the team never captured). This soft bound (rl_games' ``bounds_loss``) pulls them back
    without squashing, so log-probabilities stay those of the plain Gaussian.
    ``means``: ``(T, B, N, dim)``.
    """
    over = (means - bound).clamp(min=0) ** 2 + (means + bound).clamp(max=0) ** 2
    return over.mean(dim=(0, 1)).sum()


class NonFiniteLoss(FloatingPointError):
    """The loss or its gradient was NaN/inf; the optimiser was NOT stepped.

    The model and optimiser are exactly as before the failed
    :meth:`~a2cm_phys.algos.learner.Learner.update`, so a trainer can stop and keep its last
    good checkpoint. ``metrics`` holds what was computed.
    """

    def __init__(self, message: str, metrics: dict[str, float]) -> None:
        super().__init__(message)
        self.metrics = metrics


class Losses(NamedTuple):
    """The loss's terms (scalar tensors): ``policy`` (Σ over agents), ``value`` (Σ over
    critics and components of the MSE, before ``value_coef``), ``entropy`` (Σ over agents
    of the mean entropy) and ``total``, the one optimised."""

    policy: torch.Tensor
    value: torch.Tensor
    entropy: torch.Tensor
    total: torch.Tensor


def a2c_losses(
    model: ActorCritic,
    critic: Callable[[torch.Tensor], torch.Tensor],
    obs: torch.Tensor,
    actions: Any,
    actor_adv: torch.Tensor,
    targets: torch.Tensor,
    *,
    entropy_coef: float,
    value_coef: float,
    mean_bound_coef: float | None,
    mean_bound: float,
) -> Losses:
    """The loss of a batch, with gradient.

    Args:
        model: the actors (and, through ``critic``, the critics).
        critic: observations ``(T, B, obs_dim)`` → critic outputs ``(T, B, C, K)``.
        obs: the batch's observations ``(T, B, obs_dim)``.
        actions: the actions taken ``(T, B, N, *action_shape)``.
        actor_adv: the actors' advantage ``(T, B, C)`` (C = 1 or N).
        targets: what the critics regress ``(T, B, C, K)``.
        entropy_coef: the entropy bonus's weight now.
        value_coef: the value loss's weight.
        mean_bound_coef: the weight of :func:`mean_bound_loss` for Gaussian actors (0: off).
        mean_bound: where that bound starts.
    """
    out = critic(obs)  # (T, B, C, K), with gradient
    dist_out = model.actor_outputs(obs)
    dist = model.dist.torch(dist_out, model.log_std)
    actions = torch.as_tensor(np.asarray(actions), device=obs.device)
    if model.log_std is None:
        actions = actions.long()
    log_prob = dist.log_prob(actions)  # (T, B, N)
    entropy = dist.entropy()  # (T, B, N)
    policy_loss = -(actor_adv * log_prob).mean(dim=(0, 1)).sum()
    entropy_sum = entropy.mean(dim=(0, 1)).sum()
    value_loss = (targets - out).pow(2).mean(dim=(0, 1)).sum()
    loss = policy_loss - entropy_coef * entropy_sum + value_coef * value_loss
    if model.log_std is not None and mean_bound_coef:
        loss = loss + mean_bound_coef * mean_bound_loss(dist_out, mean_bound)
    return Losses(policy_loss, value_loss, entropy_sum, loss)


def entropy_coef(coef: float, schedule: str, progress: float) -> float:
    """The entropy bonus's weight after ``progress`` (in ``[0, 1)``) of the run: ``coef``,
    annealed linearly to 0 when ``schedule = "linear"``."""
    if schedule == "linear":
        coef *= 1.0 - progress
    return coef


def loss_metrics(losses: Losses, adv: np.ndarray, n_agents: int) -> dict[str, float]:
    """The update's metrics as floats (one device sync): ``policy_loss``, ``value_loss``,
    ``entropy`` (mean over agents), ``mean_advantage`` (reward units), ``loss`` and
    ``grad_norm`` (NaN until the gradient is known)."""
    p_loss, v_loss, ent, total = torch.stack(
        [losses.policy, losses.value, losses.entropy, losses.total]
    ).tolist()
    return {
        "policy_loss": p_loss,
        "value_loss": v_loss,
        "entropy": ent / n_agents,
        "mean_advantage": float(adv.mean()),
        "loss": total,
        "grad_norm": math.nan,
    }
