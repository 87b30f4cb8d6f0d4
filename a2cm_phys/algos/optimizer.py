"""The optimiser's side of an update: which optimiser, the gradient and its clipping, and
the learning rate."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from .rmsprop import KerasRMSprop

if TYPE_CHECKING:
    from ..config import Train


def make_optimizer(model: torch.nn.Module, cfg: Train) -> torch.optim.Optimizer | KerasRMSprop:
    """RMSprop as the paper's Keras has it (non-centred, no momentum, eps outside the
    square root: torch's RMSprop with ``alpha = rho``, :mod:`.rmsprop`), or Adam."""
    if cfg.optimizer == "adam":
        return torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
    return KerasRMSprop(model.parameters(), lr=cfg.lr, alpha=cfg.rmsprop_alpha, eps=cfg.rmsprop_eps)


def backpropagate(model: torch.nn.Module, loss: torch.Tensor, max_grad_norm: float | None) -> float:
    """Put the gradient of ``loss`` in ``model``'s (cleared) gradients, clipped to a total
    norm of ``max_grad_norm`` (0 or ``None``: no clipping); returns the norm before."""
    model.zero_grad(set_to_none=True)  # the optimiser's own adds a profiler span
    loss.backward()
    params = [p for p in model.parameters() if p.grad is not None]
    if max_grad_norm:  # 0, or None (not resolved for a scenario): no clipping
        norm = torch.nn.utils.clip_grad_norm_(params, max_grad_norm)
    else:
        norm = torch.nn.utils.get_total_norm([p.grad for p in params])
    return norm.item()


def set_learning_rate(optimizer: torch.optim.Optimizer | KerasRMSprop, lr: float) -> None:
    """Set every parameter group's learning rate."""
    for group in optimizer.param_groups:
        group["lr"] = lr
