"""Running normalisation of value targets (PopArt-style), one scale per reward component.

The paper's rewards span eight orders of magnitude (a step costs 1,000, a collision
150,000,000). A critic regressing raw returns sees targets around 10⁸, and any fixed
reward scale that suits the collision cost drowns the time cost. :class:`ValueNorm` keeps a
debiased exponential moving average of the targets' mean and second moment per component;
the critic learns ``(G − μ) / σ`` and its value in reward units is ``σ · out + μ``. When the
statistics move, :meth:`ValueNorm.update` rescales the critic's last layer so that its
predictions in reward units are unchanged (van Hasselt et al., 2016, "Learning values across
many orders of magnitude": Preserving Outputs Precisely while Adaptively Rescaling Targets).
"""

from __future__ import annotations

from typing import Any

import torch


class ValueNorm:
    """Debiased EMA of the mean and second moment of value targets, per output.

    Args:
        shape: the trailing dims of targets that get statistics of their own, e.g.
            ``(C, K)``: every critic and reward component apart (A2C's critics stay
            independent), or ``n`` for ``(n,)``.
        beta: weight of the past per update (``0.999``: a memory of about 1,000 updates).
        min_var: floor of the variance (in squared reward units), so that a component
            that has been constant (e.g. no collision for a while) is not divided by zero.
    """

    def __init__(
        self, shape: int | tuple[int, ...], beta: float = 0.999, min_var: float = 1e-4
    ) -> None:
        self.beta, self.min_var = beta, min_var
        self.shape = (shape,) if isinstance(shape, int) else tuple(shape)
        self.mean = torch.zeros(self.shape, dtype=torch.float64)
        self.mean_sq = torch.zeros(self.shape, dtype=torch.float64)
        self.debias = torch.zeros((), dtype=torch.float64)
        self._stats: tuple[torch.Tensor, torch.Tensor] | None = None

    def stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``(μ, σ)`` per component (``(0, 1)`` before the first update)."""
        if self._stats is None:  # a learner update reads them five times: compute once
            self._stats = self._compute_stats()
        return self._stats

    def _compute_stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        if self.debias.item() == 0.0:
            return torch.zeros_like(self.mean), torch.ones_like(self.mean)
        mean = self.mean / self.debias
        var = (self.mean_sq / self.debias - mean**2).clamp(min=self.min_var)
        return mean, var.sqrt()

    def update(self, targets: torch.Tensor, layer: Any = None) -> None:
        """Fold a batch of targets ``(..., *shape)`` into the statistics; rescale ``layer``.

        ``layer`` is the critic's output layer (``weight (C, K, H)``, ``bias (C, K)``): its
        outputs ``o`` are changed to ``(σ·o + μ − μ') / σ'`` so that ``σ'·o' + μ'`` equals the
        value before the update.
        """
        old_mean, old_std = self.stats()
        flat = targets.detach().reshape(-1, *self.shape).double()
        b = self.beta
        self.mean.mul_(b).add_(flat.mean(0), alpha=1 - b)
        self.mean_sq.mul_(b).add_((flat**2).mean(0), alpha=1 - b)
        self.debias.mul_(b).add_(1 - b)
        self._stats = None
        if layer is None:
            return
        new_mean, new_std = self.stats()
        with torch.no_grad():
            w, bias = layer.weight, layer.bias
            ratio = (old_std / new_std).to(w.dtype)
            w.mul_(ratio[..., None])
            bias.mul_(ratio).add_(((old_mean - new_mean) / new_std).to(bias.dtype))

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """``(x − μ) / σ`` over the trailing dims ``shape``."""
        mean, std = self.stats()
        return (x - mean.to(x.dtype)) / std.to(x.dtype)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        """``σ · x + μ`` over the trailing dims ``shape``."""
        mean, std = self.stats()
        return x * std.to(x.dtype) + mean.to(x.dtype)

    def state_dict(self) -> dict[str, torch.Tensor]:
        """The statistics, for checkpoints."""
        return {"mean": self.mean.clone(), "mean_sq": self.mean_sq.clone(), "debias": self.debias}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restore :meth:`state_dict`."""
        self.mean = state["mean"].clone().double()
        self.mean_sq = state["mean_sq"].clone().double()
        self.debias = torch.as_tensor(state["debias"], dtype=torch.float64).clone()
        self._stats = None
