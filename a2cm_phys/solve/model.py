"""The grid game as a factorised Markov decision process over the joint state.

A joint state is every pursuer's cell and the evader's cell; its index is
``((p_0 · C + p_1) · C + …) · C + e`` with ``C = size²`` (``p_0`` most significant), so an
array over states reshapes to ``(C,) * (N + 1)``. A joint action index is likewise
``(a_0 · A + a_1) · A + …``.

One step factorises per agent: pursuer ``i`` moves by its own table, and whether it catches
the evader depends only on its own cell and action and the evader's cell and move. So the
expected next value ``Σ_b P(b | s) · [no capture] · U(s')`` over all states and joint actions
is a chain of ``np.take`` calls, one per agent, each multiplied by that agent's
no-capture factor; the full ``(states × joint actions)`` tensor is only built one slice of
``p_0`` at a time (:class:`~.backup.SlicedBackup`). The tables are
those of :class:`~.transitions.GridTables`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from ..config import Scenario
from .backup import SlicedBackup
from .transitions import MAX_STATES, MEMORY_BUDGET, GridTables


class GridModel(GridTables):
    """The grid game as an MDP: the tables of one grid scenario
    (:class:`~.transitions.GridTables`, whose errors and limits it raises) and the Bellman
    backup over them.

    The evader plays the scenario's scripted policy, or ``evader_probs``, an evader policy
    table (:mod:`.tables`) that replaces it: the oracle then solves the pursuers' best
    response to that evader.
    """

    def __init__(
        self,
        scenario: Scenario,
        memory_budget: float = MEMORY_BUDGET,
        max_states: int = MAX_STATES,
        evader_probs: np.ndarray | None = None,
    ) -> None:
        super().__init__(scenario, memory_budget, max_states, evader_probs)
        self.backup = SlicedBackup(self)

    def reward(self, k: int) -> np.ndarray | float:
        """Expected immediate reward of slice number ``k`` (an array, or the step reward)."""
        return self.backup.reward(k)

    def expect(
        self, u: np.ndarray, collisions: bool = True
    ) -> Iterator[tuple[int, int, np.ndarray]]:
        """Yield ``(lo, hi, G)`` for slices ``p_0 ∈ [lo, hi)`` of the full tensor.

        ``G[p_0 - lo, a_0, p_1, a_1, …, e] = Σ_b P(b | s) · P(not terminated | s, a, b) ·
        u[s']``, ``u`` an array of shape :attr:`shape`. With ``collisions=False`` only a
        capture terminates (used for the capture probability itself). ``G`` is a buffer
        reused for the next slice: copy what must outlive the iteration.
        """
        return self.backup.expect(u, collisions)
