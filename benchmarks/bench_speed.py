"""The main job's speed ablation (issue 35): training time and greedy quality per variant.

    python benchmarks/bench_speed.py [--scenario grid_collision] [--variants NAME,...]
        [--seeds 0-4] [--episodes 5000] [--jobs 1] [--out FILE] [--table]

A variant is a set of training options on top of the scenario's defaults (``VARIANTS``;
``defaults`` is the shipped configuration, ``before`` the grid defaults before issue 35:
16 games, batches of 128, 5,000 updates at 7e-3; the ``w`` variants keep the scenario's
own step budget, for physics). Each (variant, seed) trains without an episode
log, timed as ``Trainer.run()`` alone, then plays the trained team greedily for
``--episodes`` episodes (seed 1000 + seed). Rows go to ``--out`` as JSON lines as they
come (a rerun skips the ones there). The table gives per variant the median training
seconds, its ratio to ``defaults`` in the same file, the median greedy capture steps
(target ≤ 2.96 on ``grid_collision``) and collisions per episode (target 0), and the worst
seed. Run on a quiet machine with ``--jobs 1`` for times; ``--jobs 2`` halves the wall time
and keeps the quality figures exact.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import statistics
import tempfile
import time
from pathlib import Path

import torch

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.policies import pursuer_policy
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.training.runs import model_policy
from a2cm_phys.training.trainer import Trainer

STEPS = 640_000
"""The main job's environment steps (5,000 updates × 128)."""

VARIANTS: dict[str, dict] = {
    "defaults": {},
    "before": {"num_envs": 16, "batch_size": 128, "updates": 5000, "lr": 7e-3},
    "e32b256": {"num_envs": 32, "batch_size": 256, "updates": STEPS // 256},
    "e64b512": {"num_envs": 64, "batch_size": 512, "updates": STEPS // 512},
    "e64b512lr1e-2": {"num_envs": 64, "batch_size": 512, "updates": STEPS // 512, "lr": 1e-2},
    "e32b512": {"num_envs": 32, "batch_size": 512, "updates": STEPS // 512},
    "e128b1024": {"num_envs": 128, "batch_size": 1024, "updates": STEPS // 1024},
    "e64b512x.75": {"num_envs": 64, "batch_size": 512, "updates": 3 * STEPS // 4 // 512},
    "e64b512x.5": {"num_envs": 64, "batch_size": 512, "updates": STEPS // 2 // 512},
    # the scenario's own step budget (updates = steps // batch_size): physics's variants
    "w16b128": {"num_envs": 16, "batch_size": 128},
    "w32b256": {"num_envs": 32, "batch_size": 256},
    "w64b512": {"num_envs": 64, "batch_size": 512},
    "w64b512lr1e-2": {"num_envs": 64, "batch_size": 512, "lr": 1e-2},
}


def run_one(job: dict) -> dict:
    """Train one variant and seed, play it greedily: the row of the results file."""
    torch.set_num_threads(1)
    sc = load_scenario(job["scenario"])
    options = {**VARIANTS[job["variant"]], "seed": job["seed"], "algo": job["algo"]}
    cfg = resolve_train(sc, load_train(options))
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(sc, cfg, tmp, record=False, progress=False)
        start = time.perf_counter()
        status = trainer.run()
        seconds = time.perf_counter() - start
    if status != "done":
        raise RuntimeError(f"{job}: the run ended with {status}")
    result = play(
        sc, model_policy(trainer.model, greedy=True), job["episodes"], 16, 1000 + job["seed"]
    )
    return {
        **job,
        "train_seconds": seconds,
        "steps": cfg.updates * cfg.batch_size,
        "mean_steps": float(result.lengths.mean()),
        "collisions": float(result.collisions.mean()),
    }


def pursuit_steps(scenario: str, seeds: list[int], episodes: int) -> float:
    """The scripted ``pursuit`` team's median mean capture steps on the episodes the
    variants are played on (seeds 1000 + seed): the reference of physics's target."""
    sc = load_scenario(scenario)
    policy = pursuer_policy("pursuit", sc)
    return statistics.median(
        float(play(sc, policy, episodes, 16, 1000 + s).lengths.mean()) for s in seeds
    )


def seeds_of(text: str) -> list[int]:
    """``"0-4"`` or ``"0,2,5"`` as a list of seeds."""
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def table(rows: list[dict], scenario: str, algo: str) -> None:
    """Per variant: median seconds, ratio to ``defaults``, median and worst quality."""
    by: dict[str, list[dict]] = {}
    for row in rows:
        if row["scenario"] == scenario and row["algo"] == algo:
            by.setdefault(row["variant"], []).append(row)
    base = by.get("defaults")
    base_s = statistics.median(r["train_seconds"] for r in base) if base else None
    print(
        "| variant | seeds | train s (median) | ratio to defaults | greedy steps (median, worst) "
        "| collisions/episode (median, worst) |"
    )
    print("|---|---|---|---|---|---|")
    for name, group in by.items():
        secs = statistics.median(r["train_seconds"] for r in group)
        ratio = f"{secs / base_s:.3f}" if base_s else "–"
        steps = [r["mean_steps"] for r in group]
        coll = [r["collisions"] for r in group]
        print(
            f"| {name} | {len(group)} | {secs:.1f} | {ratio} | {statistics.median(steps):.3f}, "
            f"{max(steps):.3f} | {statistics.median(coll):.4f}, {max(coll):.4f} |"
        )


def main() -> None:
    """Run the missing (variant, seed) pairs, then print the table."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="grid_collision")
    p.add_argument("--variants", default="defaults,e32b256,e64b512")
    p.add_argument("--algo", default="a2cm", choices=["a2cm", "a2c"])
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--episodes", type=int, default=5000)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/speed.jsonl"))
    p.add_argument("--table", action="store_true", help="only print the table of --out")
    p.add_argument(
        "--pursuit", action="store_true", help="also print the scripted pursuit team's figure"
    )
    args = p.parse_args()
    done = []
    if args.out.exists():
        done = [json.loads(line) for line in args.out.read_text().splitlines() if line]
    if not args.table:
        have = {(r["scenario"], r["algo"], r["variant"], r["seed"]) for r in done}
        jobs = [
            {
                "scenario": args.scenario,
                "algo": args.algo,
                "variant": v,
                "seed": s,
                "episodes": args.episodes,
            }
            for s in seeds_of(args.seeds)
            for v in args.variants.split(",")
            if (args.scenario, args.algo, v, s) not in have
        ]
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with mp.get_context("spawn").Pool(args.jobs) as pool:
            for row in pool.imap_unordered(run_one, jobs):
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
                done.append(row)
                print(
                    f"{row['variant']} s{row['seed']}: {row['train_seconds']:.1f} s, "
                    f"{row['mean_steps']:.3f} steps, {row['collisions']:.4f} coll",
                    flush=True,
                )
    table(done, args.scenario, args.algo)
    if args.pursuit:
        seeds = seeds_of(args.seeds)
        print(f"pursuit: {pursuit_steps(args.scenario, seeds, args.episodes):.3f} steps")


if __name__ == "__main__":
    main()
