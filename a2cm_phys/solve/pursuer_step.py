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
  probabilities, form a sparse ``S × S`` matrix (torch CSR: one fused gather–multiply–sum),
  one for all evader moves (:mod:`.sparse_step`).

The product kind's tables and the collision masks come from :meth:`GridRules.apply` on
every one- and two-pursuer configuration; the tests compare the three kinds with each
other and with plain enumeration of the rules.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from ..config import Scenario
from ..envs.grid import GridRules
from .sparse_step import (
    CsrPattern,
    apart_mask,
    joint_next_states,
    sparse_expect,
    swap_entries,
    swap_rows,
)
from .tables import check_table, n_states, state_cells, state_of_cells, valid_states
from .transitions import MAX_STATES, MEMORY_BUDGET, TooLargeError, UnsupportedError, free_table

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


def replay_step(
    scenario: Scenario, table: np.ndarray, moves: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The deterministic kind: every (state, evader move) replayed through
    ``GridRules.apply`` under the one-hot ``table``. Returns the next states ``(S, nb)``,
    the probabilities (0 or 1) of a capture and of the episode's end."""
    cells = state_cells(scenario)
    actions = table.argmax(-1)  # (S, N)
    rules = GridRules(scenario)
    terminate = scenario.collisions.mode == "terminate"
    s, nb = n_states(scenario), len(moves)
    nxt = np.empty((s, nb), dtype=np.int64)
    p_capture = np.empty((s, nb))
    p_end = np.empty((s, nb))
    for b, move in enumerate(moves):
        new, captured, collisions, _ = rules.apply(cells.copy(), actions, np.full(s, move))
        nxt[:, b] = state_of_cells(scenario, new)
        p_capture[:, b] = captured
        p_end[:, b] = captured | (terminate & (collisions > 0))
    return nxt, p_capture, p_end


def product_matrices(
    scenario: Scenario, rho: np.ndarray, pmove: np.ndarray, moves: np.ndarray
) -> np.ndarray:
    """The product kind's ``M[i, b, e, p, q]``: P(pursuer ``i`` moves from ``p`` to ``q``
    and misses the evader leaving ``e`` by move ``b``), under the rows ``rho (N, A)`` every
    state shares."""
    c, a, n = scenario.size**2, scenario.actions, scenario.pursuers
    free = free_table(scenario, moves)  # (p, a, e, b)
    matrices = np.zeros((n, len(moves), c, c, c))  # (i, b, e, p, q)
    p = np.arange(c)
    for i in range(n):
        for act in range(a):  # p -> q is one-to-one for one action: no repeated pairs
            w = rho[i, act] * free[:, act]  # (p, e, b)
            matrices[i][:, :, p, pmove[:, act]] += w.transpose(2, 1, 0)
    return matrices


def product_expect(matrices: np.ndarray, emove: np.ndarray, x: np.ndarray, b: int) -> np.ndarray:
    """The product kind's ``G[:, b]`` of ``x (S, m)`` for one evader move: the evader's
    axis first, then one matrix product per pursuer (broadcast over the evader's cell and
    the pursuers before it: no transposes)."""
    c, n, m = emove.shape[0], matrices.shape[0], x.shape[1]
    y = x.reshape(-1, c, m)[:, emove[:, b]].transpose(1, 0, 2)  # (e, q…, m)
    y = np.ascontiguousarray(y)
    for i in range(n):
        y = np.matmul(matrices[i, b][:, None], y.reshape(c, c**i, c, -1))
    return y.reshape(c, -1, m).transpose(1, 0, 2).reshape(len(x), m)


class PursuerStep:
    """The expectation over the pursuers' table of one step, from every joint state.

    ``moves`` are the evader's moves ``b`` (action numbers; 4 is stay). Raises
    :class:`~.model.TooLargeError` when the arena is beyond ``max_states`` joint states
    or the estimated memory beyond ``memory_budget``, :class:`~.model.UnsupportedError`
    outside grid mode and ``ValueError`` for a malformed table.

    ``p_capture[s, b]`` and ``p_end[s, b]`` are the probabilities that the step from
    ``s`` with evader move ``b`` captures the evader, and that it ends the episode
    (capture, or a pursuer collision in ``terminate`` mode). The general kind keeps its
    next states ``index`` and their ``weight`` ``(S, A^N)``, its ``swaps``
    (:func:`~.sparse_step.swap_rows`) and, in ``terminate`` mode, ``apart``
    (:func:`~.sparse_step.apart_mask`).
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
            self.next, self.p_capture, self.p_end = replay_step(scenario, self.table, self.moves)
            self.cont = 1.0 - self.p_end
            return
        if self.kind == "product":
            rho = self.table[np.argmax(self.valid)]  # (N, A): the rows every state shares
            self.matrices = product_matrices(scenario, rho, self.pmove, self.moves)
        else:
            self.index = joint_next_states(scenario, self.pmove)
            self.weight = self.joint_weights(np.arange(self.n_states))
            self.swaps = swap_rows(scenario, self.pmove, self.emove)
            self.pattern = CsrPattern(self.index)
            self.apart: np.ndarray | None = None  # see _fold_collisions
        self._weigh()

    def _weigh(self) -> None:
        """The general kind's matrix of ``weight``, and the capture and end probabilities
        of a step, with collisions folded into the weights in ``terminate`` mode."""
        if self.kind == "general":
            self._sparse()
        ones = self.valid.astype(np.float64)[:, None]  # 1 where the episode goes on
        self.p_capture = self.p_end = 1.0 - self.expect(ones)[..., 0]
        if self.terminate:  # now also end the episode on collisions
            self._fold_collisions()
            self.p_end = 1.0 - self.expect(ones)[..., 0]

    def _sparse(self) -> None:
        """The general kind's sparse matrix and swap entries of the current ``weight``."""
        self.matrix: Any = self.pattern.matrix(self.weight)
        self.swap_entries = swap_entries(self.index, self.weight, self.swaps)

    def _fold_collisions(self) -> None:
        """``terminate`` mode: a step in which two pursuers meet ends the episode."""
        if self.apart is None:
            self.apart = apart_mask(self.scenario)
        self.weight = self.weight * self.apart
        self._sparse()

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

    def expect(self, x: np.ndarray) -> np.ndarray:
        """``G (S, nb, m)`` of ``x (S, m)`` (``x`` zero where a pursuer is on the evader)."""
        if self.kind == "deterministic":
            return self.cont[..., None] * x[self.next]
        if self.kind == "general":
            return sparse_expect(self.matrix, self.swap_entries, self.emove, x)
        out = np.empty((self.n_states, len(self.moves), x.shape[1]))
        for b in range(len(self.moves)):
            out[:, b] = product_expect(self.matrices, self.emove, x, b)
        return out
