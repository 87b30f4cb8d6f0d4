"""``oracle`` takes the names ``evaluate`` takes, meaning the same policies (``oracle`` on a
scenario with a learned evader: the team optimal against the random evader); the one name
without a table says why in one line; ``--help`` is quick and says every default."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from a2cm_phys.analysis.names import PURSUER_POLICIES, PURSUER_TABLES, policy_names
from a2cm_phys.analysis.policies import OraclePolicy, grid_twin, pursuit_policy
from a2cm_phys.analysis.sources import pursuer_source
from a2cm_phys.commands import oracle
from a2cm_phys.config import load_scenario
from a2cm_phys.solve.best_response import TOLERANCE
from a2cm_phys.solve.tables import joint_observations, valid_states

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--set", "size=3", "--set", "pursuers=2", "--set", "max_steps=60", "--no-progress"]


def test_oracle_takes_every_pursuer_name_evaluate_takes() -> None:
    assert set(PURSUER_POLICIES) - set(PURSUER_TABLES) == {"qmdp", "search"}
    assert set(policy_names("evader")) - set(policy_names("evader", "tabled")) == {"best-response"}


def test_oracle_on_a_learned_evader_is_evaluates_team(tmp_path, capsys) -> None:
    """``--scenario grid_vs --pursuers oracle``: the team optimal against the random evader,
    the same table as evaluate's oracle policy plays and as on the scenario with the random
    evader."""
    sc = load_scenario("grid_vs", {"size": 3, "pursuers": 2, "max_steps": 60})
    table = pursuer_source(sc, "oracle", tmp_path).table
    played = OraclePolicy(grid_twin(sc), tmp_path).act(joint_observations(sc))
    valid = valid_states(sc)
    np.testing.assert_array_equal(table.argmax(-1)[valid], played[valid])

    def worst_case(scenario: str) -> str:
        argv = ["--scenario", scenario, *SMALL, "--cache-dir", str(tmp_path)]
        assert oracle.main([*argv, "--best-response", "evader", "--pursuers", "oracle"]) == 0
        out = capsys.readouterr().out
        assert "the oracle's policy (optimal against the random evader)" in out
        return next(line for line in out.splitlines() if "worst-case" in line)

    assert worst_case("grid_vs") == worst_case("grid")


def test_pursuit_is_a_table_of_the_rule_evaluate_plays(tmp_path, capsys) -> None:
    sc = load_scenario("grid", {"size": 3, "pursuers": 2})
    table = pursuer_source(sc, "pursuit").table
    played = pursuit_policy(sc)(joint_observations(sc), np.random.default_rng(0))
    np.testing.assert_array_equal(table.argmax(-1), played)
    assert np.all(table.max(-1) == 1.0)
    argv = ["--scenario", "grid_vs", *SMALL, "--best-response", "evader", "--pursuers", "pursuit"]
    assert oracle.main(argv) == 0
    assert "pursuers: pursuit (each pursuer straight at the evader" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--scenario", "grid_vs", "--best-response", "pursuers", "--evader", "best-response"],
            "--evader best-response: the best-response evader is solved against the pursuers",
        ),
        (
            ["--best-response", "pursuers", "--evader", "best-response"],  # no scenario given
            "ask for it with --best-response evader --pursuers P",
        ),
        (
            ["--scenario", "phys", "--best-response", "evader", "--pursuers", "pursuit"],
            "grids only",
        ),
    ],
)
def test_a_name_without_a_table_says_why_in_one_line(argv, message, capsys) -> None:
    assert oracle.main([*argv, "--no-cache", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and message in err


def test_help_names_every_default_and_is_quick() -> None:
    assert oracle.TOLERANCE == TOLERANCE
    parser = oracle.build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        assert action.help, action.dest
        if action.default is None:
            assert "default" in action.help, action.dest
    code = "import sys; import a2cm_phys.commands.oracle; print(sorted(sys.modules))"
    modules = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    assert "'torch'" not in modules and "a2cm_phys.solve" not in modules
