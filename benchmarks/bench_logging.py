"""Cost of the run log: a random-policy loop over ``VectorEnv("grid", 16)`` with and without
an :class:`~a2cm_phys.record.EpisodeRecorder` logging every episode, the same for the A2CM
trainer, and the log size extrapolated to the paper's 640,000 steps.

    python benchmarks/bench_logging.py [--steps 3000] [--repeats 5] [--trainer-updates 300]

Times are this process's CPU time (the machine is shared: wall time swings with the load
of others), runs alternate (plain, recorded, plain, …), the table reports medians.
Recorded runs include opening and closing the log.
The random loop is the worst case: a grid step costs a few microseconds per game, so the
recorder's fixed work per episode weighs most there; the trainer row is the requirement's
measure (logging every episode costs at most 15% of training throughput).
"""

from __future__ import annotations

import argparse
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.record import EpisodeRecorder

PAPER_STEPS = 640_000


def random_loop(scenario_name: str, envs: int, steps: int, path: Path | None, seed: int) -> float:
    """Seconds for ``steps`` vector steps of a uniform random policy, recorded to ``path``
    (every episode) unless ``path`` is ``None``."""
    scenario = load_scenario(scenario_name)
    env = VectorEnv(scenario, envs)
    rng = np.random.default_rng(seed)
    shape = (envs, scenario.pursuers)
    obs = env.reset(seed)
    inside = 0.0
    start = time.process_time()
    if path is None:
        for _ in range(steps):
            env.step(rng.integers(0, scenario.actions, size=shape))
    else:
        meta = {"train": {"algo": "random", "seed": seed}}
        with EpisodeRecorder(path, scenario, meta) as rec:
            rec.start(env, obs)
            for _ in range(steps):
                actions = rng.integers(0, scenario.actions, size=shape)
                step = env.step(actions)
                t = time.process_time()
                rec.record_step(actions, step)
                inside += time.process_time() - t
            t = time.process_time()
        inside += time.process_time() - t  # close: the last block, summary, footer
    return time.process_time() - start, inside


def trainer_run(
    scenario_name: str, envs: int, updates: int, run_dir: Path | None, seed: int
) -> float:
    """Seconds for ``updates`` A2CM updates, with the MCAP log in ``run_dir`` if given."""
    from a2cm_phys.training.trainer import Trainer

    scenario = load_scenario(scenario_name)
    cfg = resolve_train(scenario, load_train({"num_envs": envs, "updates": updates, "seed": seed}))
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(
            scenario,
            cfg,
            run_dir or Path(tmp),
            record=run_dir is not None,
            checkpoint_seconds=1e9,
        )
        start = time.process_time()
        trainer.run()
        return time.process_time() - start


def _row(name: str, env_steps: int, vector_steps: int, seconds: list[float]) -> str:
    t = float(np.median(seconds))
    return f"| {name} | {env_steps / t:,.0f} | {t / vector_steps * 1e6:.1f} |"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print a markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="grid")
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--steps", type=int, default=3000, help="vector steps per random run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--trainer-updates",
        type=int,
        default=300,
        help="updates per trainer run (0: skip the trainer rows)",
    )
    args = parser.parse_args(argv)
    loop: dict[bool, list[float]] = {False: [], True: []}
    inside: list[float] = []
    train: dict[bool, list[float]] = {False: [], True: []}
    sizes: dict[str, list[float]] = {"random loop": [], "trainer": []}
    with tempfile.TemporaryDirectory() as tmp:
        # Warm-up (imports, first allocations, torch's first passes), not timed.
        random_loop(args.scenario, args.envs, 200, Path(tmp) / "warm.mcap", 0)
        if args.trainer_updates:
            (Path(tmp) / "warm").mkdir()
            trainer_run(args.scenario, args.envs, 20, Path(tmp) / "warm", 0)
        for r in range(args.repeats):
            for recorded in (False, True):
                path = Path(tmp) / f"loop{r}.mcap" if recorded else None
                seconds, in_recorder = random_loop(args.scenario, args.envs, args.steps, path, r)
                loop[recorded].append(seconds)
                if recorded:
                    inside.append(in_recorder)
                if path is not None:
                    sizes["random loop"].append(path.stat().st_size / (args.steps * args.envs))
            for recorded in (False, True) if args.trainer_updates else ():
                run_dir = Path(tmp) / f"train{r}" if recorded else None
                if run_dir is not None:
                    run_dir.mkdir()
                train[recorded].append(
                    trainer_run(args.scenario, args.envs, args.trainer_updates, run_dir, r)
                )
                if run_dir is not None:
                    steps = args.trainer_updates * 128
                    sizes["trainer"].append((run_dir / "episodes.mcap").stat().st_size / steps)
    print(f"`{shlex.join(['python', *sys.argv])}`\n")
    print(
        f"{args.scenario}, {args.envs} envs, median of {args.repeats} alternating runs; "
        f"random loop: {args.steps} vector steps a run; trainer (A2CM, batch 128): "
        f"{args.trainer_updates} updates a run\n"
    )
    print("| loop | env steps/s | µs per vector step |")
    print("| --- | ---: | ---: |")
    env_steps = args.steps * args.envs
    print(_row("random policy, no recorder", env_steps, args.steps, loop[False]))
    print(_row("random policy, recorder (every episode)", env_steps, args.steps, loop[True]))
    cost = 1 - np.median(loop[False]) / np.median(loop[True])
    own = float(np.median(inside)) / args.steps * 1e6
    lines = [
        f"random loop: logging costs {100 * cost:.1f}% of throughput; time inside the "
        f"recorder's calls: {own:.1f} µs per vector step "
        f"({100 * own / (own + np.median(loop[False]) / args.steps * 1e6):.1f}% of a recorded step)"
    ]
    if args.trainer_updates:
        t_steps = args.trainer_updates * 128
        vec = t_steps // args.envs
        print(_row("A2CM trainer, --no-record", t_steps, vec, train[False]))
        print(_row("A2CM trainer, recorder (every episode)", t_steps, vec, train[True]))
        cost = 1 - np.median(train[False]) / np.median(train[True])
        lines.append(f"trainer: logging costs {100 * cost:.1f}% of throughput")
    print()
    print("\n".join(lines))
    for name, values in sizes.items():
        if values:
            per_step = float(np.median(values))
            print(
                f"log size ({name}): {per_step:.1f} bytes per env step -> "
                f"{per_step * PAPER_STEPS / 1e6:.1f} MB extrapolated to {PAPER_STEPS:,} steps"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
