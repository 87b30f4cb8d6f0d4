"""N agents' dense layers as one batched op: :class:`StackedLinear` and the MLP made of them.

The N actors (and A2C's N critics) live in layers whose parameters carry a leading agent
dimension, so all of them are evaluated in one op, not a Python loop.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import torch
import torch.nn.functional as F
from torch import nn


class StackedLinear(nn.Module):
    """``n`` independent dense layers ``in_features → out_features`` with stacked parameters.

    ``weight`` has shape ``(n, out_features, in_features)`` and ``bias`` ``(n, out_features)``;
    slice ``i`` is initialised exactly as ``nn.Linear(in_features, out_features)`` would be
    (kaiming-uniform weight with ``a=√5``, bias uniform in ``±1/√in_features``).
    """

    def __init__(
        self,
        n: int,
        in_features: int,
        out_features: int,
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        self.n, self.in_features, self.out_features = n, in_features, out_features
        self.weight = nn.Parameter(torch.empty(n, out_features, in_features))
        self.bias = nn.Parameter(torch.empty(n, out_features))
        self.reset_parameters(generator)

    def reset_parameters(self, generator: torch.Generator | None = None) -> None:
        """Initialise every slice like ``nn.Linear.reset_parameters``."""
        bound = 1.0 / math.sqrt(self.in_features)
        with torch.no_grad():
            for i in range(self.n):
                nn.init.kaiming_uniform_(self.weight[i], a=math.sqrt(5), generator=generator)
                nn.init.uniform_(self.bias[i], -bound, bound, generator=generator)

    def forward_shared(self, x: torch.Tensor) -> torch.Tensor:
        """Apply all ``n`` layers to the same input: ``(..., in) → (..., n, out)`` (one matmul)."""
        flat = F.linear(
            x,
            self.weight.reshape(self.n * self.out_features, self.in_features),
            self.bias.reshape(self.n * self.out_features),
        )
        return flat.unflatten(-1, (self.n, self.out_features))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Apply layer ``i`` to row ``i`` of the agent dim: ``(..., n, in) → (..., n, out)``."""
        return torch.einsum("...ni,noi->...no", x, self.weight) + self.bias

    def extra_repr(self) -> str:
        """Shape summary shown by ``print(module)``."""
        return f"n={self.n}, in_features={self.in_features}, out_features={self.out_features}"


def stacked_mlp(
    first: StackedLinear,
    deep: Iterable[StackedLinear],
    last: StackedLinear,
    x: torch.Tensor,
) -> torch.Tensor:
    """``n`` MLPs on one shared input ``(..., in) → (..., n, out)``: ``first`` on ``x``, then
    each of ``deep`` agent by agent, with a ReLU after every hidden layer, then ``last``."""
    h = F.relu(first.forward_shared(x))
    for layer in deep:
        h = F.relu(layer(h))
    return last(h)
