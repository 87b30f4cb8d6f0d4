"""Grid-mode speed: our parallel env vs PettingZoo's SISL pursuit_v5 (5×5, 3 pursuers,
1 evader, random actions) in one process, and the batched core at B = 4096 on one core.

    python benchmarks/bench_grid.py [--repeats 7]

Needs the bench extra (PettingZoo's pursuit: ``pip install pettingzoo pygame scipy``).
Figures are medians over interleaved repeats; ratios compare runs of the same process.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import warnings

import numpy as np

from a2cm_phys import make_env
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.grid import GridCore


def steps_per_second_parallel(env, steps: int, seed: int) -> float:
    """Random-action steps/s of a PettingZoo-style parallel env, resetting when done."""
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, 4, (steps, 8))
    env.reset(seed=seed)
    agents = list(env.possible_agents)
    start = time.perf_counter()
    for t in range(steps):
        if not env.agents:
            env.reset()
        row = actions[t]
        env.step({a: int(row[i]) for i, a in enumerate(agents)})
    return steps / (time.perf_counter() - start)


def steps_per_second_core(batch: int, steps: int, seed: int) -> float:
    """Env-steps/s of the batched grid core with random actions and auto-reset."""
    core = GridCore(load_scenario("grid"), batch)
    rng = np.random.default_rng(seed)
    core.reset(np.arange(batch), rng.integers(0, 2**63, batch).astype(np.uint64))
    start = time.perf_counter()
    for _ in range(steps):
        out = core.step(rng.integers(0, 4, (batch, 3)))
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
    return batch * steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--steps", type=int, default=20_000)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    warnings.filterwarnings("ignore")
    from pettingzoo.sisl import pursuit_v5

    theirs_env = pursuit_v5.parallel_env(
        x_size=5, y_size=5, n_pursuers=3, n_evaders=1, n_catch=1, max_cycles=1000
    )
    ours_env = make_env("grid")
    ours, theirs, core = [], [], []
    for r in range(args.repeats):
        ours.append(steps_per_second_parallel(ours_env, args.steps, r))
        theirs.append(steps_per_second_parallel(theirs_env, args.steps // 10, r))
        core.append(steps_per_second_core(4096, 500, r))
    med = statistics.median
    ratios = [o / t for o, t in zip(ours, theirs, strict=True)]
    print(f"command: python benchmarks/bench_grid.py --repeats {args.repeats} --steps {args.steps}")
    print("| what | median | ratio |")
    print("|---|---|---|")
    print(
        f"| PettingZoo pursuit_v5 (5x5, 3 pursuers, 1 evader) | {med(theirs):,.0f} steps/s | 1.0 |"
    )
    print(f"| a2cm_phys make_env('grid') | {med(ours):,.0f} steps/s | {med(ratios):.1f}x |")
    print(
        f"| a2cm_phys GridCore, B=4096, one core | {med(core) / 1e6:.2f} M env-steps/s |"
        f" {med(core) / med(theirs):,.0f}x |"
    )


if __name__ == "__main__":
    main()
