"""The exact solvers report their iterations and residual on stderr when asked (the oracle
command asks), and are silent by default (training calls them every few updates)."""

from __future__ import annotations

import re

import pytest

from a2cm_phys.commands.oracle import main
from a2cm_phys.config import load_scenario
from a2cm_phys.solve import minimax, nash
from a2cm_phys.solve.best_response import evader_best_response, pursuers_best_response
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.tables import joint_policy_table, uniform_table


@pytest.fixture(autouse=True)
def _lines_every_update(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "1e-9")
    monkeypatch.delenv("A2CM_PROGRESS", raising=False)


def _grid(**over: object):
    return load_scenario("grid", {"size": 3, "pursuers": 2, **over})


def test_value_iteration_reports_sweeps_and_residual_only_when_asked(capsys) -> None:
    sol = load_or_solve(_grid(), use_cache=False, progress=True)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "value iteration: started"
    sweeps = [line for line in err if re.match(r"value iteration: \d+ sweeps, ", line)]
    assert len(sweeps) >= 2
    assert all(re.search(r", residual [\d.e+-]+ \(tol 1e-10\)$", line) for line in sweeps)
    residual = f"residual {sol.meta['residual']:.1e} (tol 1e-10)"
    assert err[-1].startswith(f"value iteration: done, {sol.meta['sweeps'] - 1} sweeps, ")
    assert err[-1].endswith(residual)  # the last sweep's: below the tolerance
    load_or_solve(_grid(), use_cache=False)
    assert capsys.readouterr().err == ""


def test_best_responses_report_steps_and_bound_only_when_asked(capsys) -> None:
    sc = _grid(max_steps=40)
    team = joint_policy_table(sc, load_or_solve(sc, use_cache=False).policy)
    quiet = evader_best_response(sc, team)  # as training's exploitability calls it
    pursuers_best_response(sc, uniform_table(sc, 1))
    assert capsys.readouterr().err == ""
    loud = evader_best_response(sc, team, progress=True)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "best response: started (40 steps)"
    assert re.match(r"best response: 1/40 steps \(2%\), .+ steps/s, .+, bound [\d.e+-]+$", err[1])
    assert err[-1].startswith(f"best response: done, {loud.outcome.iterations}/40 steps")
    assert loud.value_from_start == quiet.value_from_start  # progress changes nothing


def test_minimax_and_game_value_report_each_phase(capsys) -> None:
    sc = _grid(max_steps=31)  # a game no other test solves: not in the solvers' caches
    bounds = minimax.minimax_bounds(sc, progress=True)
    value = nash.game_value(sc, progress=True)
    err = capsys.readouterr().err
    for phase in ("minimax upper", "minimax lower"):
        assert f"{phase}: started" in err and f"{phase}: done, " in err
    assert re.search(r"minimax upper: 1 steps, .*, [\d,]+ changed", err)
    assert re.search(r"Shapley: \d+ it, .*, sweep 1: moved [\d.e+-]+, gap [\d.e+-]+", err)
    assert "polish: done, 400/400 iterations (100%)" in err
    for side in ("evader", "team"):
        assert re.search(rf"{side} worst case: \d+ steps, .*, bound .+ \(tol 1e-06\)", err)
    assert minimax.minimax_bounds(sc, progress=True) is bounds  # cached: no second solve
    assert nash.game_value(sc) is value
    assert capsys.readouterr().err == ""


def test_the_oracle_command_shows_progress_unless_told_not_to(tmp_path, capsys) -> None:
    argv = ["--set", "size=3", "--set", "pursuers=2", "--no-cache"]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert "value iteration: started" in err and "value iteration: done" in err
    assert "value iteration" not in out and "expected steps to capture: 1.853516" in out
    assert main([*argv, "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "expected steps to capture: 1.853516" in out
