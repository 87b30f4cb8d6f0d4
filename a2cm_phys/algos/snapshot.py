"""The actors' weights as numpy, for rollouts: :class:`ActorSnapshot`.

Computing the actor outputs from a numpy copy of the weights is several times faster than
torch for 1–64 rows. The copy is rebuilt whenever the torch parameters change in place
(optimiser step, ``load_state_dict``, ``no_grad`` copies), which their version counters
tell.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from .layers import StackedLinear


class ActorSnapshot:
    """A numpy copy of N actors (``first → ReLU → deep… → last``) and their ``log_std``.

    Args:
        first: the actors' first layer (applied to the shared input).
        last: their output layer.
        deep: their hidden layers beyond the first.
        log_std: the Gaussian actors' ``log_std``, or ``None``.
        per_agent: whether each actor reads an input of its own (``(..., N, in)``, sensing
            scenarios) rather than one shared input ``(..., in)``.
    """

    def __init__(
        self,
        first: StackedLinear,
        last: StackedLinear,
        deep: Sequence[StackedLinear],
        log_std: nn.Parameter | None,
        per_agent: bool = False,
    ) -> None:
        self.per_agent = per_agent
        self.n_agents, self.hidden, self.n_outputs = first.n, first.out_features, last.out_features
        self._deep = tuple(deep)
        self._log_std = log_std
        params = [first.weight, first.bias, last.weight, last.bias]
        for layer in self._deep:
            params += [layer.weight, layer.bias]
        if log_std is not None:
            params.append(log_std)
        self._params = tuple(params)
        self._arrays: tuple[Any, ...] | None = None
        self._key: tuple[int, ...] | None = None
        self.log_std: np.ndarray | None = None
        """``log_std`` as of the last :meth:`refresh` (``None`` for categorical actors)."""

    def refresh(self) -> None:
        """Rebuild the numpy copy now."""
        with torch.no_grad():
            t_w1, t_b1, t_w2, t_b2 = (p.detach().cpu().numpy() for p in self._params[:4])
            deep = [
                (
                    np.ascontiguousarray(layer.weight.detach().cpu().numpy().transpose(0, 2, 1)),
                    layer.bias.detach().cpu().numpy()[:, None, :].copy(),
                )
                for layer in self._deep
            ]
            log_std = self._log_std
            self.log_std = None if log_std is None else log_std.detach().cpu().numpy().copy()
        n, h, d = t_w1.shape
        o = t_w2.shape[1]
        # the second layer as one block-diagonal (N·H, N·O) matrix: a single small matmul
        w2 = np.zeros((n * h, n * o), dtype=np.float32)
        for i in range(n):
            w2[i * h : (i + 1) * h, i * o : (i + 1) * o] = t_w2[i].T
        first = (
            np.ascontiguousarray(t_w1.transpose(0, 2, 1))  # (N, in, H): one matmul per agent
            if self.per_agent
            else np.ascontiguousarray(t_w1.reshape(n * h, d).T)
        )
        self._arrays = (
            first,
            t_b1.reshape(n * h).copy(),
            w2,
            t_b2.reshape(n * o).copy(),
            deep,
        )
        self._key = self._versions()

    def outputs(self, x: np.ndarray) -> np.ndarray:
        """Actor outputs ``(..., N, n_outputs)`` for float32 network inputs ``(..., in)``, or
        ``(..., N, in)`` (one row per actor) when ``per_agent``."""
        if self._arrays is None or self._key != self._versions():
            self.refresh()
        assert self._arrays is not None
        w1, b1, w2, b2, deep = self._arrays
        if self.per_agent:
            lead = x.shape[:-2]
            rows = np.moveaxis(x.reshape(-1, self.n_agents, x.shape[-1]), 1, 0)  # (N, B, in)
            h = np.moveaxis(np.matmul(rows, w1), 0, 1).reshape(*lead, self.n_agents * self.hidden)
        else:
            h = x @ w1
        h += b1
        np.maximum(h, 0.0, out=h)
        if deep:  # agent by agent: (N, B, H) through each agent's own weights
            lead = h.shape[:-1]
            h = np.moveaxis(h.reshape(-1, self.n_agents, self.hidden), 1, 0)
            for w, b in deep:
                h = np.matmul(h, w)
                h += b
                np.maximum(h, 0.0, out=h)
            h = np.moveaxis(h, 0, 1).reshape(*lead, self.n_agents * self.hidden)
        out = h @ w2
        out += b2
        return out.reshape(*out.shape[:-1], self.n_agents, self.n_outputs)

    def _versions(self) -> tuple[int, ...]:
        # In-place updates (optimiser steps, load_state_dict, no_grad copies) bump the
        # version counter of a parameter, so a changed key means a stale snapshot.
        return tuple(p._version for p in self._params)
