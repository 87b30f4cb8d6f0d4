"""Differential drive's cost: a step of ``PhysicsCore`` on ``phys_diff`` (differential-drive
pursuers, substep-major stepping with every pursuer's servo, torque, rail and velocity
written between substeps) against one on ``phys_cont`` (holonomic), both B = 64 games in
one process, random commands in ``[-1, 1]²``, finished games restarted; then the same
pair with discrete moves (``phys`` against ``phys_diff`` with ``control = "discrete"``,
dt = 1 s in 10 substeps).

    python benchmarks/bench_drive.py [--repeats 7] [--steps 400] [--batch 64]

The continuous pair is the same game but for the drive (5 × 5, dt = 0.1 s, 2 substeps).
Figures are medians over interleaved repeats; a ratio is the median of the repeats'
ratios (each repeat times both back to back, so a load that moves between runs cancels).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from a2cm_phys.config import Scenario, load_scenario
from a2cm_phys.envs.physics import PhysicsCore

DISCRETE = {"control": "discrete", "physics.dt": 1.0, "physics.substeps": 10}
PAIRS = {  # label: (holonomic, differential)
    "continuous": (load_scenario("phys_cont"), load_scenario("phys_diff")),
    "discrete": (load_scenario("phys"), load_scenario("phys_diff", DISCRETE)),
}


def step_seconds(core: PhysicsCore, steps: int, seed: int) -> float:
    """Seconds per step of ``core`` (all its games) with random commands or moves,
    restarting games that end; observations are read each step, as a rollout does."""
    sc: Scenario = core.scenario
    rng = np.random.default_rng(seed)
    b, n = core.num_envs, sc.pursuers
    if sc.continuous:
        actions = rng.uniform(-1.0, 1.0, (steps, b, n, 2))
    else:
        actions = rng.integers(0, sc.actions, (steps, b, n))
    core.reset(np.arange(b), rng.integers(0, 2**63, b).astype(np.uint64))
    start = time.perf_counter()
    for k in range(steps):
        out = core.step(actions[k])
        core.observe()
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
    return (time.perf_counter() - start) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--batch", type=int, default=64)
    args = parser.parse_args()
    print(
        f"command: python benchmarks/bench_drive.py --repeats {args.repeats} "
        f"--steps {args.steps} --batch {args.batch}\n"
    )
    print("| control | scenario | drive | ms per step (B games) | env-steps/s | ratio |")
    print("|---|---|---|---|---|---|")
    med = statistics.median
    for label, pair in PAIRS.items():
        cores = [PhysicsCore(sc, args.batch) for sc in pair]
        steps = args.steps if label == "continuous" else max(args.steps // 4, 1)
        for core in cores:
            step_seconds(core, 20, 0)  # warm up
        times: list[list[float]] = [[], []]
        for r in range(args.repeats):
            for core, kept in zip(cores, times, strict=True):
                kept.append(step_seconds(core, steps, r))
        ratio = med(d / h for h, d in zip(*times, strict=True))
        for core, kept, scale in zip(cores, times, (1.0, ratio), strict=True):
            sc, t = core.scenario, med(kept)
            print(
                f"| {label} | {sc.name} | {sc.physics.drive} | {1e3 * t:.3f} | "
                f"{args.batch / t:,.0f} | {scale:.2f}x |"
            )


if __name__ == "__main__":
    main()
