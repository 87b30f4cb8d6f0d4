"""The grid game's value with mixed strategies, and what each evader gets against the oracle.

Brackets the value of ``grid_vs`` (both teams at their best; ``python -m a2cm_phys.oracle
--scenario grid_vs --game-value``, :mod:`a2cm_phys.solve.nash`) and puts beside it, all
exactly (``max_steps`` 1000):

- each evader's **worst case** (the team that knows its policy best-responds): the
  equilibrium evader's, the fleeing one's, the random one's and, with ``--runs``, the
  learned evaders' of those runs;
- each evader **against the oracle's team** (optimal against the random evader), the
  pairing of issue 14's evader target;
- the worst cases of the equilibrium team, the oracle's and the minimax team, and with
  ``--runs`` the learned pursuers'.

Usage: ``python benchmarks/bench_game_value.py [--runs RUN_DIR ...]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from a2cm_phys.config import load_scenario
from a2cm_phys.solve.best_response import evader_best_response, evaluate_tables
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.minimax import minimax_bounds
from a2cm_phys.solve.nash import evader_worst_case, game_value
from a2cm_phys.solve.tables import (
    joint_policy_table,
    model_table,
    scripted_evader_table,
    uniform_table,
)
from a2cm_phys.training.runs import load_trained_run


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", nargs="+", type=Path, default=[], metavar="RUN_DIR")
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    # the solvers take any evader's table: the scenario's own evader only names the rules
    game = load_scenario("grid_vs", {"evader": "random", "max_steps": 1000})
    t0 = time.perf_counter()
    value = game_value(game)
    print(
        f"game value: [{value.lower:.4f}, {value.upper:.4f}] (estimate"
        f" {value.estimate_from_start:.4f}; {value.sweeps} sweeps, {value.seconds:.0f} s)"
    )
    start = value.start
    oracle = joint_policy_table(game, load_or_solve(load_scenario("grid")).policy)
    evaders = {
        "equilibrium": value.evader,
        "flee": scripted_evader_table(game, "flee"),
        "random": uniform_table(game, 1),
    }
    for run in args.runs:
        evaders[f"learned {run}"] = model_table(game, load_trained_run(run).evader, 1)
    print("| evader | worst case (its best response) | share of the value | vs the oracle's team |")
    print("|---|---|---|---|")
    for name, table in evaders.items():
        worst = float(evader_worst_case(game, table)[start])
        against = float(evaluate_tables(game, oracle, table).values[start])
        print(f"| {name} | {worst:.3f} | {worst / value.lower:.3f} | {against:.3f} |")
    teams = {
        "oracle": oracle,
        "minimax": joint_policy_table(game, minimax_bounds(game).policy),
    }
    for run in args.runs:
        teams[f"learned {run}"] = model_table(game, load_trained_run(run).pursuers, game.pursuers)
    print(f"| team | worst case |\n|---|---|\n| equilibrium (correlated) | {value.upper:.3f} |")
    for name, table in teams.items():
        print(f"| {name} | {evader_best_response(game, table).value_from_start:.3f} |")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
