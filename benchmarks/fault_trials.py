"""The run log's invariant under random SIGKILLs, at scale (issue 29): more trials than CI
runs, of grid and physics runs, each killed several times at random instants and resumed.

    python benchmarks/fault_trials.py --trials 10 --kills 5 --scenario grid_collision
    python benchmarks/fault_trials.py --trials 4 --kills 4 --scenario phys_collision --updates 400

Prints one row per trial: the checkpoint's and the log's episode counts after each kill,
then the summary's count, the log's and how many trajectories ``replay --verify``
re-simulated, and any problem (none expected). The harness is ``tests/faults.py``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from faults import kill_trial


def main() -> int:
    """Run the trials and print the table; exit 1 if any broke the invariant."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--kills", type=int, default=5)
    p.add_argument("--scenario", default="grid_collision")
    p.add_argument("--updates", type=int, default=4000)
    p.add_argument("--checkpoint-every", type=int, default=3)
    p.add_argument("--window", type=float, default=2.0, help="seconds a kill may wait")
    p.add_argument("--seed", type=int, default=0, help="first trial's seed")
    args = p.parse_args()
    print("| trial | (checkpoint, log) episodes after each kill | summary | log | verified |"
          " problems |\n|---:|---|---:|---:|---:|---|")  # fmt: skip
    broken = 0
    started = time.perf_counter()
    for i in range(args.trials):
        with tempfile.TemporaryDirectory() as tmp:
            trial = kill_trial(Path(tmp) / "run", args.seed + i, args.kills,
                               updates=args.updates, checkpoint_every=args.checkpoint_every,
                               scenario=args.scenario, window=args.window)  # fmt: skip
        kills = ", ".join(f"({a:,}, {b:,})" for a, b in trial.after_kill)
        problems = "; ".join(trial.problems) or "none"
        broken += bool(trial.problems)
        print(f"| {args.seed + i} | {kills} | {trial.summary_episodes:,} | {trial.log_episodes:,}"
              f" | {trial.verified:,} | {problems} |", flush=True)  # fmt: skip
    print(f"\n{args.trials} trials of {args.scenario}, {args.kills} kills each:"
          f" {broken} broke the invariant ({time.perf_counter() - started:.0f} s)")  # fmt: skip
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
