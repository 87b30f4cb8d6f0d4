"""Random starts (issue 45): A2CM and A2C trained from random starts, against the exact
optimum over the start distribution, beside the main job as the peer for wall time; then
the generalisation table (fixed-trained teams from random starts, and the reverse).

    python benchmarks/bench_random_starts.py [--seeds 0-4] [--episodes 5000] [--out FILE]
    python benchmarks/bench_random_starts.py --tables benchmarks/results/random_starts.json

Each run is the shipped ``train`` command with its defaults (no option changed), timed as
a whole process; each evaluation is ``evaluate RUN --greedy`` over ``--episodes`` episodes
(seed 0), whose reference is the oracle's exact optimum over the scenario's starts. Prints
a Markdown table of medians over seeds and writes every run's figures as JSON.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TRAINED = ("grid_random", "grid_collision_random", "grid_collision")
ALGOS = ("a2cm", "a2c")
CROSS = {"grid_collision": "grid_collision_random", "grid_collision_random": "grid_collision"}


def seeds(text: str) -> list[int]:
    """``0-4`` or ``0,2,5`` as a list of seeds."""
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def train(scenario: str, algo: str, seed: int, run_dir: Path) -> float:
    """Train with the shipped defaults; the wall time of the whole process."""
    cmd = [sys.executable, "-m", "a2cm_phys.train", "--scenario", scenario, "--algo", algo]
    cmd += ["--seed", str(seed), "--run-dir", str(run_dir), "--no-progress"]
    started = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - started


def evaluate(run_dir: Path, episodes: int, scenario: str | None = None) -> dict:
    """``evaluate RUN --greedy --json`` (on another scenario if given)."""
    cmd = [sys.executable, "-m", "a2cm_phys.evaluate", str(run_dir), "--greedy", "--json"]
    cmd += ["--episodes", str(episodes), "--no-progress"]
    if scenario:
        cmd += ["--scenario", scenario]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    doc = json.loads(out)
    return {
        "steps": doc["capture_steps"]["mean"]["value"],
        "capture_rate": doc["capture_rate"]["value"],
        "collisions": doc["collisions_per_episode"]["value"],
        "optimum": doc["reference"]["capture_steps"],
    }


def main() -> None:
    """Train, evaluate, print the tables, write the JSON."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--episodes", type=int, default=5000)
    ap.add_argument("--out", default="benchmarks/results/random_starts.json")
    ap.add_argument(
        "--tables", metavar="FILE", help="only print the tables of a JSON written before"
    )
    args = ap.parse_args()
    if args.tables:
        print_tables(json.loads(Path(args.tables).read_text()))
        return
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in TRAINED:
            for algo in ALGOS:
                for seed in seeds(args.seeds):
                    run = Path(tmp) / f"{scenario}-{algo}-s{seed}"
                    row = {"scenario": scenario, "algo": algo, "seed": seed}
                    row["wall_s"] = train(scenario, algo, seed, run)
                    row["own"] = evaluate(run, args.episodes)
                    row["cross_scenario"] = CROSS.get(scenario)
                    if row["cross_scenario"]:
                        row["cross"] = evaluate(run, args.episodes, row["cross_scenario"])
                    rows.append(row)
                    print(json.dumps(row), file=sys.stderr, flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")
    print_tables(rows)


def print_tables(rows: list[dict]) -> None:
    """The two Markdown tables: learning against the optimum, and generalisation. Steps are
    the mean over captured episodes (a collision that ends an episode is not a capture)."""
    main_job = [r for r in rows if r["scenario"] == "grid_collision" and r["algo"] == "a2cm"]
    peer = statistics.median(r["wall_s"] for r in main_job)  # the main job, as typed
    print(
        "| trained on | algo | greedy steps (median) | optimum | ratio | captured (min)"
        " | collisions/ep (max) | wall s (median) | × main job |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for scenario in TRAINED:
        for algo in ALGOS:
            mine = [r for r in rows if r["scenario"] == scenario and r["algo"] == algo]
            steps = statistics.median(r["own"]["steps"] for r in mine)
            opt = mine[0]["own"]["optimum"]
            wall = statistics.median(r["wall_s"] for r in mine)
            coll = max(r["own"]["collisions"] for r in mine)
            cap = min(r["own"]["capture_rate"] for r in mine)
            print(
                f"| `{scenario}` | {algo} | {steps:.3f} | {opt:.3f} | {steps / opt:.3f} |"
                f" {cap:.3f} | {coll:.3f} | {wall:.1f} | {wall / peer:.2f} |"
            )
    print(
        "\n| trained on | evaluated on | algo | greedy steps (median) | optimum | ratio |"
        " captured (min) | collisions/ep (max) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for scenario, other in CROSS.items():
        for algo in ALGOS:
            mine = [r for r in rows if r["scenario"] == scenario and r["algo"] == algo]
            steps = statistics.median(r["cross"]["steps"] for r in mine)
            opt = mine[0]["cross"]["optimum"]
            coll = max(r["cross"]["collisions"] for r in mine)
            cap = min(r["cross"]["capture_rate"] for r in mine)
            print(
                f"| `{scenario}` | `{other}` | {algo} | {steps:.3f} | {opt:.3f} |"
                f" {steps / opt:.3f} | {cap:.3f} | {coll:.3f} |"
            )


if __name__ == "__main__":
    main()
