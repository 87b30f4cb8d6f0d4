"""The grid game's per-agent tables: moves, captures, walls and collisions of one grid
scenario (:class:`GridTables`), the solvers' limits, and the errors they raise.

All tables come from :class:`~a2cm_phys.envs.grid.GridRules`: its move table, and its
:meth:`~a2cm_phys.envs.grid.GridRules.apply` run on every one-pursuer (capture) and
two-pursuer (collision) configuration. The joint state's and joint action's numbering is
:mod:`.tables`'.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..config import Scenario
from ..envs.evaders.scripted import STAY
from ..envs.grid import GridRules
from .tables import (
    SCRIPTED_EVADERS,
    check_table,
    flee_law,
    joint_actions,
    state_cells,
    state_of_cells,
    valid_states,
)

MAX_STATES = 20_000_000
"""Largest joint state space the solver attempts."""

MEMORY_BUDGET = 3 * 2**30
"""Largest estimated peak memory (bytes) the solver attempts."""

CHUNK_BYTES = 32 * 2**20
"""Target size of one slice of the ``states × joint actions`` tensor."""


class UnsupportedError(ValueError):
    """The scenario is not a game this solver handles (physics mode, ill-posed rewards)."""


class TooLargeError(ValueError):
    """The joint state space is too large to solve exactly within the limits."""


def check_supported(scenario: Scenario) -> None:
    """Raise :class:`UnsupportedError` unless the scenario is a well-posed grid game.

    The objective is the expected total raw reward until termination (no discount), which
    is finite and attained by a stationary policy only if every step costs something.
    """
    if scenario.mode != "grid":
        raise UnsupportedError(f"the oracle solves grid mode only, got mode={scenario.mode!r}")
    rw = scenario.rewards
    if rw.step + scenario.pursuers * max(rw.wall, 0.0) >= 0:
        raise UnsupportedError(
            "the oracle minimises expected cost until termination and needs every step to "
            f"cost: rewards.step + pursuers * max(rewards.wall, 0) < 0 (step={rw.step:g})"
        )
    if scenario.collisions.mode == "penalize" and rw.collision > 0:
        raise UnsupportedError("rewards.collision > 0 with collisions.mode='penalize' is unbounded")


def free_table(scenario: Scenario, moves: np.ndarray) -> np.ndarray:
    """``(C, A, C, nb)``: 1.0 where pursuer (cell, action) misses evader (cell, ``moves[b]``)."""
    c, a, nb = scenario.size**2, scenario.actions, len(moves)
    one = GridRules(dataclasses.replace(scenario, pursuers=1))
    p, act, e, b = (g.ravel() for g in np.indices((c, a, c, nb)))
    _, captured, _, _ = one.apply(np.stack([p, e]), act[:, None], np.asarray(moves)[b])
    return 1.0 - captured.reshape(c, a, c, nb).astype(np.float64)


def pair_table(scenario: Scenario) -> np.ndarray:
    """``(C, A, C, A)``: collisions (0/1) of two pursuers' (cell, action) pairs."""
    c, a = scenario.size**2, scenario.actions
    two = GridRules(dataclasses.replace(scenario, pursuers=2))
    pi, ai, pj, aj = (g.ravel() for g in np.indices((c, a, c, a)))
    cells = np.stack([pi, pj, np.zeros_like(pi)])
    _, _, collisions, _ = two.apply(cells, np.stack([ai, aj], 1), np.full(len(pi), STAY))
    return collisions.reshape(c, a, c, a).astype(np.float64)


class GridTables:
    """Per-agent transition and reward tables of one grid scenario.

    The evader plays the scenario's scripted policy, or ``evader_probs``, an evader policy
    table (:mod:`.tables`) that replaces it: the oracle then solves the pursuers' best
    response to that evader.

    Raises :class:`UnsupportedError` for scenarios it cannot solve and
    :class:`TooLargeError` when :meth:`memory_estimate` exceeds ``memory_budget`` or the
    state count exceeds ``max_states``.
    """

    def __init__(
        self,
        scenario: Scenario,
        memory_budget: float = MEMORY_BUDGET,
        max_states: int = MAX_STATES,
        evader_probs: np.ndarray | None = None,
    ) -> None:
        check_supported(scenario)
        if evader_probs is None and scenario.evader not in SCRIPTED_EVADERS:
            raise UnsupportedError(
                f"the oracle needs a scripted evader ({', '.join(SCRIPTED_EVADERS)}) or the "
                f"evader's policy table, got evader={scenario.evader!r}"
            )
        self.scenario = scenario
        self.rules = GridRules(scenario)
        self.n = n = scenario.pursuers
        self.n_actions = a = scenario.actions
        self.n_cells = c = scenario.size**2
        self.n_states = c ** (n + 1)
        self.n_joint = a**n
        self.shape = (c,) * (n + 1)
        self.table = None if evader_probs is None else check_table(scenario, evader_probs, "evader")
        if self.table is not None:  # the moves some state plays
            self.evader_moves = np.flatnonzero(self.table[:, 0].any(axis=0))
        elif scenario.evader == "static":
            self.evader_moves = np.array([STAY])
        else:
            self.evader_moves = np.arange(a)
        self.terminate = scenario.collisions.mode == "terminate"
        rw = scenario.rewards
        self.collision_reward = rw.collision if scenario.collisions.mode != "off" else 0.0
        self.action_axes = tuple(range(1, 2 * n, 2))
        per_p0 = self.n_states // c * self.n_joint
        self.chunk = max(1, min(c, CHUNK_BYTES // (8 * per_p0)))
        need = self.memory_estimate()
        if self.n_states > max_states or need > memory_budget:
            raise TooLargeError(
                f"{scenario.size}x{scenario.size} arena with {n} pursuers is too large to solve "
                f"exactly: {self.n_states:,} joint states x {self.n_joint:,} joint actions "
                f"need ~{need / 2**30:.1f} GiB (limits: {max_states:,} states, "
                f"{memory_budget / 2**30:.1f} GiB)"
            )
        move = self.rules.move.reshape(c, 5).astype(np.intp)
        self.pmove = move[:, :a]  # (C, A): pursuer cell, action -> next cell
        self.emove = move[:, self.evader_moves]  # (C, nb): evader cell, move -> next cell
        self.free = free_table(scenario, self.evader_moves)
        self.walls = self.rules.blocked.reshape(c, 5)[:, :a].astype(np.float64)
        self.pair_collide = pair_table(scenario)
        self.weights = self._evader_weights()

    # ------------------------------------------------------------------ sizes and states

    @property
    def may_escape(self) -> bool:
        """Whether the evader's law might keep capture from being forced somewhere.

        Not for the uniform and static evaders: pursuers walk up to a static evader, and an
        evader playing each of the ``actions`` moves with positive probability in every
        state sometimes steps into (or swaps with) an adjacent pursuer. Any other law might.
        With obstacles, only the uniform evader over every move is sure to be caught from
        every state: also from those that never occur (an agent on a blocked cell, which
        the value iteration sweeps too), where no pursuer can walk up to an evader that
        does not leave its blocked cell.
        """
        own = self.evader_moves < self.n_actions
        every_move = own.sum() == self.n_actions
        if self.weights is None:
            return bool(self.rules.blocked_cell.any()) and not every_move
        if self.rules.blocked_cell.any():
            return True
        every = bool(np.all(self.weights[self.valid()][:, own] > 0))
        return not (every_move and every)

    @property
    def n_moves(self) -> int:
        """Number of evader moves with a probability (``actions``, or 1 for ``static``)."""
        return len(self.evader_moves)

    def memory_estimate(self) -> float:
        """Estimated peak bytes of a solve (value arrays, backup slices, policy replay)."""
        s, nb, n = self.n_states, len(self.evader_moves), self.n
        law = self.table is not None or self.scenario.evader == "flee"  # not uniform
        state_arrays = s * 8 * 8 + (s * nb * 8 if law else 0)
        chain = nb * s * self.n_actions ** (n - 1) * 8  # one pre-reduced tensor per evader move
        slices = 4 * self.chunk * (s // self.n_cells) * self.n_joint * 8
        full = s * self.n_joint
        extra = full * (8 if self.reward_varies else 0) + full * self.terminate
        extra += full * law  # safe-action mask
        replay = s * nb * (8 + 8 + 4 * (n + 1) * 2)
        return float(state_arrays + chain + slices + extra + replay)

    def decode(self, index: np.ndarray) -> np.ndarray:
        """Cells ``(N + 1, K)`` (pursuers, then the evader) of state indices ``(K,)``."""
        return state_cells(self.scenario, index)

    def encode(self, cells: np.ndarray) -> np.ndarray:
        """State indices of cells ``(N + 1, …)``."""
        return state_of_cells(self.scenario, cells)

    def joint_to_actions(self, joint: np.ndarray) -> np.ndarray:
        """Per-pursuer actions ``(K, N)`` int64 of joint action indices ``(K,)``."""
        return joint_actions(self.scenario, joint)

    def valid(self) -> np.ndarray:
        """``(S,)`` mask of states that can occur: no pursuer on the evader's cell."""
        return valid_states(self.scenario)

    # ------------------------------------------------------------------ tables

    def _evader_weights(self) -> np.ndarray | None:
        """``(S, nb)`` probabilities of the evader's moves; ``None`` when uniform."""
        if self.table is not None:
            weights = self.table[:, 0, self.evader_moves]
            return None if np.all(weights == 1.0 / self.n_moves) else weights
        if self.scenario.evader == "flee":
            return flee_law(self.scenario)
        return None

    @property
    def reward_varies(self) -> bool:
        """Whether the immediate reward depends on the state and joint action (walls,
        captures or collisions pay), not only the step's."""
        rw = self.scenario.rewards
        return bool(rw.wall or rw.capture or self.collision_reward)
