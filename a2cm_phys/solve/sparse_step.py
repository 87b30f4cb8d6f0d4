"""The general kind of :class:`~.pursuer_step.PursuerStep`: one step of the grid game
under a pursuer table whose rows depend on every agent's cell, as a sparse ``S × S`` matrix.

Every state's ``A^N`` next states (:func:`joint_next_states`), weighed by the joint
probabilities, form the matrix (torch CSR, :class:`CsrPattern`). Which next state does not
depend on the evader's move once ``x`` is shifted along the evader's axis, so one matrix
product serves all moves and columns at once (:func:`sparse_expect`). A pursuer landing on
the evader's cell lands on a state where ``x`` is zero; a pursuer and the evader swapping
cells is a capture the matrix cannot see, so those entries (:func:`swap_rows`) are
subtracted again, sparsely. Collisions (``terminate`` mode) are taken out of the weights
(:func:`apart_mask`).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ..config import Scenario
from .tables import n_states, state_cells
from .transitions import pair_table


def joint_next_states(scenario: Scenario, pmove: np.ndarray) -> np.ndarray:
    """``(S, A^N)``: the state index after every joint action from every state, the evader
    staying (its move is a shift of the index, applied later)."""
    c, a, n, s = scenario.size**2, scenario.actions, scenario.pursuers, n_states(scenario)
    cells = state_cells(scenario)
    joint = (s,) + (a,) * n
    index = np.broadcast_to(cells[-1].reshape((s,) + (1,) * n), joint).copy()
    for i in range(n):
        shape = (s,) + (1,) * i + (a,) + (1,) * (n - 1 - i)
        index += (pmove[cells[i]] * c ** (n - i)).reshape(shape)
    return index.reshape(s, -1)


def swap_rows(
    scenario: Scenario, pmove: np.ndarray, emove: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per evader move: the states and flat ``(state, joint action)`` indices in which
    some pursuer moves onto the evader's cell ``e`` as the evader moves onto its cell."""
    a, n = scenario.actions, scenario.pursuers
    cells = state_cells(scenario)
    swaps = []
    for b in range(emove.shape[1]):
        target = emove[cells[-1], b]
        rows = np.flatnonzero(np.any(cells[:-1] == target, axis=0) & (target != cells[-1]))
        hit = np.zeros((len(rows),) + (a,) * n, dtype=bool)
        for i in range(n):
            swap = (cells[i, rows] == target[rows])[:, None] & (
                pmove[cells[i, rows]] == cells[-1, rows, None]
            )  # (rows, A)
            hit |= swap.reshape((len(rows),) + (1,) * i + (a,) + (1,) * (n - 1 - i))
        r, j = np.nonzero(hit.reshape(len(rows), a**n))
        swaps.append((rows[r], rows[r] * a**n + j))
    return swaps


def swap_entries(
    index: np.ndarray, weight: np.ndarray, swaps: list[tuple[np.ndarray, np.ndarray]]
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per evader move: the swap entries' rows, columns and weights."""
    index, weight = index.ravel(), weight.ravel()
    return [(rows, index[flat], weight[flat]) for rows, flat in swaps]


def apart_mask(scenario: Scenario) -> np.ndarray:
    """``(S, A^N)``: no two pursuers meet in the step (``terminate`` mode: it goes on)."""
    a, n, s = scenario.actions, scenario.pursuers, n_states(scenario)
    cells = state_cells(scenario)
    pair = pair_table(scenario) == 0
    ok = np.ones((s,) + (a,) * n, dtype=bool)
    for i in range(n):
        for k in range(i + 1, n):
            ai = np.arange(a).reshape((1,) * i + (a,) + (1,) * (n - 1 - i))
            ak = np.arange(a).reshape((1,) * k + (a,) + (1,) * (n - 1 - k))
            pi, pk = (cells[h].reshape((s,) + (1,) * n) for h in (i, k))
            ok &= pair[pi, ai, pk, ak]
    return ok.reshape(s, -1)


class CsrPattern:
    """The structure of the step's sparse matrix, sorted out once from ``index (S, J)``
    (it depends on the arena alone): :meth:`matrix` then only sums new weights."""

    def __init__(self, index: np.ndarray) -> None:
        import torch

        self.n_states = len(index)
        order = np.argsort(index, axis=1, kind="stable")
        cols = np.take_along_axis(index, order, axis=1)
        first = np.ones(cols.shape, dtype=bool)
        first[:, 1:] = cols[:, 1:] != cols[:, :-1]
        self.starts = np.flatnonzero(first)
        crow = np.concatenate(([0], np.cumsum(first.sum(axis=1))))
        order += np.arange(self.n_states)[:, None] * order.shape[1]
        self.order = order.ravel()
        self.crow = torch.from_numpy(crow.astype(np.int32))
        self.cols = torch.from_numpy(cols.ravel()[self.starts].astype(np.int32))

    def matrix(self, weight: np.ndarray) -> Any:
        """``weight (S, J)`` at the columns ``index`` as a torch CSR matrix, duplicate
        columns (moves that bump into a wall) summed."""
        import torch

        values = np.add.reduceat(weight.ravel()[self.order], self.starts)
        with warnings.catch_warnings():  # "sparse CSR support is in beta"
            warnings.simplefilter("ignore", UserWarning)
            return torch.sparse_csr_tensor(
                self.crow,
                self.cols,
                torch.from_numpy(values),
                size=(self.n_states, self.n_states),
                check_invariants=False,
            )


def sparse_expect(
    matrix: Any,
    entries: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
    emove: np.ndarray,
    x: np.ndarray,
) -> np.ndarray:
    """``G (S, nb, m)`` of ``x (S, m)``, all evader moves at once: ``x`` shifted along the
    evader's axis by each move, side by side, times the ``matrix``; minus the swap
    ``entries`` (:func:`swap_entries`)."""
    import torch

    s, (c, nb), m = len(x), emove.shape, x.shape[1]
    shifted = np.take(x.reshape(-1, c, m), emove, axis=1)  # (…, e, b, m)
    shifted = shifted.reshape(s, nb * m)
    out = (matrix @ torch.from_numpy(shifted)).numpy().reshape(-1, nb, m)
    for b, (rows, cols, weight) in enumerate(entries):
        for col in range(m):
            values = weight * shifted[cols, b * m + col]
            out[:, b, col] -= np.bincount(rows, weights=values, minlength=s)
    return out
