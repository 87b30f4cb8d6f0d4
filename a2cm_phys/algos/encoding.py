"""How a network sees an observation: the raw vector, or :class:`OneHotCells` on grids."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


class OneHotCells:
    """A grid observation (SPEC §5: every coordinate divided by ``size − 1``) as one one-hot
    vector of ``size`` per coordinate: ``(..., d) → (..., d · size)``. A network then tells
    "next to the evader" from "two cells away" with one weight per cell, where the raw
    coordinates make it carve the arena with ReLUs."""

    def __init__(self, size: int) -> None:
        if size < 2:
            raise ValueError(f"one-hot cells need an arena of size >= 2, got {size}")
        self.size = size
        self._eye = np.eye(size, dtype=np.float32)

    def features(self, obs_dim: int) -> int:
        """Length of the encoded input."""
        return obs_dim * self.size

    def torch(self, obs: torch.Tensor) -> torch.Tensor:
        """Encode a float tensor of observations."""
        cells = torch.round(obs * (self.size - 1)).long().clamp_(0, self.size - 1)
        return F.one_hot(cells, self.size).to(obs.dtype).flatten(-2)

    def numpy(self, obs: np.ndarray) -> np.ndarray:
        """Encode observations in numpy (float32), as :meth:`torch` does."""
        cells = np.rint(np.asarray(obs, dtype=np.float32) * (self.size - 1)).astype(np.intp)
        np.clip(cells, 0, self.size - 1, out=cells)
        return self._eye[cells].reshape(*cells.shape[:-1], -1)
