"""Value iteration on a :class:`~.model.GridModel`: the optimal value and a greedy policy.

The objective is the expected total raw reward until the episode terminates (capture, or a
collision in ``terminate`` mode), undiscounted, ignoring truncation at ``max_steps``. Every
step costs, so this is a stochastic shortest-path problem: value iteration from zero
converges to the optimum wherever termination can be forced with probability one.

For the random and static evaders that is every state (pursuers can always walk to the
evader; a random evader steps into a neighbouring pursuer with positive probability). With
obstacles, not for the static one: standing on a blocked cell (a state that never occurs,
but is swept all the same) it is out of every pursuer's reach. A fleeing evader, or any
evader law that skips some move somewhere (:attr:`~.model.GridModel.may_escape`), may be
uncatchable (one pursuer on a small arena), so for it the states from which termination can
be forced almost surely are found first, by the classic nested fixed point on the support
of the transition law; the others get value ``-inf``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..base.progress import Progress
from .model import GridModel

_POSITIVE = 1e-9  # probabilities are multiples of >= 1/5; anything above this is positive


@dataclass
class DPResult:
    """Optimal values and a greedy optimal policy over all joint states.

    ``value[s]`` is the optimal expected return from state ``s`` (``-inf`` where termination
    cannot be forced), ``policy[s]`` the joint action index of a greedy optimal policy and
    ``lose`` the mask of states with ``-inf`` value (``None``: no such state possible).
    """

    value: np.ndarray
    policy: np.ndarray
    lose: np.ndarray | None
    sweeps: int
    qualitative_sweeps: int
    residual: float
    seconds: float


def bellman_backup(
    model: GridModel,
    v: np.ndarray,
    lose: np.ndarray | None,
    safe: list[np.ndarray] | None,
    policy: np.ndarray | None = None,
) -> np.ndarray:
    """One Bellman backup ``max_a Q(s, a)`` of the values ``v`` (shape ``model.shape``);
    fills ``policy`` with the argmax if given. ``lose`` and ``safe`` are those of
    :func:`winning_states` (``None``: every state can force termination). The backup is
    linear in ``v`` before the max, so ``γ · v`` gives the discounted one."""
    u = v if lose is None else np.where(lose, 0.0, v)
    out = np.empty(model.shape)
    n = model.n
    order = (*range(0, 2 * n + 1, 2), *model.action_axes)
    for k, (lo, hi, q) in enumerate(model.expect(u)):
        q += model.reward(k)
        if safe is not None:
            q[~safe[k]] = -np.inf
        if policy is None:
            out[lo:hi] = q.max(axis=model.action_axes)
        else:
            flat = q.transpose(order).reshape(-1, model.n_joint)
            best = flat.argmax(axis=1)
            out[lo:hi] = flat[np.arange(len(best)), best].reshape(out[lo:hi].shape)
            policy[lo:hi] = best.reshape(policy[lo:hi].shape)
    if lose is not None:
        out[lose] = -np.inf
    return out


def winning_states(
    model: GridModel, progress: bool = False
) -> tuple[np.ndarray, list[np.ndarray], int]:
    """States from which termination can be forced with probability one (``progress``:
    report the sweeps on stderr, :class:`~a2cm_phys.base.progress.Progress`).

    Returns ``(lose, safe, sweeps)``: ``lose`` the ``(C,) * (N + 1)`` mask of the other
    states, ``safe`` the per-slice masks of joint actions that surely stay among winning
    states (or terminate), and the number of backups used. Outer loop: shrink the
    candidate set ``W``; inner loop: grow the set ``Z`` of states with a ``W``-safe action
    that terminates or enters ``Z`` with positive probability.
    """
    win = np.ones(model.shape, dtype=bool)
    sweeps = 0
    with Progress("reachability", unit="sweeps", enabled=progress) as bar:
        while True:
            safe = [g < _POSITIVE for _, _, g in model.expect((~win).astype(np.float64))]
            sweeps += 1
            bar.update()
            reach = np.zeros(model.shape, dtype=bool)
            while True:
                grown = reach.copy()
                for k, (lo, hi, g) in enumerate(model.expect((~reach).astype(np.float64))):
                    ok = safe[k] & (g < 1.0 - _POSITIVE)
                    grown[lo:hi] |= ok.any(axis=model.action_axes)
                grown &= win
                sweeps += 1
                bar.note(f"{int(win.sum()):,} candidate states")
                bar.update()
                if np.array_equal(grown, reach):
                    break
                reach = grown
            if np.array_equal(reach, win):
                return ~win, safe, sweeps
            win = reach


def solve_dp(
    model: GridModel,
    tol: float | None = None,
    max_sweeps: int = 100_000,
    progress: bool = False,
) -> DPResult:
    """Value iteration to a sup-norm residual below ``tol`` (default ``1e-10 · |step|``).

    ``progress`` reports the sweeps and the residual on stderr
    (:class:`~a2cm_phys.base.progress.Progress`; off for solvers called inside training).
    Raises ``RuntimeError`` if it does not converge within ``max_sweeps``.
    """
    start = time.perf_counter()
    tol = 1e-10 * abs(model.scenario.rewards.step) if tol is None else tol
    lose = safe = None
    qualitative = 0
    if model.may_escape:
        lose, safe, qualitative = winning_states(model, progress)
        if not lose.any():
            lose = safe = None
    v = np.zeros(model.shape)
    finite = slice(None) if lose is None else ~lose
    residual, sweeps = np.inf, 0
    with Progress("value iteration", unit="sweeps", enabled=progress) as bar:
        while residual >= tol:
            if sweeps == max_sweeps:
                raise RuntimeError(f"value iteration did not converge in {max_sweeps} sweeps")
            new = bellman_backup(model, v, lose, safe)
            residual = float(np.max(np.abs(new[finite] - v[finite]), initial=0.0))
            v, sweeps = new, sweeps + 1
            bar.note(f"residual {residual:.1e} (tol {tol:.0e})")
            bar.update()
    dtype = np.min_scalar_type(model.n_joint - 1)
    policy = np.zeros(model.shape, dtype=dtype)
    v = bellman_backup(model, v, lose, safe, policy)
    return DPResult(
        value=v.ravel(),
        policy=policy.ravel(),
        lose=None if lose is None else lose.ravel(),
        sweeps=sweeps + 1,
        qualitative_sweeps=qualitative,
        residual=residual,
        seconds=time.perf_counter() - start,
    )
