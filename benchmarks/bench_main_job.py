"""The main job's wall time, as a user types it (issue 12: at most 30 s with its log).

    python benchmarks/bench_main_job.py [--repeats 5] [--peer /path/to/other/checkout]
        [--scenario grid_collision]

Runs ``python -m a2cm_phys.train --scenario grid_collision --no-progress`` (or another
scenario as typed, e.g. ``--scenario phys_cont``) in a fresh
temporary folder (interpreter start-up, imports, training, the MCAP log and the summary
included) ``--repeats`` times and prints the median wall time. With ``--peer`` the same
command runs from another checkout (``PYTHONPATH``), alternating with this one, and the
ratio of the medians is printed: on a shared machine the ratio is the figure to trust.
``--record`` appends the pairs to ``benchmarks/results/main_job.jsonl`` (the peer's commit
with them), from which the report's claims on the speed targets are made.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
RECORDS = HERE / "benchmarks" / "results" / "main_job.jsonl"


def commit(checkout: Path) -> str:
    """The checkout's commit (``unknown`` outside git, e.g. a ``git archive`` copy)."""
    done = subprocess.run(
        ["git", "-C", str(checkout), "rev-parse", "--short", "HEAD"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    return done.stdout.strip() or "unknown"


def wall_time(checkout: Path, scenario: str) -> float:
    """Seconds of one run of ``scenario`` as typed from ``checkout``, in a fresh folder."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    command = [sys.executable, "-m", "a2cm_phys.train", "--scenario", scenario, "--no-progress"]
    with tempfile.TemporaryDirectory() as folder:
        t0 = time.perf_counter()
        subprocess.run(command, cwd=folder, env=env, check=True, stdout=subprocess.DEVNULL)
        return time.perf_counter() - t0


def main() -> None:
    """Alternate the checkouts, then print each one's times, median and the ratio."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--peer", type=Path, help="another checkout to time beside this one")
    p.add_argument("--scenario", default="grid_collision", help="the job: train this scenario")
    p.add_argument(
        "--peer-commit", help="the peer's commit, if its checkout is not a git work tree"
    )
    p.add_argument("--record", action="store_true", help=f"append the pairs to {RECORDS}")
    args = p.parse_args()
    checkouts = {"this": HERE, **({"peer": args.peer.resolve()} if args.peer else {})}
    times: dict[str, list[float]] = {name: [] for name in checkouts}
    for _ in range(args.repeats):
        for name, checkout in checkouts.items():
            times[name].append(wall_time(checkout, args.scenario))
    for name, values in times.items():
        each = ", ".join(f"{v:.1f}" for v in values)
        print(f"{name} ({checkouts[name]}): median {statistics.median(values):.2f} s ({each})")
    if args.peer:
        ratio = statistics.median(times["this"]) / statistics.median(times["peer"])
        print(f"this / peer: {ratio:.3f}")
    if args.record and args.peer:
        row = {
            "scenario": args.scenario,
            "this": commit(HERE),
            "peer": args.peer_commit or commit(args.peer),
            "pairs": [list(pair) for pair in zip(times["this"], times["peer"], strict=True)],
            "date": time.strftime("%Y-%m-%d"),
        }
        with RECORDS.open("a") as out:
            out.write(json.dumps(row) + "\n")
        print(f"recorded in {RECORDS}")


if __name__ == "__main__":
    main()
