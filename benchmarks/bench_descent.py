"""Grid self-play with exploitability descent (issue 14's targets), measured exactly.

    python benchmarks/bench_descent.py [--seeds 0-4] [--jobs 2] [--logdir logs/bench-descent]
        [--set train.KEY=VALUE] [--set ...] [--label NAME]
    python benchmarks/bench_descent.py --runs RUN_DIR [RUN_DIR ...]

Trains ``grid_vs`` once per seed (``python -m a2cm_phys.train --scenario grid_vs --seed S
--preset descent`` with the ``--set`` options, no episode log; finished runs are reused,
unfinished ones resumed), then measures each
run's final policies with the exact solvers, on the scenario's own 1,000-step horizon:

- the pursuers' **worst case**: the value of the evader's exact best response to their
  sampled actors (``oracle --best-response evader --pursuers RUN``), beside the oracle's
  (the team optimal against the random evader: 10);
- the pursuers' expected capture time against the **random** evader, exactly, beside the
  optimum (2.939);
- the learned **evader** against the oracle's pursuers, exactly, beside the random and
  fleeing evaders against the same team, and against its own exact best response (the
  oracle solved against it: ``oracle --best-response pursuers --evader RUN``), beside the
  fleeing evader's (3.948) and the random one's (2.939).

A row per run, then medians over seeds with 95% percentile-bootstrap intervals. Wall times
are those of the training commands, ``--jobs`` at a time. ``--runs`` measures the given
``grid_vs`` runs (however trained) the same way and trains nothing.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from a2cm_phys.analysis.stats import STATISTICS, bootstrap_ci
from a2cm_phys.commands.sweep import parse_seeds
from a2cm_phys.config import Scenario, load_scenario
from a2cm_phys.solve.best_response import (
    evader_best_response,
    evaluate_tables,
    pursuers_best_response,
)
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.tables import (
    joint_policy_table,
    model_table,
    scripted_evader_table,
    uniform_table,
)
from a2cm_phys.training.runs import load_trained_run

PRESET = "descent"
"""The training preset of the runs (``config.PRESETS``); ``--set`` options win over it."""


def train(seed: int, run_dir: Path, assignments: list[str]) -> float:
    """Train one seed into ``run_dir`` (skipped if it finished); the wall time (s)."""
    summary = run_dir / "summary.json"
    if summary.exists() and json.loads(summary.read_text())["status"] == "done":
        return float(json.loads(summary.read_text())["wall_time_s"])
    command = [
        sys.executable, "-m", "a2cm_phys.train", "--scenario", "grid_vs", "--seed", str(seed),
        "--no-record", "--no-progress",
        *(["--resume", str(run_dir)] if (run_dir / "checkpoint.pt").exists()
          else ["--run-dir", str(run_dir), "--preset", PRESET,
                *[w for a in assignments for w in ("--set", a)]]),
    ]  # fmt: skip
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return float(json.loads(summary.read_text())["wall_time_s"])


def measure(run_dir: Path, oracle_table: np.ndarray, game: Scenario) -> dict[str, float]:
    """The exact figures of one run's final actors in ``game`` (the solvers' rules)."""
    run = load_trained_run(run_dir)
    pursuers = model_table(game, run.pursuers, game.pursuers)
    evader = model_table(game, run.evader, 1)
    worst = evader_best_response(game, pursuers)
    random = uniform_table(game, 1)
    return {
        "worst_case": worst.value_from_start,
        "worst_case_p_capture": worst.p_capture_from_start,
        "vs_random": float(evaluate_tables(game, pursuers, random).values[worst.start]),
        "evader_vs_oracle": float(evaluate_tables(game, oracle_table, evader).values[worst.start]),
        "evader_vs_best_response": pursuers_best_response(game, evader).value_from_start,
    }


def median_ci(values: list[float]) -> str:
    """``median [low, high]`` of per-seed values (bootstrap over seeds)."""
    low, high = bootstrap_ci(np.asarray(values), STATISTICS["median"])
    return f"{np.median(values):.3f} [{low:.3f}, {high:.3f}]"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--logdir", default="logs/bench-descent")
    p.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="one pair per flag"
    )
    p.add_argument("--label", default="descent")
    p.add_argument("--runs", nargs="+", type=Path, metavar="RUN_DIR", help="measure these")
    p.add_argument("--max-steps", type=int, default=1000, help="the horizon of every exact value")
    args = p.parse_args()
    assignments = args.set
    if args.runs:
        run_dirs = args.runs
        names = [str(r) for r in run_dirs]
        walls = [json.loads((r / "summary.json").read_text())["wall_time_s"] for r in run_dirs]
        command = "--runs " + " ".join(names)
    else:
        seeds = parse_seeds(args.seeds)
        root = Path(args.logdir) / args.label
        root.mkdir(parents=True, exist_ok=True)
        run_dirs, names = [root / f"s{s}" for s in seeds], [str(s) for s in seeds]
        t0 = time.perf_counter()
        with ThreadPoolExecutor(args.jobs) as pool:
            walls = list(pool.map(lambda s: train(s, root / f"s{s}", assignments), seeds))
        took = time.perf_counter() - t0
        print(f"trained {len(seeds)} runs in {took:.0f} s ({args.jobs} at a time)")
        command = f"--seeds {args.seeds}" + "".join(f" --set {a}" for a in assignments)
    if args.max_steps != 1000:
        command += f" --max-steps {args.max_steps}"

    # the solvers take any evader's table: the scenario's own evader only names the rules
    game = load_scenario("grid_vs", {"evader": "random", "max_steps": args.max_steps})
    oracle = joint_policy_table(game, load_or_solve(load_scenario("grid")).policy)
    start = evader_best_response(game, oracle)
    reference = {
        "oracle worst case": start.value_from_start,
        "random evader vs oracle": float(
            evaluate_tables(game, oracle, uniform_table(game, 1)).values[start.start]
        ),
        "fleeing evader vs oracle": float(
            evaluate_tables(game, oracle, scripted_evader_table(game, "flee")).values[start.start]
        ),
        "fleeing evader vs its best response": pursuers_best_response(
            game, scripted_evader_table(game, "flee")
        ).value_from_start,
    }
    rows = [measure(r, oracle, game) for r in run_dirs]
    print(f"command: python benchmarks/bench_descent.py {command}")
    print("references: " + ", ".join(f"{k} {v:.3f}" for k, v in reference.items()))
    print(f"\n| run | worst case (exact) | P(capture) within {args.max_steps:,} |"
          " vs random evader (exact) |"
          " learned evader vs oracle (exact) | learned evader vs its best response (exact) |"
          " wall (s) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name, row, wall in zip(names, rows, walls, strict=True):
        print(
            f"| {name} | {row['worst_case']:.3f} | {row['worst_case_p_capture']:.6f} |"
            f" {row['vs_random']:.3f} | {row['evader_vs_oracle']:.3f} |"
            f" {row['evader_vs_best_response']:.3f} | {wall:.0f} |"
        )
    cols = (
        "worst_case",
        "worst_case_p_capture",
        "vs_random",
        "evader_vs_oracle",
        "evader_vs_best_response",
    )
    print(
        "| median [95% CI] | "
        + " | ".join(median_ci([r[c] for r in rows]) for c in cols)
        + f" | {np.median(walls):.0f} |"
    )


if __name__ == "__main__":
    main()
