"""Continuous-control speed (issue 13): one game through ``make_env("phys_cont")`` vs mpe2's
``simple_tag_v3`` with ``continuous_actions=True`` (3 adversaries, 1 good agent, no
obstacles), and the batched continuous core split across 2 processes at B = 64
(``ProcessCore(workers=2)``: this process steps half the games, one worker process the
other half) vs VMAS ``simple_tag`` on the CPU at B = 1,024 (1 torch thread, no landmarks).
Random actions; games restart when they end.

    python benchmarks/bench_continuous.py [--repeats 5] [--steps 5000] [--batch-steps 600]
                                          [--vmas-steps 200] [--batch 64] [--vmas-batch 1024]

Targets: the single game at >= 3x mpe2, the 2-process core at >= VMAS. Needs the bench extra
(``pip install mpe2 vmas``). Figures are medians over interleaved repeats; each ratio is the
median of the ratios within a repeat.
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import numpy as np

from a2cm_phys import make_env
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.workers import ProcessCore

WORKERS = 2
SCENARIO = "phys_cont"


def single_game(env, steps: int, seed: int, sample) -> float:
    """Steps/s of a PettingZoo-style parallel env with ``sample(rng, agent)`` actions,
    resetting when the episode ends (actions drawn before the clock starts)."""
    rng = np.random.default_rng(seed)
    agents = list(env.possible_agents)
    plan = [{a: sample(rng, a) for a in agents} for _ in range(steps)]
    env.reset(seed=seed)
    start = time.perf_counter()
    for actions in plan:
        if not env.agents:
            env.reset()
        env.step({a: v for a, v in actions.items() if a in env.agents})
    return steps / (time.perf_counter() - start)


def batched_core(core, steps: int, seed: int) -> float:
    """Env-steps/s of a batched core with random commands, restarting finished games."""
    rng = np.random.default_rng(seed)
    b, n = core.num_envs, core.scenario.pursuers
    plan = rng.uniform(-1, 1, (steps, b, n, 2))
    core.reset(np.arange(b), rng.integers(0, 2**63, b).astype(np.uint64))
    start = time.perf_counter()
    for actions in plan:
        out = core.step(actions)
        core.observe()
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
    return b * steps / (time.perf_counter() - start)


def vmas_env(batch: int):
    """VMAS ``simple_tag`` (3 adversaries, 1 good agent, no landmarks) on the CPU."""
    import torch
    import vmas

    torch.set_num_threads(1)
    return vmas.make_env(
        "simple_tag",
        num_envs=batch,
        device="cpu",
        continuous_actions=True,
        num_good_agents=1,
        num_adversaries=3,
        num_landmarks=0,
        seed=0,
    )


def vmas_steps(env, steps: int, seed: int) -> float:
    """Env-steps/s of a VMAS env with uniform random actions over each agent's range
    (drawn before the clock starts); VMAS games have no end here, as in its benchmarks."""
    import torch

    gen = torch.Generator().manual_seed(seed)
    b = env.num_envs
    plan = [
        [(torch.rand(b, 2, generator=gen) * 2 - 1) * agent.action.u_range for agent in env.agents]
        for _ in range(steps)
    ]
    env.reset()
    start = time.perf_counter()
    for actions in plan:
        env.step(actions)
    return b * steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--steps", type=int, default=5_000, help="steps of the single games")
    parser.add_argument("--batch-steps", type=int, default=600, help="steps of our batched core")
    parser.add_argument("--vmas-steps", type=int, default=200, help="steps of the VMAS batch")
    parser.add_argument("--batch", type=int, default=64, help="games B of our batched core")
    parser.add_argument("--vmas-batch", type=int, default=1024, help="games B of VMAS")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    from mpe2 import simple_tag_v3

    theirs_env = simple_tag_v3.parallel_env(
        num_good=1, num_adversaries=3, num_obstacles=0, max_cycles=1000, continuous_actions=True
    )
    ours_env = make_env(SCENARIO)
    scenario = load_scenario(SCENARIO)
    mpe_space = {a: theirs_env.action_space(a) for a in theirs_env.possible_agents}

    def mpe_action(rng, agent):
        space = mpe_space[agent]
        return rng.uniform(space.low, space.high).astype(np.float32)

    def our_action(rng, agent):
        return rng.uniform(-1, 1, 2).astype(np.float32)

    split = ProcessCore(scenario, args.batch, WORKERS)
    vmas = vmas_env(args.vmas_batch)
    alone = PhysicsCore(scenario, args.batch)
    ours, theirs, workers, vm, one = [], [], [], [], []
    try:
        for r in range(args.repeats):
            ours.append(single_game(ours_env, args.steps, r, our_action))
            theirs.append(single_game(theirs_env, args.steps, r, mpe_action))
            workers.append(batched_core(split, args.batch_steps, r))
            vm.append(vmas_steps(vmas, args.vmas_steps, r))
            one.append(batched_core(alone, args.batch_steps, r))
    finally:
        split.close()
    med = statistics.median
    single_ratio = med(o / t for o, t in zip(ours, theirs, strict=True))
    batch_ratio = med(w / v for w, v in zip(workers, vm, strict=True))
    one_ratio = med(o / v for o, v in zip(one, vm, strict=True))
    ph = scenario.physics
    print(
        "command: python benchmarks/bench_continuous.py "
        f"--repeats {args.repeats} --steps {args.steps} --batch-steps {args.batch_steps} "
        f"--vmas-steps {args.vmas_steps} --batch {args.batch} --vmas-batch {args.vmas_batch}"
    )
    print(
        f"({SCENARIO}: dt = {ph.dt:g} s, substeps = {ph.substeps}, evader "
        f"{scenario.evader}; medians of {args.repeats} repeats)\n"
    )
    print("| what | median | ratio | target |")
    print("|---|---|---|---|")
    mpe = "mpe2 simple_tag_v3, continuous, one game"
    print(f"| {mpe} | {med(theirs):,.0f} steps/s | 1.0 | |")
    print(
        f"| make_env('{SCENARIO}'), one game | {med(ours):,.0f} steps/s | "
        f"{single_ratio:.2f}x mpe2 | >= 3x |"
    )
    print(f"| VMAS simple_tag, CPU, B = {args.vmas_batch} | {med(vm):,.0f} env-steps/s | 1.0 | |")
    print(
        f"| ProcessCore('{SCENARIO}'), B = {args.batch}, {WORKERS} workers | "
        f"{med(workers):,.0f} env-steps/s | {batch_ratio:.2f}x VMAS | >= 1x |"
    )
    print(
        f"| PhysicsCore('{SCENARIO}'), B = {args.batch}, one process | "
        f"{med(one):,.0f} env-steps/s | {one_ratio:.2f}x VMAS | |"
    )


if __name__ == "__main__":
    main()
