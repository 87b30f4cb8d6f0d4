"""The exact gradient of a pursuer team's worst case on the grid (exploitability descent).

Against a pursuer table ``π`` (:mod:`.tables`) the evader's best response has the values

    V(s) = max_b Q(s, b),   Q(s, b) = Σ_a π(a | s) · (1 + γ · [the episode goes on] · V(s'))

(``V = 0`` where a pursuer stands on the evader; ``s'`` the next state under the pursuers'
joint action ``a`` and the evader's move ``b``). With ``γ = 1`` and a horizon this is the
worst case of :mod:`.best_response`; ``γ < 1``, the discount of the pursuers' own returns,
keeps it finite for a team that some evader escapes for ever. By Danskin's theorem its
gradient at the start ``s₀``, the maximising moves held fixed, is

    ∇V(s₀) = Σ_s d(s) Σ_i Σ_{a_i} ∇π_i(a_i | s) · Q_i(s, a_i),

``d`` the discounted visits of the states from the start when the pursuers play ``π`` and
the evader its best response, ``Q_i(s, a_i)`` the expected value of the step when pursuer
``i`` takes ``a_i``, the others play ``π`` and the evader its best move. Descending it is
*exploitability descent* (Lockhart et al., IJCAI 2019): each step makes the team better
against the opponent that exploits it most. :class:`WorstCaseGradient` computes the pieces:

- ``V`` by value iteration over every joint state, warm-started from the last call
  (``sweeps`` a call: between two calls the policy moves little, so the values follow it;
  the first calls start from 0 and catch up);
- ``d`` by simulating ``trajectories`` games from the start for ``horizon`` steps (the exact
  law would touch every state a stochastic team can reach, for weights that are mostly
  negligible), then drawing ``samples`` states from it for the gradient;
- ``Q_i`` at the visited states, exactly, from the joint actions' next states.

The step operator is :class:`~.pursuer_step.PursuerStep`'s general kind, reweighted for
each new table (:meth:`~.pursuer_step.PursuerStep.reweight`).
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario
from ..envs.grid import GridRules
from .pursuer_step import PursuerStep, check_size
from .tables import n_states, start_state, state_cells

SWEEPS = 10
"""Value-iteration sweeps per call (about 0.1-0.2 s each on the 5×5 arena)."""

TRAJECTORIES = 16_384
"""Games simulated from the start to estimate the visits ``d``."""

SAMPLES = 8_192
"""States drawn from the visits, in proportion to them, for the gradient: an unbiased
estimate at a fraction of the cost of every visited state (up to 200,000 of a team that
rarely captures)."""

HORIZON = 60
"""Steps each simulated game runs at most (``γ^60 ≈ 0.55`` at γ 0.99: later visits count
little, and a team worth training captures long before)."""


class WorstCaseGradient:
    """The evader's best response to a pursuer table and the pursuers' gradient against it.

    Call :meth:`refresh` with the team's current table, then :meth:`visits` and
    :meth:`advantages`. ``values`` (the best response's ``V``, warm start of the next call)
    is the state to save to continue exactly. Raises :class:`~.model.TooLargeError` or
    :class:`~.model.UnsupportedError` where an exact best response is out of reach.
    """

    def __init__(
        self,
        scenario: Scenario,
        gamma: float,
        sweeps: int = SWEEPS,
        trajectories: int = TRAJECTORIES,
        horizon: int = HORIZON,
        samples: int = SAMPLES,
    ) -> None:
        check_size(scenario, "general")
        self.scenario, self.gamma = scenario, gamma
        self.sweeps, self.trajectories, self.horizon = sweeps, trajectories, horizon
        self.samples = samples
        self.moves = np.arange(scenario.actions)
        self.start = start_state(scenario)
        self.values = np.zeros(n_states(scenario))
        self.choice = np.zeros(n_states(scenario), dtype=np.int64)
        c = scenario.size**2
        evader = state_cells(scenario)[-1]
        move = GridRules(scenario).move.reshape(c, 5)[:, self.moves]
        self._shift = move[evader] - evader[:, None]  # (S, nb): index change by the move
        self._step: PursuerStep | None = None
        self._swapped: np.ndarray | None = None

    def refresh(self, table: np.ndarray) -> float:
        """Take the team's table ``(S, N, A)``, update the best response's values and moves
        by :attr:`sweeps` sweeps, and return ``V`` at the start."""
        if self._step is None:
            self._step = PursuerStep(self.scenario, table, self.moves, "general")
            self._swapped = np.zeros((len(self.moves), self._step.index.size), dtype=bool)
            for b, (_, flat) in enumerate(self._step.swaps):
                self._swapped[b, flat] = True
        else:
            self._step.reweight(table)
        step, values = self._step, self.values
        for _ in range(self.sweeps):
            q = 1.0 + self.gamma * step.expect(values[:, None])[..., 0]  # (S, nb)
            values = q.max(axis=1)
            values[~step.valid] = 0.0
        self.values = values
        self.choice = q.argmax(axis=1)
        return float(values[self.start])

    def visits(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The visited states and their discounted visits per game ``(rows, weights)``,
        from :attr:`trajectories` games from the start, pursuers sampled from the table and
        the evader playing its best move."""
        step = self._require()
        state = np.full(self.trajectories, self.start)
        counts = np.zeros(step.n_states)
        for t in range(self.horizon):
            counts += np.bincount(state, minlength=step.n_states) * self.gamma**t
            # each pursuer's move drawn from its own row: the joint action's index
            cdf = np.cumsum(step.table[state], axis=-1)  # (M, N, A)
            draw = rng.random(cdf.shape[:2]) * cdf[..., -1]
            moves = (cdf <= draw[..., None]).sum(axis=-1).clip(max=step.a - 1)  # (M, N)
            joint = moves @ step.a ** np.arange(step.n - 1, -1, -1)
            nxt, goes_on = self._next(state, joint)
            state = nxt[goes_on]
            if not len(state):
                break
        rows = np.flatnonzero(counts)
        return rows, counts[rows] / self.trajectories

    def sample(
        self, rng: np.random.Generator, rows: np.ndarray, weights: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`samples` draws from ``rows`` in proportion to ``weights``: the distinct
        states drawn and their weights (draws times the weights' total over
        :attr:`samples`), so that a sum over them estimates the sum over ``rows``
        without bias."""
        if len(rows) <= self.samples:
            return rows, weights
        total = weights.sum()
        drawn = rng.choice(len(rows), size=self.samples, p=weights / total)
        index, count = np.unique(drawn, return_counts=True)
        return rows[index], count * (total / self.samples)

    def advantages(self, rows: np.ndarray) -> np.ndarray:
        """``(R, N, A)``: in each state of ``rows``, ``Q_i(s, a) − Σ_a π_i(a | s) Q_i(s, a)``
        for every pursuer ``i`` and action ``a``, against the best response."""
        step = self._require()
        n, a = step.n, step.a
        joint = np.arange(a**n)
        nxt, goes_on = self._next(np.repeat(rows, len(joint)), np.tile(joint, len(rows)))
        value = 1.0 + self.gamma * goes_on * self.values[nxt]
        value = value.reshape((len(rows),) + (a,) * n)
        probs = step.table[rows]  # (R, N, A)
        letters = "abcdefghijklmnopq"[:n]
        q = np.empty((len(rows), n, a))
        for i in range(n):
            others = [k for k in range(n) if k != i]
            spec = f"r{letters}," + ",".join(f"r{letters[k]}" for k in others)
            q[:, i] = np.einsum(f"{spec}->r{letters[i]}", value, *(probs[:, k] for k in others))
        return q - (q * probs).sum(axis=-1, keepdims=True)

    def _next(self, states: np.ndarray, joint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Next states of ``states`` under joint actions ``joint`` and the evader's best
        moves, and whether the episode goes on (no capture, no ending collision)."""
        step = self._require()
        assert self._swapped is not None
        flat = states * step.index.shape[1] + joint
        move = self.choice[states]
        nxt = step.index.ravel()[flat] + self._shift[states, move]
        goes_on = step.valid[nxt] & ~self._swapped[move, flat]
        if step.terminate:
            goes_on &= step.apart.ravel()[flat]
        return nxt, goes_on

    def _require(self) -> PursuerStep:
        if self._step is None:
            raise RuntimeError("call refresh(table) first")
        return self._step
