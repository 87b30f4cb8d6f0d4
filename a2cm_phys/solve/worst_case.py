"""The exact gradients of both teams' worst cases on the grid (exploitability descent).

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

:class:`EvaderGradient` is the same for the other team: the pursuers' best response to an
evader table (the oracle's backup, :mod:`.dp`) and the gradient of its value in the
evader's policy, which the evader ascends.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..config import Rewards, Scenario
from ..envs.grid import GridRules
from .dp import bellman_backup
from .model import GridModel
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

EVADER_SWEEPS = 3
"""Sweeps of the oracle's backup per call of :class:`EvaderGradient` (about 0.5 s each on
the 5×5 arena; the last, which reads the best response off, among them)."""

HORIZON = 60
"""Steps each simulated game runs at most (``γ^60 ≈ 0.55`` at γ 0.99: later visits count
little, and a team worth training captures long before)."""


def draw(rng: np.random.Generator, probs: np.ndarray) -> np.ndarray:
    """One action per row of ``probs`` ``(M, K, A)``: ``(M, K)`` indices, drawn by inverse
    CDF from ``M · K`` uniforms."""
    cdf = np.cumsum(probs, axis=-1)
    u = rng.random(cdf.shape[:2]) * cdf[..., -1]
    return (cdf <= u[..., None]).sum(axis=-1).clip(max=probs.shape[-1] - 1)


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
        places = step.a ** np.arange(step.n - 1, -1, -1)

        def moves(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            joint = draw(rng, step.table[state]) @ places  # each pursuer from its own row
            return joint, self.choice[state]

        return self.simulate(moves)

    def simulate(
        self, moves: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """The visited states and their discounted visits per game ``(rows, weights)`` of
        :attr:`trajectories` games from the start, :attr:`horizon` steps at most, ``moves``
        giving the joint actions and the evader's moves in the states it is given."""
        step = self._require()
        state = np.full(self.trajectories, self.start)
        counts = np.zeros(step.n_states)
        for t in range(self.horizon):
            counts += np.bincount(state, minlength=step.n_states) * self.gamma**t
            nxt, goes_on = self.transition(state, *moves(state))
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
        states = np.repeat(rows, len(joint))
        nxt, goes_on = self.transition(states, np.tile(joint, len(rows)), self.choice[states])
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

    def transition(
        self, states: np.ndarray, joint: np.ndarray, move: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Next states of ``states`` under the pursuers' joint actions ``joint`` and the
        evader's moves ``move``, and whether the episode goes on (no capture, no ending
        collision)."""
        step = self._require()
        assert self._swapped is not None
        flat = states * step.index.shape[1] + joint
        nxt = step.index.ravel()[flat] + self._shift[states, move]
        goes_on = step.valid[nxt] & ~self._swapped[move, flat]
        if step.terminate:
            goes_on &= step.apart.ravel()[flat]
        return nxt, goes_on

    def _require(self) -> PursuerStep:
        if self._step is None:
            raise RuntimeError("call refresh(table) first")
        return self._step


class EvaderGradient:
    """The pursuers' best response to an evader table and the evader's gradient against it.

    The mirror of :class:`WorstCaseGradient`. Against an evader table ``σ`` the pursuers'
    best response (the oracle against ``σ``, on a game whose every step costs 1) has the
    costs

        V(s) = min_a Σ_b σ(b | s) · (1 + γ · [the episode goes on] · V(s'))

    and, the minimising joint actions held fixed, the gradient of ``V(s₀)`` in the evader's
    policy is ``Σ_s d(s) Σ_b ∇σ(b | s) · Q(s, b)``, ``d`` the discounted visits when the
    pursuers play their best response and the evader ``σ``, ``Q(s, b)`` the value of the
    step when the evader moves ``b``. The evader *ascends* it: its worst case is how soon
    the team that knows its policy catches it.

    ``V`` comes from the oracle's backup (:func:`~.dp.bellman_backup`), ``sweeps`` a call
    warm-started from the last (``first_sweeps`` on the first). The next states, the visits'
    simulation and the sampling are ``worst``'s (:class:`WorstCaseGradient`, refreshed
    first), which the pursuers' own descent keeps up to date.
    """

    def __init__(
        self,
        scenario: Scenario,
        gamma: float,
        worst: WorstCaseGradient,
        sweeps: int = EVADER_SWEEPS,
        first_sweeps: int = 20,
    ) -> None:
        # the best response minimises the episode's length: a step costs 1, nothing else
        self.game = dataclasses.replace(scenario, rewards=Rewards(step=-1.0))
        self.gamma, self.worst = gamma, worst
        self.sweeps, self.first_sweeps = sweeps, first_sweeps
        self.values: np.ndarray | None = None  # V over every joint state (steps)
        self.best = np.zeros(n_states(scenario), dtype=np.int64)  # the joint action
        self.table: np.ndarray | None = None  # σ, (S, nb)

    def refresh(self, evader_probs: np.ndarray) -> float:
        """Take the evader's table ``(S, 1, A)``, update the pursuers' best response by
        :attr:`sweeps` sweeps, and return ``V`` at the start."""
        model = GridModel(self.game, evader_probs=evader_probs)
        first = self.values is None
        v = np.zeros(model.shape) if first else -self.values.reshape(model.shape)
        for _ in range((self.first_sweeps if first else self.sweeps) - 1):
            v = bellman_backup(model, self.gamma * v, None, None)
        policy = np.zeros(model.shape, dtype=np.int64)
        v = bellman_backup(model, self.gamma * v, None, None, policy)
        self.values, self.best = -v.ravel(), policy.ravel()
        self.table = evader_probs[:, 0]
        return float(self.values[self.worst.start])

    def visits(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """The visited states and their discounted visits per game ``(rows, weights)``,
        from the worst case's number of simulated games, the pursuers playing their best
        response and the evader sampled from its table."""
        table = self._require()
        return self.worst.simulate(
            lambda state: (self.best[state], draw(rng, table[state, None])[:, 0])
        )

    def advantages(self, rows: np.ndarray) -> np.ndarray:
        """``(R, nb)``: in each state of ``rows``, ``Q(s, b) − Σ_b σ(b | s) Q(s, b)`` for
        every evader move ``b``, against the pursuers' best response."""
        table = self._require()
        nb = table.shape[1]
        states = np.repeat(rows, nb)
        move = np.tile(np.arange(nb), len(rows))
        nxt, goes_on = self.worst.transition(states, self.best[states], move)
        assert self.values is not None
        q = (1.0 + self.gamma * goes_on * self.values[nxt]).reshape(len(rows), nb)
        return q - (q * table[rows]).sum(axis=-1, keepdims=True)

    def _require(self) -> np.ndarray:
        if self.table is None:
            raise RuntimeError("call refresh(evader_probs) first")
        return self.table
