"""Trainer speed and what it learns: the paper's run (A2CM, ``grid``, 640,000 steps).

    python benchmarks/bench_train.py [--repeats 3] [--seeds 3] [--updates 5000]

Speed: wall time of ``Trainer.run()`` (the training loop, without interpreter start-up)
with 16 games and with 1 (the paper's setting), with and without the MCAP episode log,
and physics mode (``phys``, 16 games) when it is available; medians over ``--repeats``.
Learning: A2CM and A2C, ``--seeds`` seeds, 16 games; the final policy's mean capture steps,
greedy and sampled, over ``--episodes`` evaluation episodes (optimum ≈ 2.94 steps; the
paper's A2CM settled near 6). The learning runs (no log) double as the 16-game timings.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import tempfile
import time

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.training.runs import model_policy
from a2cm_phys.training.trainer import Trainer


def train(
    scenario: str,
    algo: str,
    num_envs: int,
    updates: int,
    seed: int,
    record: bool,
    workers: int = 1,
):
    """One run in a temporary directory: ``(seconds, trainer)``."""
    cfg = load_train(
        {
            "algo": algo,
            "num_envs": num_envs,
            "updates": updates,
            "seed": seed,
            "workers": workers,
        }
    )
    with tempfile.TemporaryDirectory() as tmp:
        sc = load_scenario(scenario)
        trainer = Trainer(sc, resolve_train(sc, cfg), tmp, record=record)
        start = time.perf_counter()
        status = trainer.run()
        seconds = time.perf_counter() - start
    if status != "done":
        raise RuntimeError(f"{scenario}/{algo}/seed {seed}: run ended with {status}")
    return seconds, trainer


def command(scenario: str, algo: str, num_envs: int, updates: int, extra: str = "") -> str:
    """The CLI run a benchmark row stands for."""
    return (
        f"python -m a2cm_phys.train --scenario {scenario} --algo {algo} "
        f"--num-envs {num_envs} --updates {updates} --no-progress{extra}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="timing repeats (1-game runs)")
    parser.add_argument("--phys-repeats", type=int, default=2, help="timing repeats (physics)")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--updates", type=int, default=5000)
    parser.add_argument("--episodes", type=int, default=5000, help="evaluation episodes")
    parser.add_argument("--skip-timing", action="store_true")
    parser.add_argument("--skip-learning", action="store_true")
    args = parser.parse_args()
    u, steps = args.updates, args.updates * 128
    print(f"# bench_train: {steps:,} steps per run ({u} updates x 128)\n", flush=True)

    learn_rows, times16 = [], {}
    if not args.skip_learning:
        for algo in ("a2cm", "a2c"):
            for seed in range(args.seeds):
                seconds, tr = train("grid", algo, 16, u, seed, record=False)
                times16.setdefault(algo, []).append(seconds)
                sc = tr.scenario
                greedy = play(sc, model_policy(tr.model, True), args.episodes, seed=100).lengths
                sampled = play(sc, model_policy(tr.model), args.episodes, seed=100).lengths
                row = (algo, seed, greedy.mean(), sampled.mean(), tr.stats.recent_mean(0), seconds)
                learn_rows.append(row)
                print(
                    "  learned",
                    *(f"{x:.3f}" if isinstance(x, float) else x for x in row),
                    flush=True,
                )

    time_rows = []
    if not args.skip_timing:
        for algo, secs in times16.items():
            time_rows.append(
                (
                    f"{algo}, grid, 16 games, no log",
                    secs,
                    command("grid", algo, 16, u, " --no-record"),
                )
            )
        cases = [("grid", 16, True, 1), ("grid", 1, True, 1), ("grid", 1, False, 1)]
        if importlib.util.find_spec("a2cm_phys.envs.physics") is not None:
            cases += [("phys", 16, False, 1), ("phys", 16, False, 2)]
        for scenario, envs, record, workers in cases:
            repeats = args.phys_repeats if scenario == "phys" else args.repeats
            secs = [train(scenario, "a2cm", envs, u, s, record, workers)[0] for s in range(repeats)]
            log = "with MCAP log" if record else "no log"
            extra = ("" if record else " --no-record") + (f" --workers {workers}") * (workers > 1)
            time_rows.append(
                (
                    f"a2cm, {scenario}, {envs} game{'s' * (envs > 1)}, {log}"
                    + f", {workers} workers" * (workers > 1),
                    secs,
                    command(scenario, "a2cm", envs, u, extra),
                )
            )
            print(
                f"  timed {time_rows[-1][0]}: {', '.join(f'{s:.1f}' for s in secs)} s", flush=True
            )

    print(f"\ncommand: python {' '.join(sys.argv)}  (machine: shared 2-core; medians)\n")
    if time_rows:
        print("| run (640k steps unless --updates) | median s | runs (s) | steps/s | command |")
        print("| --- | --- | --- | --- | --- |")
        for name, secs, cmd in time_rows:
            med = statistics.median(secs)
            runs = ", ".join(f"{s:.1f}" for s in secs)
            print(f"| {name} | {med:.1f} | {runs} | {steps / med:,.0f} | `{cmd}` |")
        print()
    if learn_rows:
        print(
            "| algo | seed | greedy mean capture steps | sampled | training mean length "
            "(last 1000) | train s |"
        )
        print("| --- | --- | --- | --- | --- | --- |")
        for algo, seed, g, s, t, secs in learn_rows:
            print(f"| {algo} | {seed} | {g:.3f} | {s:.3f} | {t:.3f} | {secs:.1f} |")
        for algo in ("a2cm", "a2c"):
            rows = [r for r in learn_rows if r[0] == algo]
            g = statistics.median(r[2] for r in rows)
            s = statistics.median(r[3] for r in rows)
            t = statistics.median(r[4] for r in rows)
            print(f"| **{algo} median** | | **{g:.3f}** | **{s:.3f}** | {t:.3f} | |")
        print(
            f"\nlearning runs: `{command('grid', 'ALGO', 16, u, ' --seed S --no-record')}`, "
            f"then `python -m a2cm_phys.evaluate RUN --episodes {args.episodes} [--greedy]`"
        )


if __name__ == "__main__":
    main()
