"""The grid game's value with mixed strategies, bracketed exactly, and its equilibrium evader.

Both teams move at once, so the game's value (the pursuers minimise, the evader maximises
``E[min(T, max_steps)]``) is that of a stochastic game, a matrix game in every state
(Shapley, 1953):

    V(s) = val_{a, b} M_s[a, b],   M_s[a, b] = 1 + V(s'(s, a, b))   (0 after a capture),

``a`` the pursuers' joint action (the team randomises jointly), ``b`` the evader's move.
:mod:`.minimax` brackets it by the two games of perfect information; this module computes
it. :func:`game_value` runs Shapley's value iteration from ``V = 0`` and solves every
state's game at once, approximately, by regret matching+ (Tammelin, 2014) with
alternating updates, its regrets carried from sweep to sweep (consecutive sweeps' games
differ little). Each solved game gives both teams' average strategies, hence a policy for
each over all joint states:

- the **equilibrium evader** ``σ``, a table ``(S, 1, A)`` (:mod:`.tables`), and
- the **equilibrium team** ``π``, a distribution over joint actions in every state.

The approximation does not enter the bracket: each policy is evaluated exactly against its
opponent's exact best response over the same horizon ``max_steps`` (backward induction over
joint actions, :func:`evader_worst_case` and :func:`team_worst_case`, to within
:data:`TOLERANCE`). The team that best-responds to ``σ`` catches it in ``lower`` steps on
average, and no team does better, so **the value is at least ``lower``**; the evader that
best-responds to ``π`` escapes it for ``upper``, so **the value is at most ``upper``**.
The team ``π`` is correlated (its pursuers draw their moves jointly); a team of independent
actors, as learned ones are, is a special case, so its worst case is at least ``lower`` too.

*Collisions.* As for :mod:`.minimax`: where a collision ends the episode the pursuers could
end it by colliding, so such scenarios raise :class:`~.model.UnsupportedError`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from ..base.progress import Progress
from ..config import Scenario
from .minimax import check_minimax, transitions
from .tables import check_table, n_states, start_state, valid_states
from .transitions import MEMORY_BUDGET, TooLargeError

SWEEPS = 60
"""Shapley sweeps at most (each one step more of the game; on the 5×5 arena with three
pursuers the values settle in 9)."""

ITERATIONS = 20
"""Regret-matching+ iterations per sweep."""

POLISH = 400
"""Iterations of the last sweep, whose average strategies are the policies."""

TOLERANCE = 1e-6
"""Error bound that ends the best responses' backward induction early (steps): a bound is
short of its policy's exact worst case by at most this."""


@dataclass
class GameValue:
    """The game's value bracketed, with the policies that bracket it.

    ``lower``: the equilibrium evader's worst case (the value is at least this);
    ``upper``: the equilibrium team's worst case (the value is at most this); ``estimate``:
    the value iteration's own figure from every joint state; ``evader``: the equilibrium
    evader's table ``(S, 1, A)``; ``team``: the equilibrium team's joint distribution
    ``(S, A^N)`` (the oracle's joint-action layout, :func:`~.tables.joint_policy_table`;
    ``None`` when loaded from the cache); ``start``: the default start's index; ``sweeps``:
    Shapley sweeps run; ``seconds``: the solve's; ``cached``: whether loaded from the cache
    (:func:`a2cm_phys.solve.cache.load_or_solve_value`).
    """

    lower: float
    upper: float
    estimate: np.ndarray
    evader: np.ndarray
    team: np.ndarray | None
    start: int
    sweeps: int
    seconds: float
    cached: bool = False

    @property
    def estimate_from_start(self) -> float:
        """The value iteration's estimate from the default start (not a bound)."""
        return float(self.estimate[self.start])


def check_game_value(scenario: Scenario, memory_budget: float = MEMORY_BUDGET) -> None:
    """Raise :class:`~.model.UnsupportedError` or :class:`~.model.TooLargeError` (naming
    what is wrong) unless :func:`game_value` can solve the scenario."""
    check_minimax(scenario, memory_budget)
    s, joint = n_states(scenario), scenario.actions**scenario.pursuers
    need = s * joint * scenario.actions * 32.0  # next states, games in float64, temporaries
    if need > memory_budget:
        raise TooLargeError(
            f"{scenario.size}x{scenario.size} arena with {scenario.pursuers} pursuer(s): the"
            f" game's value needs ~{need / 2**30:.1f} GiB (limit {memory_budget / 2**30:.1f})"
        )


def _normalise(regret: torch.Tensor, out: torch.Tensor) -> torch.Tensor:
    """Regret matching into ``out``: the positive regrets' distribution (uniform where all
    are 0)."""
    total = regret.sum(dim=1, keepdim=True)
    torch.div(regret, total.clamp_min(1e-30), out=out)
    return out.masked_fill_(total == 0, 1.0 / regret.shape[1])


class _Games:
    """Every state's matrix game at once; the regrets persist from one solve to the next.

    The iterations work in place in buffers of their own: fresh arrays of this size each
    iteration cost more in page faults than in arithmetic."""

    def __init__(self, n: int, joint: int, moves: int) -> None:
        self.team_regret = torch.zeros(n, joint)
        self.evader_regret = torch.zeros(n, moves)
        self._cost = torch.empty(n, joint, 1)
        self._gain = torch.empty(n, 1, moves)

    def solve(
        self,
        games: torch.Tensor,
        iterations: int,
        tick: Callable[[], None] | None = None,
    ) -> tuple[torch.Tensor, ...]:
        """``iterations`` of alternating RM+ on ``games`` ``(S, A^N, B)`` (the team
        minimises): the linearly weighted average strategies of both teams and, for each
        state, the value each guarantees (the evader's lower, the team's upper).
        ``tick()`` is called after each iteration."""
        team = _normalise(self.team_regret, torch.empty_like(self.team_regret))
        evader = _normalise(self.evader_regret, torch.empty_like(self.evader_regret))
        team_avg, evader_avg = torch.zeros_like(team), torch.zeros_like(evader)
        cost, gain = self._cost[..., 0], self._gain[:, 0]
        for t in range(1, iterations + 1):
            torch.bmm(games, evader[:, :, None], out=self._cost)  # (S, A^N): the team's
            expected = (team * cost).sum(dim=1, keepdim=True)
            self.team_regret.add_(expected).sub_(cost).clamp_min_(0.0)
            _normalise(self.team_regret, team)
            torch.bmm(team[:, None, :], games, out=self._gain)  # (S, B): the evader's
            expected = (evader * gain).sum(dim=1, keepdim=True)
            self.evader_regret.add_(gain).sub_(expected).clamp_min_(0.0)
            _normalise(self.evader_regret, evader)
            team_avg.add_(team, alpha=t)
            evader_avg.add_(evader, alpha=t)
            if tick is not None:
                tick()
        team_avg /= team_avg.sum(dim=1, keepdim=True)
        evader_avg /= evader_avg.sum(dim=1, keepdim=True)
        low = torch.bmm(games, evader_avg[:, :, None])[..., 0].min(dim=1).values
        high = torch.bmm(team_avg[:, None, :], games)[:, 0].max(dim=1).values
        return team_avg, evader_avg, low, high


def _step_values(nxt: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """``M_s[a, b] = 1 + V(s')``, the capture sentinel's ``V`` 0: ``(S, A^N, B)``."""
    extended = torch.cat([values, values.new_zeros(1)])
    return 1.0 + extended[nxt]


def _rules(scenario: Scenario) -> tuple[torch.Tensor, torch.Tensor]:
    """After :func:`check_game_value`: the next states ``(S, A^N, B)`` (int32, half the
    memory of int64; the capture sentinel ``S``) and the mask of states that cannot occur."""
    check_game_value(scenario)
    return torch.from_numpy(transitions(scenario)), torch.from_numpy(~valid_states(scenario))


def team_worst_case(
    scenario: Scenario, team: np.ndarray, tol: float = TOLERANCE, progress: bool = False
) -> np.ndarray:
    """``E[min(T, max_steps)]`` from every joint state when the evader best-responds to the
    joint team table ``team`` ``(S, A^N)`` (``progress``: report the steps on stderr)."""
    nxt, invalid = _rules(scenario)
    with _steps("team worst case", progress) as bar:
        return _best_response(nxt, invalid, scenario.max_steps, tol, bar, team=torch.tensor(team))


def evader_worst_case(
    scenario: Scenario, evader: np.ndarray, tol: float = TOLERANCE, progress: bool = False
) -> np.ndarray:
    """``E[min(T, max_steps)]`` from every joint state when the pursuers best-respond to the
    evader's table ``evader`` ``(S, 1, A)`` (the scenario's moves: no "stay" column where
    ``actions = 4``; a ``ValueError`` says what is wrong with a table; ``progress``: report
    the steps on stderr)."""
    table = check_table(scenario, evader, "evader")
    if table.shape[-1] != scenario.actions:
        raise ValueError(
            f"evader table: {table.shape[-1]} moves, the scenario has {scenario.actions}"
        )
    nxt, invalid = _rules(scenario)
    moves = torch.from_numpy(table[:, 0])
    with _steps("evader worst case", progress) as bar:
        return _best_response(nxt, invalid, scenario.max_steps, tol, bar, evader=moves)


def _steps(what: str, progress: bool) -> Progress:
    """The progress of a backward induction: no total, as it stops long before
    ``max_steps`` against the equilibrium (the bound falls geometrically to ``tol``),
    and a time left reckoned from ``max_steps`` would be hours off."""
    return Progress(what, unit="steps", enabled=progress)


def _best_response(
    nxt: torch.Tensor,
    invalid: torch.Tensor,
    horizon: int,
    tol: float,
    bar: Progress,
    team: torch.Tensor | None = None,
    evader: torch.Tensor | None = None,
) -> np.ndarray:
    """Backward induction over ``horizon`` steps of the best response to ``team``
    ``(S, A^N)`` (the evader maximising) or to ``evader`` ``(S, B)`` (the team minimising),
    stopped once the remaining steps cannot add ``tol`` (values only grow from 0); ``bar``
    counts the steps."""
    mixture = team if team is not None else evader
    assert mixture is not None
    mixture = mixture.double()
    mixture /= mixture.sum(dim=1, keepdim=True)  # exact sums: float32 ones are off by 1e-7
    values = torch.zeros(len(invalid), dtype=torch.float64)
    for k in range(1, horizon + 1):
        games = _step_values(nxt, values)
        if team is not None:
            new = torch.bmm(mixture[:, None, :], games)[:, 0].max(dim=1).values
        else:
            new = torch.bmm(games, mixture[:, :, None])[..., 0].min(dim=1).values
        new[invalid] = 0.0
        growth = float((new - values).max())
        values = new
        bar.note(f"bound {(horizon - k) * growth:.1e} (tol {tol:.0e})")
        bar.update()
        if (horizon - k) * growth <= tol:
            break
    return values.numpy()


_SOLVED: dict[tuple[Scenario, int, int, int], GameValue] = {}
"""The last couple of :func:`game_value` solutions, oldest first."""

CACHED = 2
"""Solutions :func:`game_value` keeps."""


def game_value(
    scenario: Scenario,
    sweeps: int = SWEEPS,
    iterations: int = ITERATIONS,
    polish: int = POLISH,
    progress: bool = False,
) -> GameValue:
    """The scenario's value with mixed strategies, bracketed (see the module).

    Sweeps stop after ``sweeps`` (or ``max_steps``, the game's length) or once no state's
    value moves by more than its games' own approximation (the largest gap between the two
    teams' guarantees). Cached per arguments. About 3 minutes and 3.4 GiB on the 5×5 arena
    with three pursuers on 2 cores; ``progress`` reports each phase on stderr (the sweeps'
    iterations, the last sweep's polish, both worst cases). Raises
    :class:`~.model.UnsupportedError` or :class:`~.model.TooLargeError` as
    :func:`check_game_value`.
    """
    key = (scenario, sweeps, iterations, polish)
    if key in _SOLVED:
        return _SOLVED[key]
    t0 = time.perf_counter()
    nxt, invalid = _rules(scenario)
    games_state = _Games(*nxt.shape)
    values, done = _shapley(
        nxt, invalid, games_state, min(sweeps, scenario.max_steps), iterations, progress
    )
    with Progress("polish", total=polish, unit="iterations", enabled=progress) as bar:
        team, evader, _, _ = games_state.solve(_step_values(nxt, values), polish, bar.update)
    evader[invalid] = 1.0 / nxt.shape[2]  # never read: any distribution
    team, evader = team.double(), evader.double()
    team /= team.sum(dim=1, keepdim=True)
    evader /= evader.sum(dim=1, keepdim=True)
    start, horizon = start_state(scenario), scenario.max_steps
    with _steps("evader worst case", progress) as bar:
        lower = float(_best_response(nxt, invalid, horizon, TOLERANCE, bar, evader=evader)[start])
    with _steps("team worst case", progress) as bar:
        upper = float(_best_response(nxt, invalid, horizon, TOLERANCE, bar, team=team)[start])
    evader_table = evader.numpy()[:, None, :]
    estimate, team_table = values.double().numpy(), team.numpy()
    for array in (estimate, evader_table, team_table):
        array.setflags(write=False)
    value = GameValue(
        lower, upper, estimate, evader_table, team_table, start, done, time.perf_counter() - t0
    )
    while len(_SOLVED) >= CACHED:
        del _SOLVED[next(iter(_SOLVED))]
    _SOLVED[key] = value
    return value


def _shapley(
    nxt: torch.Tensor,
    invalid: torch.Tensor,
    games_state: _Games,
    sweeps: int,
    iterations: int,
    progress: bool,
) -> tuple[torch.Tensor, int]:
    """Shapley's value iteration, at most ``sweeps`` sweeps of ``iterations`` RM+
    iterations each (see :func:`game_value`): the values and the sweeps run."""
    values = torch.zeros(nxt.shape[0])
    done = 0
    # counted in iterations (a sweep is 20 of them, some 20 s on 5x5): a line every 30 s
    with Progress("Shapley", unit="it", enabled=progress) as bar:
        for done in range(1, sweeps + 1):
            games = _step_values(nxt, values)  # (the last sweep's freed: ~0.4 GiB on 5x5)
            _, _, low, high = games_state.solve(games, iterations, bar.update)
            del games
            new = 0.5 * (low + high)
            new[invalid] = 0.0
            moved = float((new - values).abs().max())
            gap = float((high - low)[~invalid].max())
            values = new
            bar.note(f"sweep {done}: moved {moved:.1e}, gap {gap:.1e}")
            if moved <= gap:
                break
    return values, done
