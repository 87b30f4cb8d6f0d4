"""Discounted returns and advantages over a time-major batch (SPEC §6, paper eqs. 12–13).

All tensors are time-major: ``(T, B)`` for one critic's worth of data or ``(T, B, C)`` for C
critics. Episode ends are kept apart: a **terminated** step (capture, terminating collision)
has no future, a **truncated** step (time limit) is bootstrapped with the critic's value of
its own final observation, never treated as terminal.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    from numpy.typing import DTypeLike


def discounted_returns(
    rewards: torch.Tensor,
    terminated: torch.Tensor,
    truncated: torch.Tensor,
    bootstrap_value: torch.Tensor,
    truncation_value: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """Returns by eq. 13, computed backwards over the batch.

    ``G_t = r_t + γ·(1 − term_t)·(V(final_obs_t) if trunc_t else G_{t+1})``, seeded with
    ``G_T = bootstrap_value`` (the critic's value of the state after the batch). Where a step
    is neither terminated nor truncated this is ``G_t = r_t + γ·G_{t+1}``; at an episode end
    nothing flows back from the next episode.

    Args:
        rewards: ``(T, B)`` or ``(T, B, C)`` rewards of each step.
        terminated: ``(T, B)`` bool, the episode ended in a terminal state at step t.
        truncated: ``(T, B)`` bool, the episode was cut (time limit) at step t.
        bootstrap_value: ``(B,)`` or ``(B, C)`` value of the observation after step ``T−1``.
        truncation_value: ``(T, B)`` or ``(T, B, C)`` value of the final observation of step
            t; only read where ``truncated`` (other entries may hold anything, even NaN).
        gamma: discount factor in ``[0, 1]``.

    Returns:
        Returns of shape ``(T, B, C)`` if any input has a critic dim, else ``(T, B)``;
        ``(T, B)`` rewards are broadcast to every critic; dtype promoted from ``rewards``
        and ``bootstrap_value``. No gradient flows (these are targets).
    """
    # Targets only (no autograd): computed in numpy by discounted_returns_np.
    device = rewards.device
    returns = discounted_returns_np(
        *(
            x.detach().cpu().numpy()
            for x in (rewards, terminated, truncated, bootstrap_value, truncation_value)
        ),
        gamma,
    )
    return torch.from_numpy(returns).to(device)


def discounted_returns_np(
    rewards: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    bootstrap_value: np.ndarray,
    truncation_value: np.ndarray,
    gamma: float,
    *,
    dtype: DTypeLike = None,
) -> np.ndarray:
    """:func:`discounted_returns` on numpy arrays (same shapes, same rules, same result).

    The recurrence runs backwards over time, vectorised over environments and critics, in
    float64; the C-contiguous result is then rounded to ``dtype`` (default: promoted from
    ``rewards`` and ``bootstrap_value``, as :func:`discounted_returns`).
    """
    r, tval, boot = rewards, truncation_value, bootstrap_value
    term, trunc = terminated.astype(bool, copy=False), truncated.astype(bool, copy=False)
    if r.ndim == 3 or tval.ndim == 3 or boot.ndim == 2:
        term, trunc = term[..., None], trunc[..., None]
        r = r if r.ndim == 3 else r[..., None]
        tval = tval if tval.ndim == 3 else tval[..., None]
        boot = boot if boot.ndim == 2 else boot[..., None]
    step_dtype = np.promote_types(r.dtype, boot.dtype)
    dtype = step_dtype if dtype is None else np.dtype(dtype)
    zero, discount = step_dtype.type(0.0), step_dtype.type(gamma)
    live = np.where(term, zero, discount)  # γ·(1 − term_t)
    if trunc.any():
        step = r + live * np.where(trunc, tval, zero)  # r_t (+ γ·V(final_obs_t) if truncated)
        carry = np.where(trunc, zero, live)  # weight of G_{t+1}: γ, or 0 at an episode end
    else:
        step, carry = r, live
    if len(step) == 0:
        return np.zeros(np.broadcast_shapes(step.shape, carry.shape, (0, *boot.shape)), dtype)
    step, carry = step.astype(np.float64), carry.astype(np.float64)
    end = carry == 0.0
    any_end = end.reshape(len(end), -1).any(axis=1).tolist()
    g = boot.astype(np.float64)
    out = []
    for t in range(len(step) - 1, -1, -1):
        if any_end[t]:  # at an episode end G_{t+1} must not leak in (even if not finite)
            g = np.where(end[t], 0.0, g)
        g = carry[t] * g + step[t]
        out.append(g)
    return np.array(out[::-1], dtype=dtype)


def advantages(returns: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """Advantages by eq. 12: ``A_t = G_t − V(s_t)``, broadcasting the critic dim."""
    return returns - values


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    next_values: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    gamma: float,
    lam: float,
) -> np.ndarray:
    """Generalised advantage estimates GAE(γ, λ) over a time-major batch, in float64.

    ``δ_t = r_t + γ·(1 − term_t)·V'_t − V_t`` where ``V'_t`` is the value of the state after
    step t: of the next observation, or of the episode's final observation where it was
    truncated (bootstrapped, never treated as terminal), or of the observation after the
    batch at ``t = T − 1``. Then ``A_t = δ_t + γλ·(1 − done_t)·A_{t+1}`` with ``done = term |
    trunc``: nothing flows back across an episode end. With ``λ = 1`` the returns ``A + V``
    are exactly eq. 13's (:func:`discounted_returns`); ``λ < 1`` trades bias for variance.

    Args:
        rewards: ``(T, B, ...)`` rewards (any trailing critic/component dims).
        values: ``(T, B, ...)`` values of the observations the steps started from.
        next_values: ``(T, B, ...)`` ``V'_t`` as above (read only where not terminated).
        terminated, truncated: ``(T, B)`` bool.
        gamma, lam: discount and GAE parameter, both in ``[0, 1]``.

    Returns:
        Advantages of the shape of ``rewards`` broadcast with ``values``.
    """
    extra = (1,) * (np.ndim(values) - 2)
    term = np.asarray(terminated, dtype=bool).reshape(*np.shape(terminated), *extra)
    done = term | np.asarray(truncated, dtype=bool).reshape(term.shape)
    r = np.asarray(rewards, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    nv = np.where(term, 0.0, np.asarray(next_values, dtype=np.float64))
    delta = r + gamma * nv - v
    carry = np.where(done, 0.0, gamma * lam)
    carry = np.broadcast_to(carry, delta.shape)
    out = np.empty_like(delta)
    a = np.zeros(delta.shape[1:])
    for t in range(len(delta) - 1, -1, -1):
        a = delta[t] + carry[t] * a
        out[t] = a
    return out
