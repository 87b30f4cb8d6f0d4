"""The game's value bracketed (``a2cm_phys.solve.nash``) against an exact brute force.

The brute force solves every state's matrix game by linear programming (scipy's HiGHS), one
state at a time, over the transitions :class:`test_best_response.Brute` enumerates from the
rules written out in plain Python: Shapley's recursion, exactly, over ``max_steps`` steps.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog
from test_best_response import SMALL, Brute, grid

from a2cm_phys.commands.oracle import main
from a2cm_phys.config import Rewards, Scenario
from a2cm_phys.solve.best_response import (
    evader_best_response,
    evaluate_tables,
    pursuers_best_response,
)
from a2cm_phys.solve.cache import cached_value, load_or_solve, load_or_solve_value
from a2cm_phys.solve.minimax import minimax_bounds
from a2cm_phys.solve.nash import TOLERANCE, evader_worst_case, game_value, team_worst_case
from a2cm_phys.solve.tables import (
    joint_policy_table,
    scripted_evader_table,
    start_state,
    uniform_table,
)

LP_TOLERANCE = 1e-6
"""How far HiGHS's values may be off (its feasibility tolerance is 1e-7 per game)."""


def matrix_game_value(steps: np.ndarray) -> float:
    """The value of ``steps`` ``(J, B)`` for the evader (columns) maximising, by LP."""
    j, b = steps.shape
    # variables: the evader's mixture q (B) and the value v; maximise v
    cost = np.zeros(b + 1)
    cost[-1] = -1.0
    rows = np.hstack([-steps, np.ones((j, 1))])  # v - q·steps[j] <= 0 for every row j
    total = np.hstack([np.ones((1, b)), np.zeros((1, 1))])
    bounds = [(0, None)] * b + [(None, None)]
    res = linprog(cost, A_ub=rows, b_ub=np.zeros(j), A_eq=total, b_eq=[1.0], bounds=bounds)
    assert res.status == 0, res.message
    return float(-res.fun)


def brute_value(b: Brute, horizon: int) -> np.ndarray:
    """Shapley's recursion over ``horizon`` steps, every state's game solved exactly."""
    v = np.zeros(len(b.states))
    for _ in range(horizon):
        new = np.zeros_like(v)
        for k in np.flatnonzero(b.valid):
            steps = np.where(b.capture[k], 1.0, 1.0 + v[b.next[k]])
            new[k] = matrix_game_value(steps)
        if np.max(np.abs(new - v)) < 1e-12:
            break
        v = new
    return v


@pytest.mark.parametrize(
    ("overrides", "stationary"),
    [
        ({"size": 3, "pursuers": 2, "max_steps": 50, "collisions__mode": "penalize"}, True),
        # the horizon binds: the truncated game's equilibria are not stationary
        ({"size": 3, "pursuers": 2, "max_steps": 3}, False),
    ],
)
def test_bracket_holds_the_exact_value(overrides: dict, stationary: bool) -> None:
    sc = grid(**overrides)
    value = game_value(sc)
    b = Brute(sc, sc.actions)
    exact = brute_value(b, sc.max_steps)
    start = start_state(sc)
    slack = TOLERANCE + LP_TOLERANCE
    assert value.lower - slack <= exact[start] <= value.upper + slack
    bounds = minimax_bounds(sc)  # the games of perfect information bracket it too
    assert bounds.lower_from_start <= value.upper + slack
    assert value.lower <= bounds.upper_from_start + slack
    if not stationary:
        return
    assert value.upper - value.lower < 0.01 * exact[start]
    # From every state: the policies' exact worst cases bracket the value, closely.
    low = evader_worst_case(sc, value.evader)[b.valid]
    high = team_worst_case(sc, value.team)[b.valid]
    assert np.all(low <= exact[b.valid] + slack) and np.all(exact[b.valid] <= high + slack)
    # the lower bound is the oracle's too, where the horizon does not bind
    timed = dataclasses.replace(sc, rewards=Rewards(step=-1.0))
    oracle = pursuers_best_response(timed, value.evader).value_from_start
    assert oracle == pytest.approx(value.lower, abs=1e-3)
    assert np.max(high - low) < 0.1 and np.ptp(exact[b.valid]) > 1.0
    np.testing.assert_allclose(value.estimate[b.valid], exact[b.valid], atol=0.1)


def test_the_equilibrium_policies_guarantee_their_bounds() -> None:
    sc = grid(size=3, pursuers=2, max_steps=50)
    value = game_value(sc)
    start = start_state(sc)
    # No team catches the equilibrium evader sooner than the lower bound on average...
    teams = [
        uniform_table(sc, 2),
        joint_policy_table(sc, load_or_solve(sc, use_cache=False).policy),
        joint_policy_table(sc, minimax_bounds(sc).policy),
    ]
    for table in teams:
        caught = evaluate_tables(sc, table, value.evader).values[start]
        assert caught >= value.lower - 1e-9
    # ...and the team's bound is its exact worst case, no worse than those teams'.
    np.testing.assert_allclose(value.team.sum(axis=1), 1.0, atol=1e-5)
    assert team_worst_case(sc, value.team)[start] == pytest.approx(value.upper, abs=1e-9)
    assert evader_worst_case(sc, value.evader)[start] == pytest.approx(value.lower, abs=1e-9)
    with pytest.raises(ValueError, match="5 moves, the scenario has 4"):
        evader_worst_case(sc, scripted_evader_table(sc, "static"))  # it stays: a fifth move
    for table in teams:
        assert value.upper <= evader_best_response(sc, table).value_from_start + 1e-9


def test_cli_prints_the_bracket(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    value = game_value(grid(size=3, pursuers=2, max_steps=50))
    for cached in ("", " (cached)"):  # solved, then read from the cache
        assert main([*SMALL, "--game-value", "--cache-dir", str(tmp_path)]) == 0
        out = capsys.readouterr().out
        assert f"at least {value.lower:.6f}" in out and f"at most {value.upper:.6f}" in out
        assert out.rstrip().splitlines()[-2].endswith(f" s{cached}")
    assert main([*SMALL, "--game-value", "--best-response", "evader"]) == 2
    assert "separate questions" in capsys.readouterr().err
    assert main([*SMALL, "--game-value", "--set", "collisions.mode=terminate"]) == 2
    assert "collisions end the episode" in capsys.readouterr().err
    assert main(["--scenario", "grid_vs", "--game-value", "--set", "size=7"]) == 2
    assert "GiB" in capsys.readouterr().err


def test_cached_value_is_the_solved_one(tmp_path: Path) -> None:
    sc = grid(size=3, pursuers=2, max_steps=50)
    assert cached_value(sc, tmp_path) is None
    solved = load_or_solve_value(sc, tmp_path)
    (path,) = tmp_path.glob("*-value.npz")
    for other in (dataclasses.replace(sc, evader="flee"), grid_vs_twin(sc)):
        cached = cached_value(other, tmp_path)  # one game, one value
        assert cached.cached and (cached.lower, cached.upper) == (solved.lower, solved.upper)
        np.testing.assert_array_equal(cached.evader, solved.evader)
    assert cached_value(grid(size=3, pursuers=2, max_steps=40), tmp_path) is None
    path.write_bytes(b"not a zip file")  # damaged: solved again, and the file replaced
    again = load_or_solve_value(sc, tmp_path)
    assert not again.cached and again.lower == solved.lower
    assert cached_value(sc, tmp_path).cached


def grid_vs_twin(sc: Scenario) -> Scenario:
    """The same game with the learned evader and self-play's rewards."""
    return dataclasses.replace(sc, evader="learned", rewards=Rewards(step=-2.0, capture=5.0))


def test_equilibrium_evader_plays_as_its_table_says(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from a2cm_phys.analysis.evaluation import play
    from a2cm_phys.analysis.policies import matchup

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # where the named policy caches it

    sc = grid(size=3, pursuers=2, max_steps=50)
    value = game_value(sc)
    oracle = joint_policy_table(sc, load_or_solve(sc, use_cache=False).policy)
    exact = evaluate_tables(sc, oracle, value.evader).values[start_state(sc)]
    game = matchup(dataclasses.replace(sc, evader="learned"), "oracle", "equilibrium")
    lengths = play(game.scenario, game.pursuers, 4000, 16, 0, game.evader).lengths
    assert np.ptp(lengths) > 0  # mixed: sampled, not its most probable move
    se = lengths.std() / np.sqrt(len(lengths))
    assert abs(lengths.mean() - exact) < 4 * se


def test_cli_best_response_to_the_equilibrium_evader(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from a2cm_phys.commands.evaluate import main as evaluate

    value = game_value(grid(size=3, pursuers=2, max_steps=50))
    argv = [*SMALL, "--best-response", "pursuers", "--evader", "equilibrium"]
    assert main([*argv, "--cache-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "equilibrium evader" in out and f"{value.lower:.3f}" in out
    argv = ["--scenario", "phys_vs", "--pursuers", "pursuit", "--evader", "equilibrium"]
    assert evaluate(argv) == 2
    assert "grids only" in capsys.readouterr().err
