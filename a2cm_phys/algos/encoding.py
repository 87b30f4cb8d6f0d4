"""How a network sees an observation: the raw vector, :class:`OneHotCells` on grids, or
:class:`RelativePositions` (each actor's own view)."""

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


class RelativePositions:
    """Each actor's own view of the global observation: every other body's position as its
    offset from the actor's body times ``scale``, the actor's own position and everything
    else (velocities, headings) as they are, ``(..., d) → (..., n, d)``. The offsets are the
    numbers a pursuit rule reads, so a network need not learn to subtract coordinates, and
    they are the same wherever in the arena a configuration occurs (random starts). With
    ``scale`` the arena's length over the observation's unit (``encoding = "metric"``) they
    are in metres (cells on a grid): a body 1 m away reads 1 on every arena size, where as
    a fraction of a 10 × 10 arena it reads 0.1, and the direction to a near evader turns
    within inputs that small.

    The map is linear, ``x_i = M_i x``: :attr:`matrices` ``(n, d, d)`` hold the ``M_i``
    (an export folds them into each actor's first layer, ``W M_i``).

    Args:
        bodies: bodies in the observation (the pursuers and the evader), whose positions
            are its first ``2 · bodies`` entries (x, y each).
        obs_dim: length of the observation.
        first: the body of the first actor; actor ``j`` is body ``first + j``.
        n: how many actors.
        scale: what the offsets are multiplied by (1: fractions of the arena).
    """

    def __init__(self, bodies: int, obs_dim: int, first: int, n: int, scale: float = 1.0) -> None:
        if first < 0 or first + n > bodies or 2 * bodies > obs_dim:
            raise ValueError(
                f"relative positions of actors {first}…{first + n - 1} need them among"
                f" {bodies} bodies whose positions fit in {obs_dim} entries"
            )
        m = np.tile(np.eye(obs_dim, dtype=np.float32), (n, 1, 1))
        for j in range(n):
            own = first + j
            for body in range(bodies):
                if body != own:
                    for c in range(2):  # scale · (x_body - x_own), scale · (y_body - y_own)
                        row = 2 * body + c
                        m[j, row, row], m[j, row, 2 * own + c] = scale, -scale
        self.matrices, self.scale = m, scale
        self._torch = torch.from_numpy(m)

    def torch(self, obs: torch.Tensor) -> torch.Tensor:
        """Each actor's input ``(..., n, d)`` of observations ``(..., d)``."""
        return torch.einsum("nij,...j->...ni", self._torch.to(obs), obs)

    def numpy(self, obs: np.ndarray) -> np.ndarray:
        """:meth:`torch` in numpy (float32)."""
        return np.einsum("nij,...j->...ni", self.matrices, np.asarray(obs, dtype=np.float32))

    def view(self, obs):
        """:meth:`torch` of a tensor, :meth:`numpy` of anything else."""
        return self.torch(obs) if isinstance(obs, torch.Tensor) else self.numpy(obs)
