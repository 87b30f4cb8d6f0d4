"""Physics-mode speed: one game through ``make_env("phys")`` vs mpe2's ``simple_tag_v3``
(3 adversaries chase 1 good agent, no obstacles; also a 2-D physics toy) in one process,
random actions, resetting when an episode ends; plus the batched physics core at B = 64
(``--batch``), in one process and split across 2 worker processes (``ProcessCore``).

    python benchmarks/bench_physics.py [--repeats 5] [--steps 5000] [--batch-steps 600]
                                       [--batch 64]

Needs the bench extra (``pip install mpe2``). Figures are medians over interleaved repeats;
ratios compare runs of the same repeat. Nothing is pinned to a core: the worker figure
needs both.
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
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.workers import ProcessCore

WORKERS = 2


def steps_per_second_parallel(env, steps: int, seed: int, n_actions: int) -> float:
    """Random-action steps/s of a PettingZoo-style parallel env, resetting when done."""
    rng = np.random.default_rng(seed)
    agents = list(env.possible_agents)
    actions = rng.integers(0, n_actions, (steps, len(agents)))
    env.reset(seed=seed)
    start = time.perf_counter()
    for t in range(steps):
        if not env.agents:
            env.reset()
        row = actions[t]
        env.step({a: int(row[i]) for i, a in enumerate(agents) if a in env.agents})
    return steps / (time.perf_counter() - start)


def steps_per_second_core(core, steps: int, seed: int) -> float:
    """Env-steps/s of a batched core with random actions, restarting finished games."""
    rng = np.random.default_rng(seed)
    b, n = core.num_envs, core.scenario.pursuers
    core.reset(np.arange(b), rng.integers(0, 2**63, b).astype(np.uint64))
    start = time.perf_counter()
    for _ in range(steps):
        out = core.step(rng.integers(0, 4, (b, n)))
        core.observe()
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
    return b * steps / (time.perf_counter() - start)


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux ``/proc``; else NaN)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--steps", type=int, default=5_000, help="steps of the single games")
    parser.add_argument("--batch-steps", type=int, default=600, help="steps of the batched cores")
    parser.add_argument("--batch", type=int, default=64, help="games B of the batched cores")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    from mpe2 import simple_tag_v3

    theirs_env = simple_tag_v3.parallel_env(
        num_good=1, num_adversaries=3, num_obstacles=0, max_cycles=1000
    )
    ours_env = make_env("phys")
    scenario = load_scenario("phys")
    single = PhysicsCore(scenario, args.batch)
    split = ProcessCore(scenario, args.batch, WORKERS)
    core_steps = args.batch_steps
    ours, theirs, batched, workers, per_cpu = [], [], [], [], []
    try:
        for r in range(args.repeats):
            ours.append(steps_per_second_parallel(ours_env, args.steps, r, scenario.actions))
            theirs.append(steps_per_second_parallel(theirs_env, args.steps, r, 5))
            batched.append(steps_per_second_core(single, core_steps, r))
            used = [cpu_seconds(p.pid) for p in split._procs]
            start = time.perf_counter()
            workers.append(steps_per_second_core(split, core_steps, r))
            wall = time.perf_counter() - start
            used = [cpu_seconds(p.pid) - u for p, u in zip(split._procs, used, strict=True)]
            per_cpu.append(workers[-1] * wall / sum(used))  # env-steps per worker CPU-second
    finally:
        split.close()
    med = statistics.median
    ratio = med(o / t for o, t in zip(ours, theirs, strict=True))
    print(
        "command: python benchmarks/bench_physics.py "
        f"--repeats {args.repeats} --steps {args.steps} --batch-steps {args.batch_steps} "
        f"--batch {args.batch}"
    )
    print(f"(physics.substeps = {scenario.physics.substeps}; medians of {args.repeats} repeats)\n")
    print("| what | median | ratio |")
    print("|---|---|---|")
    mpe = "mpe2 simple_tag_v3 (3 adversaries, 1 good, no obstacles)"
    print(f"| {mpe} | {med(theirs):,.0f} steps/s | 1.0 |")
    print(f"| a2cm_phys make_env('phys'), one game | {med(ours):,.0f} steps/s | {ratio:.2f}x |")
    b = args.batch
    # The batched rows' ratios are to mpe2's one game, in the same repeat: a figure of
    # this machine's speed at the time, which moves by a quarter between runs.
    one = med(o / t for o, t in zip(batched, theirs, strict=True))
    two = med(o / t for o, t in zip(workers, theirs, strict=True))
    print(f"| PhysicsCore B={b}, one process | {med(batched):,.0f} env-steps/s | {one:.2f}x |")
    print(
        f"| ProcessCore B={b}, {WORKERS} workers | {med(workers):,.0f} env-steps/s | {two:.2f}x |"
    )
    print(
        f"\nProcessCore workers: {med(per_cpu):,.0f} env-steps per worker CPU-second "
        f"(x {WORKERS}: the most {WORKERS} free cores could give); load average now: "
        f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}"
    )


if __name__ == "__main__":
    main()
