"""The range sensor's cost: a ``VectorEnv`` step (the physics step and every agent's
observation) with ``sensing.rays`` against the same scenario without them, B = 64 games in
one process, random commands, finished games restarted.

    python benchmarks/bench_rays.py [--repeats 7] [--steps 400] [--batch 64] [--rays 8]

The pairs: ``phys_cont_pomdp`` (holonomic, sensing radius 1.5 m) and ``phys_diff_obstacles``
with ``sensing.radius = 2`` and occlusion (differential drive, two obstacles), each without
rays and with ``--rays``. Figures are medians over interleaved repeats; a ratio is the
median of the repeats' ratios (each repeat times both back to back).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from a2cm_phys.config import load_scenario
from a2cm_phys.envs.vector import VectorEnv


def step_seconds(env: VectorEnv, steps: int, seed: int) -> float:
    """Seconds per ``env.step`` with random commands (the env restarts finished games)."""
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, (steps, env.num_envs, *env.action_shape))
    env.reset(seed)
    start = time.perf_counter()
    for k in range(steps):
        env.step(actions[k].astype(np.float32))
    return (time.perf_counter() - start) / steps


def main() -> None:
    """Time each pair and print the Markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--rays", type=int, default=8)
    args = parser.parse_args()
    pairs = {
        "phys_cont_pomdp": {},
        "phys_diff_obstacles": {"sensing.radius": 2.0, "sensing.occlusion": True},
    }
    print(
        f"command: python benchmarks/bench_rays.py --repeats {args.repeats} --steps "
        f"{args.steps} --batch {args.batch} --rays {args.rays}\n"
    )
    print("| scenario | rays | ms per step (B games) | ratio |")
    print("|---|---|---|---|")
    for name, base in pairs.items():
        envs = [
            VectorEnv(load_scenario(name, base), args.batch),
            VectorEnv(load_scenario(name, {**base, "sensing.rays": args.rays}), args.batch),
        ]
        for env in envs:
            step_seconds(env, 20, 0)  # warm up
        times: list[list[float]] = [[], []]
        for r in range(args.repeats):
            for env, kept in zip(envs, times, strict=True):
                kept.append(step_seconds(env, args.steps, r))
        ratio = statistics.median(w / wo for wo, w in zip(*times, strict=True))
        for env, kept, shown in zip(envs, times, ("1", f"{ratio:.3f}"), strict=True):
            rays = env.scenario.sensing.rays
            print(f"| {name} | {rays} | {1e3 * statistics.median(kept):.3f} | {shown} |")
        for env in envs:
            env.close()


if __name__ == "__main__":
    main()
