"""The exact oracle as the arena grows (issue 35): the symmetric solver on ``grid``.

    python benchmarks/bench_oracle_scale.py [--sizes 5,6,7,8,9,10] [--pursuers 3]
        [--scenario grid] [--out benchmarks/results/oracle_scale.jsonl]

For every arena size, solves the scenario (``size`` and ``pursuers`` overridden) with
:func:`a2cm_phys.solve.symmetric.solve_symmetric`, each size in its own subprocess so that
its peak resident set size (``ru_maxrss``, imports included) is its own, and prints:
canonical states, greedy and evaluation sweeps, seconds, peak RSS and the solver's memory
estimate (GiB), and the expected capture steps from the default start. Rows go to
``--out`` as JSON lines as sizes finish; a rerun skips the (scenario, size, pursuers)
already there. Times depend on what else the machine runs.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
from pathlib import Path

COLUMNS = ("size", "states", "canonical", "greedy", "evaluation", "seconds", "peak_gib")


def solve_one(scenario: str, size: int, pursuers: int) -> dict:
    """Solve one size in this process and return its row."""
    from a2cm_phys.config import load_scenario
    from a2cm_phys.solve.symmetric import solve_symmetric

    sc = load_scenario(scenario, {"size": size, "pursuers": pursuers})
    result = solve_symmetric(sc, progress=True)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB
    return {
        "scenario": scenario,
        "size": size,
        "pursuers": pursuers,
        "states": sc.size ** (2 * (pursuers + 1)),
        "canonical": result.index.n,
        "greedy": result.greedy_sweeps,
        "evaluation": result.evaluation_sweeps,
        "residual": result.residual,
        "seconds": round(result.seconds, 2),
        "peak_gib": round(peak / 2**30, 3),
        "estimate_gib": round(result.memory_estimate / 2**30, 3),
        "start_value": result.start_value,
        "capture_steps": result.start_steps,
    }


def done_rows(path: Path) -> list[dict]:
    """The rows already in ``path`` (none if it does not exist)."""
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def show(row: dict) -> str:
    """One table line."""
    cells = [f"{row[k]:,}" if isinstance(row[k], int) else f"{row[k]}" for k in COLUMNS]
    return "  ".join(f"{c:>12}" for c in cells) + f"  {row['capture_steps']:.6f}"


def main() -> None:
    """Parse the options, solve the missing sizes (one subprocess each), print the table."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="5,6,7,8,9,10", help="arena sizes, comma-separated")
    p.add_argument("--pursuers", type=int, default=3, help="number of pursuers")
    p.add_argument("--scenario", default="grid", help="scenario name")
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/oracle_scale.jsonl"))
    p.add_argument("--one", type=int, help=argparse.SUPPRESS)  # the child: solve one size
    args = p.parse_args()
    if args.one is not None:
        print(json.dumps(solve_one(args.scenario, args.one, args.pursuers)))
        return
    rows = done_rows(args.out)
    print("  ".join(f"{c:>12}" for c in COLUMNS) + "  capture_steps")
    for size in (int(s) for s in args.sizes.split(",")):
        key = (args.scenario, size, args.pursuers)
        row = next((r for r in rows if (r["scenario"], r["size"], r["pursuers"]) == key), None)
        if row is None:
            child = [sys.executable, __file__, "--one", str(size)]
            child += ["--pursuers", str(args.pursuers), "--scenario", args.scenario]
            out = subprocess.run(child, check=True, stdout=subprocess.PIPE, text=True).stdout
            row = json.loads(out.strip().splitlines()[-1])
            args.out.parent.mkdir(parents=True, exist_ok=True)
            with args.out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            rows.append(row)
        print(show(row), flush=True)


if __name__ == "__main__":
    main()
