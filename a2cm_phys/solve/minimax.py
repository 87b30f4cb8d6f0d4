"""Exact bounds on the grid game's minimax capture time, and the most robust deterministic
pursuer team.

In the grid game both teams move at once, so its minimax value (the pursuers minimise,
the evader maximises ``E[min(T, max_steps)]``) may need mixed strategies in every state:
a matrix game per state (:mod:`.nash` computes it, bracketed by two policies' exact worst
cases). Two games of perfect information bracket it more loosely, and each is a
deterministic dynamic programme over joint states:

- **the evader moves first** (the pursuers see its move), ``V_lo(s) = max_b min_a …``: no
  pursuer team, however it randomises, has a worst case below ``V_lo``;
- **the pursuers move first** (the evader sees their move), ``V_hi(s) = min_a max_b …``:
  its minimising joint action in every state is a deterministic team, the **minimax
  team**, whose worst case is exactly ``V_hi``: against a known deterministic team, the
  evader's best response (:func:`~.best_response.evader_best_response`) knows each move
  before it is made.

So ``V_lo ≤ value ≤ V_hi``, and any team with a worst case below ``V_hi`` must randomise.
A step counts 1, a capture ends the episode, and the recursion runs over the remaining
steps as the best responses' (``V_0 = 0``; it stops when ``V_k = V_{k-1}``, a fixed point,
or after ``max_steps`` steps, the minimax team then being the last step's rule). The value
of a state where a pursuer stands on the evader is 0. Ties in the minimax team's action go
to the lowest joint action index.

*Collisions.* Where a pursuer collision ends the episode (``collisions.mode =
"terminate"``) the pursuers could end it by colliding, and "worst case" measures nothing:
such scenarios raise :class:`~.model.UnsupportedError`. Elsewhere collisions do not change
the moves, so they do not enter.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from ..base.progress import Progress
from ..config import Scenario
from ..envs.grid import GridRules, meet
from .tables import n_states, start_state, state_cells, valid_states
from .transitions import MEMORY_BUDGET, TooLargeError, UnsupportedError

CHUNK = 1 << 15
"""States per block of the recursion (bounds its temporary arrays to ~100 MB)."""


@dataclass
class MinimaxBounds:
    """The two perfect-information games' values and the pursuers-first game's policy.

    ``lower[s]`` and ``upper[s]``: ``V_lo`` and ``V_hi`` from every joint state (steps);
    ``policy[s]``: the minimax team's joint action index ``(a_0 · A + a_1) · A + …`` (the
    oracle's layout, see :func:`~.tables.joint_policy_table`); ``start``: the default
    start's index; ``iterations``: steps of the recursion computed for each game.
    """

    lower: np.ndarray
    upper: np.ndarray
    policy: np.ndarray
    start: int
    iterations: tuple[int, int]
    seconds: float

    @property
    def lower_from_start(self) -> float:
        """``V_lo`` from the default start: no team's worst case is below it."""
        return float(self.lower[self.start])

    @property
    def upper_from_start(self) -> float:
        """``V_hi`` from the default start: the minimax team's worst case."""
        return float(self.upper[self.start])


def check_minimax(scenario: Scenario, memory_budget: float = MEMORY_BUDGET) -> None:
    """Raise :class:`~.model.UnsupportedError` or :class:`~.model.TooLargeError` (naming
    what is wrong) unless :func:`minimax_bounds` can solve the scenario."""
    if scenario.mode != "grid":
        raise UnsupportedError(f"minimax bounds are exact on grids only, got {scenario.mode!r}")
    if scenario.collisions.mode == "terminate":
        raise UnsupportedError(
            "minimax bounds: collisions end the episode in this scenario, so pursuers could"
            " end it by colliding (use collisions.mode = 'off' or 'penalize')"
        )
    s, joint = n_states(scenario), scenario.actions**scenario.pursuers
    need = s * joint * scenario.actions * 4.0  # the next states (int32)
    if need > memory_budget:
        raise TooLargeError(
            f"{scenario.size}x{scenario.size} arena with {scenario.pursuers} pursuer(s): the"
            f" minimax bounds need ~{need / 2**30:.1f} GiB (limit {memory_budget / 2**30:.1f})"
        )


def transitions(scenario: Scenario) -> np.ndarray:
    """Next state ``(S, A^N, B)`` int32 of every joint state, joint pursuer action and
    evader move, ``S`` (one past the last state) where the step captures the evader.

    From the rules' move table and :func:`~a2cm_phys.envs.grid.meet`, as
    :meth:`GridRules.apply` but one agent at a time: a joint state's index is a sum over
    agents, and a capture an "or" over pursuers.
    """
    rules, cells = GridRules(scenario), state_cells(scenario)
    s, n, a, c = n_states(scenario), scenario.pursuers, scenario.actions, scenario.size**2
    move = rules.move.reshape(c, 5).astype(np.int64)
    weight = c ** np.arange(n, -1, -1)  # of each agent's cell in the state index
    evader = [move[cells[n], b] for b in range(a)]
    placed = [[move[cells[i], act] for act in range(a)] for i in range(n)]
    part = [[(placed[i][act] * weight[i]).astype(np.int32) for act in range(a)] for i in range(n)]
    hit = [  # hit[i][act][b]: pursuer i's move act meets the evader's move b
        [[meet(cells[i], placed[i][act], cells[n], e) for e in evader] for act in range(a)]
        for i in range(n)
    ]
    nxt = np.empty((s, a**n, a), dtype=np.int32)
    for j, joint in enumerate(itertools.product(range(a), repeat=n)):
        base = sum(part[i][act] for i, act in enumerate(joint))
        for b in range(a):
            captured = np.logical_or.reduce([hit[i][act][b] for i, act in enumerate(joint)])
            nxt[:, j, b] = np.where(captured, s, base + evader[b])
    return nxt


def _solve(
    nxt: np.ndarray, valid: np.ndarray, horizon: int, pursuers_first: bool, progress: bool
) -> tuple[np.ndarray, np.ndarray, int]:
    """Backward induction of one game: values (integer steps) over ``S + 1`` entries, the
    last the "captured" sentinel (always 0), the last step's joint actions, the steps."""
    what = "minimax upper" if pursuers_first else "minimax lower"
    # no total: the values reach their fixed point long before max_steps (9 steps on 5x5)
    with Progress(what, unit="steps", enabled=progress) as bar:
        return _induction(nxt, valid, horizon, pursuers_first, bar)


def _induction(
    nxt: np.ndarray, valid: np.ndarray, horizon: int, pursuers_first: bool, bar: Progress
) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`_solve`'s recursion, ``bar`` counting its steps."""
    v = np.zeros(len(valid) + 1, dtype=np.int32)
    new = np.zeros_like(v)
    policy = np.zeros(len(valid), dtype=np.int64)
    k = 0
    while k < horizon:
        for lo in range(0, len(valid), CHUNK):  # chunks: all states at once take ~0.5 GiB
            part = slice(lo, min(lo + CHUNK, len(valid)))  # never the sentinel
            q = v[nxt[part]]  # (chunk, joint, move): steps after this one
            if pursuers_first:
                worst = q.max(axis=2)
                policy[part] = worst.argmin(axis=1)
                new[part] = worst.min(axis=1) + 1
            else:
                new[part] = q.min(axis=1).max(axis=1) + 1
        new[:-1][~valid] = 0
        k += 1
        changed = int(np.count_nonzero(new != v))
        bar.note(f"{changed:,} changed")
        bar.update()
        if not changed:
            break
        v, new = new, v
    return v[:-1].astype(np.float64), policy, k


_SOLVED: dict[Scenario, MinimaxBounds] = {}
"""The last few scenarios' bounds (:func:`minimax_bounds`), oldest first."""

CACHED = 4
"""Scenarios whose bounds :func:`minimax_bounds` keeps."""


def minimax_bounds(scenario: Scenario, progress: bool = False) -> MinimaxBounds:
    """Solve both perfect-information games of the scenario (see the module); ``progress``
    reports the steps of each recursion on stderr.

    Cached per scenario (its arrays are read-only), so that every pairing of a cross-play
    table that names the minimax team shares one solution. Raises
    :class:`~.model.UnsupportedError` or :class:`~.model.TooLargeError` as
    :func:`check_minimax`. About 20 s and 0.5 GiB on a 5×5 arena with three pursuers.
    """
    if scenario in _SOLVED:
        return _SOLVED[scenario]
    check_minimax(scenario)
    t0 = time.perf_counter()
    nxt = transitions(scenario)
    valid = valid_states(scenario)
    horizon = scenario.max_steps
    upper, policy, k_hi = _solve(nxt, valid, horizon, True, progress)
    lower, _, k_lo = _solve(nxt, valid, horizon, False, progress)
    for array in (lower, upper, policy):
        array.setflags(write=False)
    bounds = MinimaxBounds(
        lower, upper, policy, start_state(scenario), (k_lo, k_hi), time.perf_counter() - t0
    )
    while len(_SOLVED) >= CACHED:
        del _SOLVED[next(iter(_SOLVED))]
    _SOLVED[scenario] = bounds
    return bounds
