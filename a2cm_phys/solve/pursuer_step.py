"""One step of the grid game under a fixed pursuer policy table, for every joint state and
every evader move: the operator the finite-horizon dynamic programming of
:mod:`.best_response` applies up to ``max_steps`` times.

:meth:`PursuerStep.expect` maps an array ``x`` over joint states (with trailing columns),
zero on states where a pursuer stands on the evader, to
``G[s, b] = Σ_a P(a | s) · [the episode goes on] · x[s'(s, a, b)]``, ``a`` the pursuers'
joint action, drawn from the table, ``b`` the evader's move and ``s'`` the next state.
Three implementations, picked by the table:

- *deterministic* (every row one-hot, e.g. the oracle): the next state of every
  (state, evader move) comes from :meth:`~a2cm_phys.envs.grid.GridRules.apply` itself,
  so a step is one gather of ``S · nb`` values.
- *product* (the same rows in every state, e.g. uniformly random pursuers, and no
  collision termination): the sum over joint actions factorises per pursuer. Pursuer
  ``i``'s move, with its probabilities and its chance of missing the evader
  (:func:`~.model.free_table`), is a ``C × C`` matrix per evader cell; a step is ``N``
  batched matrix products per evader move.
- *general* (e.g. learned actors): a pursuer's probabilities depend on every agent's
  cell, so nothing factorises: every state's ``A^N`` next states, weighed by the joint
  probabilities, form a sparse ``S × S`` matrix (torch CSR: one fused gather–multiply–sum).
  Which next state does not depend on the evader's move once ``x`` is shifted along the
  evader's axis, so one matrix product serves all moves and columns at once. A pursuer
  landing on the evader's cell lands on a state where ``x`` is zero; collisions
  (``terminate`` mode) are left out of the matrix, and swaps are subtracted again, sparsely.

The product kind's tables and the collision masks come from :meth:`GridRules.apply` on
every one- and two-pursuer configuration; the tests compare the three kinds with each
other and with plain enumeration of the rules.
"""

from __future__ import annotations

import warnings
from typing import Any, Literal

import numpy as np

from ..config import Scenario
from ..envs.grid import GridRules
from .model import (
    MAX_STATES,
    MEMORY_BUDGET,
    TooLargeError,
    UnsupportedError,
    free_table,
    pair_table,
)
from .tables import check_table, n_states, state_cells, valid_states

Kind = Literal["auto", "deterministic", "product", "general"]

COLUMNS = 3
"""Most columns of ``x`` the dynamic programming carries (steps, capture, episode end)."""


def pick_kind(scenario: Scenario, table: np.ndarray) -> str:
    """The cheapest exact implementation for a checked pursuer table (see the module)."""
    rows = table[valid_states(scenario)]
    if np.all((rows == 0.0) | (rows == 1.0)):
        return "deterministic"
    if scenario.collisions.mode != "terminate" and np.all(rows == rows[:1]):
        return "product"
    return "general"


def memory_estimate(scenario: Scenario, kind: str, moves: int) -> float:
    """Estimated peak bytes of a dynamic programming run with ``kind`` (tables included)."""
    s, n, a = n_states(scenario), scenario.pursuers, scenario.actions
    base = s * n * a * 8 * 2 + s * moves * COLUMNS * 8 * 3 + s * (n + 1) * 8
    if kind == "deterministic":
        return float(base + s * moves * 24)
    if kind == "product":
        return float(base + 3 * s * COLUMNS * 8)
    full = s * a**n  # (state, joint action) pairs: building the sparse matrix, and the
    # next states, weights and sorting order it keeps (to be reweighted)
    swaps = full * 24 * moves * min(1.0, n / scenario.size**2)
    return float(base + full * 56 + swaps)


def check_size(
    scenario: Scenario,
    kind: str = "general",
    moves: int | None = None,
    memory_budget: float = MEMORY_BUDGET,
    max_states: int = MAX_STATES,
) -> None:
    """Raise unless a best response of this ``kind`` on the scenario's grid is within the
    limits (:class:`~.model.UnsupportedError` outside grid mode, else
    :class:`~.model.TooLargeError` naming the limit). Cheap: call it before building tables.
    """
    if scenario.mode != "grid":
        raise UnsupportedError(f"best responses are exact on grids only, got {scenario.mode!r}")
    s, n = n_states(scenario), scenario.pursuers
    size = f"{scenario.size}x{scenario.size} arena with {n} pursuer(s)"
    if s > max_states:
        raise TooLargeError(
            f"{size} is too large for an exact best response: {s:,} joint states "
            f"(limit {max_states:,})"
        )
    need = memory_estimate(scenario, kind, moves or scenario.actions + 1)
    if need > memory_budget:
        raise TooLargeError(
            f"{size} is too large for an exact best response against a {kind} policy "
            f"table: {s:,} joint states need ~{need / 2**30:.1f} GiB (limit "
            f"{memory_budget / 2**30:.1f} GiB)"
        )


class PursuerStep:
    """The expectation over the pursuers' table of one step, from every joint state.

    ``moves`` are the evader's moves ``b`` (action numbers; 4 is stay). Raises
    :class:`~.model.TooLargeError` when the arena is beyond ``max_states`` joint states
    or the estimated memory beyond ``memory_budget``, :class:`~.model.UnsupportedError`
    outside grid mode and ``ValueError`` for a malformed table.

    ``p_capture[s, b]`` and ``p_end[s, b]`` are the probabilities that the step from
    ``s`` with evader move ``b`` captures the evader, and that it ends the episode
    (capture, or a pursuer collision in ``terminate`` mode).
    """

    def __init__(
        self,
        scenario: Scenario,
        pursuer_probs: np.ndarray,
        moves: np.ndarray,
        kind: Kind = "auto",
        memory_budget: float = MEMORY_BUDGET,
        max_states: int = MAX_STATES,
    ) -> None:
        check_size(scenario, "deterministic", len(moves), memory_budget, max_states)
        self.scenario = scenario
        self.n, self.a, self.c = scenario.pursuers, scenario.actions, scenario.size**2
        self.n_states = n_states(scenario)
        self.shape = (self.c,) * (self.n + 1)
        self.moves = np.asarray(moves, dtype=np.int64)
        self.terminate = scenario.collisions.mode == "terminate"
        self.table = check_table(scenario, pursuer_probs, "pursuers")
        self.kind = pick_kind(scenario, self.table) if kind == "auto" else kind
        if self.kind == "product" and self.terminate:
            raise ValueError("the product kind cannot end episodes on collisions")
        check_size(scenario, self.kind, len(self.moves), memory_budget, max_states)
        self.valid = valid_states(scenario)
        move = GridRules(scenario).move.reshape(self.c, 5).astype(np.intp)
        self.pmove = move[:, : self.a]
        self.emove = move[:, self.moves]
        if self.kind == "deterministic":
            self._build_chain()
            return
        if self.kind == "product":
            self._build_matrices()
        else:
            self._structure: tuple[Any, ...] | None = None  # see _csr
            self.apart: np.ndarray | None = None  # see _fold_collisions
            self._build_sparse()
        self._weigh()

    def _weigh(self) -> None:
        """The general kind's matrix of ``weight``, and the capture and end probabilities
        of a step, with collisions folded into the weights in ``terminate`` mode."""
        if self.kind == "general":
            self.matrix = self._csr(self.weight)
            self._swap_entries()
        ones = self.valid.astype(np.float64)[:, None]  # 1 where the episode goes on
        self.p_capture = self.p_end = 1.0 - self.expect(ones)[..., 0]
        if self.terminate:  # now also end the episode on collisions
            self._fold_collisions()
            self.p_end = 1.0 - self.expect(ones)[..., 0]

    # ------------------------------------------------------------------ deterministic

    def _build_chain(self) -> None:
        """Replay every (state, evader move) through ``GridRules.apply``."""
        cells = state_cells(self.scenario)
        actions = self.table.argmax(-1)  # (S, N)
        rules = GridRules(self.scenario)
        s, nb = self.n_states, len(self.moves)
        self.next = np.empty((s, nb), dtype=np.int64)
        self.p_capture = np.empty((s, nb))
        self.p_end = np.empty((s, nb))
        for b, move in enumerate(self.moves):
            new, captured, collisions, _ = rules.apply(cells.copy(), actions, np.full(s, move))
            self.next[:, b] = np.ravel_multi_index(tuple(new), self.shape)
            self.p_capture[:, b] = captured
            self.p_end[:, b] = captured | (self.terminate & (collisions > 0))
        self.cont = 1.0 - self.p_end

    # ------------------------------------------------------------------ product

    def _build_matrices(self) -> None:
        """``M[i, b, e, p, q]``: P(pursuer ``i`` moves from ``p`` to ``q`` and misses the
        evader leaving ``e`` by move ``b``), the same in every state."""
        c, a, n = self.c, self.a, self.n
        rho = self.table[np.argmax(self.valid)]  # (N, A)
        free = free_table(self.scenario, self.moves)  # (p, a, e, b)
        self.matrices = np.zeros((n, len(self.moves), c, c, c))  # (i, b, e, p, q)
        p = np.arange(c)
        for i in range(n):
            for act in range(a):  # p -> q is one-to-one for one action: no repeated pairs
                w = rho[i, act] * free[:, act]  # (p, e, b)
                self.matrices[i][:, :, p, self.pmove[:, act]] += w.transpose(2, 1, 0)

    def _product(self, x: np.ndarray, b: int) -> np.ndarray:
        """One evader move: the evader's axis first, then one matrix product per pursuer
        (broadcast over the evader's cell and the pursuers before it: no transposes)."""
        c, n, m = self.c, self.n, x.shape[1]
        y = x.reshape(-1, c, m)[:, self.emove[:, b]].transpose(1, 0, 2)  # (e, q…, m)
        y = np.ascontiguousarray(y)
        for i in range(n):
            y = np.matmul(self.matrices[i, b][:, None], y.reshape(c, c**i, c, -1))
        return y.reshape(c, -1, m).transpose(1, 0, 2).reshape(self.n_states, m)

    # ------------------------------------------------------------------ general

    def _build_sparse(self) -> None:
        """The step as one sparse ``S × S`` matrix (shared by all evader moves) and, per
        move, the swap entries to take out again."""
        c, a, n, s = self.c, self.a, self.n, self.n_states
        cells = state_cells(self.scenario)
        joint = (s,) + (a,) * n
        index = np.broadcast_to(cells[-1].reshape((s,) + (1,) * n), joint).copy()
        weight = np.ones(joint)
        for i in range(n):
            shape = (s,) + (1,) * i + (a,) + (1,) * (n - 1 - i)
            index += (self.pmove[cells[i]] * c ** (n - i)).reshape(shape)
            weight *= self.table[:, i, :].reshape(shape)
        self.index, self.weight = index.reshape(s, -1), weight.reshape(s, -1)
        # Swaps: pursuer i moves onto the evader's cell e as the evader moves onto p_i.
        # A capture the matrix cannot see (the next state is a valid one): those
        # (state, joint action) entries are subtracted again, sparsely.
        self.swaps: list[tuple[np.ndarray, np.ndarray]] = []
        for b in range(len(self.moves)):
            target = self.emove[cells[-1], b]
            rows = np.flatnonzero(np.any(cells[:-1] == target, axis=0) & (target != cells[-1]))
            hit = np.zeros((len(rows),) + (a,) * n, dtype=bool)
            for i in range(n):
                swap = (cells[i, rows] == target[rows])[:, None] & (
                    self.pmove[cells[i, rows]] == cells[-1, rows, None]
                )  # (rows, A)
                hit |= swap.reshape((len(rows),) + (1,) * i + (a,) + (1,) * (n - 1 - i))
            r, j = np.nonzero(hit.reshape(len(rows), a**n))
            self.swaps.append((rows[r], rows[r] * a**n + j))

    def _swap_entries(self) -> None:
        """Per evader move: the swap entries' rows, columns and weights."""
        index, weight = self.index.ravel(), self.weight.ravel()
        self.swap_entries = [(rows, index[flat], weight[flat]) for rows, flat in self.swaps]

    def _csr(self, weight: np.ndarray) -> Any:
        """``weight (S, J)`` at columns ``index (S, J)`` as a torch CSR matrix, duplicate
        columns (moves that bump into a wall) summed. The matrix's structure depends on the
        arena alone: it is sorted out once, and a later call only sums new weights."""
        import torch

        if self._structure is None:
            order = np.argsort(self.index, axis=1, kind="stable")
            cols = np.take_along_axis(self.index, order, axis=1)
            first = np.ones(cols.shape, dtype=bool)
            first[:, 1:] = cols[:, 1:] != cols[:, :-1]
            starts = np.flatnonzero(first)
            crow = np.concatenate(([0], np.cumsum(first.sum(axis=1))))
            order += np.arange(self.n_states)[:, None] * order.shape[1]
            self._structure = (
                order.ravel(),
                starts,
                torch.from_numpy(crow.astype(np.int32)),
                torch.from_numpy(cols.ravel()[starts].astype(np.int32)),
            )
        flat_order, starts, crow, cols = self._structure
        values = np.add.reduceat(weight.ravel()[flat_order], starts)
        with warnings.catch_warnings():  # "sparse CSR support is in beta"
            warnings.simplefilter("ignore", UserWarning)
            return torch.sparse_csr_tensor(
                crow,
                cols,
                torch.from_numpy(values),
                size=(self.n_states, self.n_states),
                check_invariants=False,
            )

    def _fold_collisions(self) -> None:
        """``terminate`` mode: a step in which two pursuers meet ends the episode."""
        a, n, s = self.a, self.n, self.n_states
        if self.apart is None:  # (S, J): no two pursuers meet
            cells = state_cells(self.scenario)
            pair = pair_table(self.scenario) == 0
            ok = np.ones((s,) + (a,) * n, dtype=bool)
            for i in range(n):
                for k in range(i + 1, n):
                    ai = np.arange(a).reshape((1,) * i + (a,) + (1,) * (n - 1 - i))
                    ak = np.arange(a).reshape((1,) * k + (a,) + (1,) * (n - 1 - k))
                    pi, pk = (cells[h].reshape((s,) + (1,) * n) for h in (i, k))
                    ok &= pair[pi, ai, pk, ak]
            self.apart = ok.reshape(s, -1)
        self.weight = self.weight * self.apart
        self.matrix = self._csr(self.weight)
        self._swap_entries()

    def reweight(self, pursuer_probs: np.ndarray) -> None:
        """The same step under another pursuer table of the same arena (general kind): the
        sparse structure is kept, only the weights are recomputed (a fraction of building).
        """
        if self.kind != "general":
            raise ValueError(f"only the general kind can be reweighted, this one is {self.kind}")
        self.table = check_table(self.scenario, pursuer_probs, "pursuers")
        self.weight = self.joint_weights(np.arange(self.n_states))
        self._weigh()

    def joint_weights(self, rows: np.ndarray) -> np.ndarray:
        """``(R, A^N)`` probabilities of the pursuers' joint actions in states ``rows``, in
        the joint index order ``(a_0 · A + a_1) · A + …``."""
        w = self.table[rows, 0]
        for i in range(1, self.n):
            w = (w[:, :, None] * self.table[rows, i, None, :]).reshape(len(rows), -1)
        return w

    def _general(self, x: np.ndarray) -> np.ndarray:
        """All evader moves at once: ``x`` shifted along the evader's axis by each move,
        side by side, times the matrix; minus the swaps."""
        import torch

        c, m, nb = self.c, x.shape[1], len(self.moves)
        shifted = np.take(x.reshape(-1, c, m), self.emove, axis=1)  # (…, e, b, m)
        shifted = shifted.reshape(self.n_states, nb * m)
        out = (self.matrix @ torch.from_numpy(shifted)).numpy().reshape(-1, nb, m)
        for b, (rows, cols, weight) in enumerate(self.swap_entries):
            for col in range(m):
                values = weight * shifted[cols, b * m + col]
                out[:, b, col] -= np.bincount(rows, weights=values, minlength=self.n_states)
        return out

    # ------------------------------------------------------------------ the operator

    def expect(self, x: np.ndarray) -> np.ndarray:
        """``G (S, nb, m)`` of ``x (S, m)`` (``x`` zero where a pursuer is on the evader)."""
        if self.kind == "deterministic":
            return self.cont[..., None] * x[self.next]
        if self.kind == "general":
            return self._general(x)
        out = np.empty((self.n_states, len(self.moves), x.shape[1]))
        for b in range(len(self.moves)):
            out[:, b] = self._product(x, b)
        return out
