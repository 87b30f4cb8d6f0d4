"""A2CM and A2C against BenchMARL's MAPPO and IPPO on our scenarios, at equal environment steps.

    python benchmarks/bench_peers.py [--scenarios grid_collision,grid_random]
        [--algos a2cm,a2c,mappo,ippo] [--variants defaults,tuned] [--seeds 0-2]
        [--steps 640000] [--episodes 2000] [--jobs 2] [--out benchmarks/results/peers.jsonl]
        [--figure benchmarks/results/peers.png]

Each run trains on ``--steps`` environment steps (all games) and its team is then played
greedily by our own evaluation (:func:`a2cm_phys.analysis.evaluation.play`, the same
2,000 games for every learner: seed 1000 + seed) against the scenario's reference (the
exact optimum on grids, over the start distribution with random starts; in physics
``pursuit`` played on 2,000 games). Ours train with
the train command's defaults (``a2cm_phys.training.Trainer``); the peers are BenchMARL's
own implementations on :class:`a2cm_phys.integrations.benchmarl.PursuitTask`, over our
batched games:

- ``defaults``: BenchMARL's published defaults (``conf/experiment/base_experiment.yaml``,
  ``conf/algorithm/mappo.yaml`` / ``ippo.yaml``, ``conf/model/layers/mlp.yaml``: Adam
  5e-5, 6,000 frames a batch from 10 games, 45 epochs of minibatches of 400, γ 0.99, λ
  0.9, clip 0.2, no entropy bonus, two layers of 256 tanh units, policy and critic
  parameters shared within the team); the rewards as the scenario gives them;
- ``tuned``: the small tuning budget, stated: rewards divided by the step penalty's size
  (a step costs 1), Adam 3e-4, 10 epochs, 64 games a batch (everything else the defaults).

Results go to ``--out`` as JSON lines as they come (a rerun skips the rows already there);
the table printed at the end gives per scenario, learner and variant the median over
seeds of greedy steps ÷ the reference, the capture rate, collisions a game, and the
training wall time (``--jobs`` runs at once on this machine).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import statistics
import tempfile
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from benchmarl.algorithms import IppoConfig, MappoConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig

from a2cm_phys.analysis.evaluation import optimum, play
from a2cm_phys.analysis.policies import pursuer_policy
from a2cm_phys.commands.sweep import parse_seeds
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.integrations.benchmarl import PursuitTask
from a2cm_phys.integrations.torchrl import team_policy
from a2cm_phys.training.runs import model_policy
from a2cm_phys.training.trainer import Trainer

OURS, PEERS = ("a2cm", "a2c"), ("mappo", "ippo")


def _train_ours(job: dict, sc, tmp: str):
    values = {"algo": job["algo"], "seed": job["seed"]}
    batch = resolve_train(sc, load_train(values)).batch_size  # the defaults' batch
    cfg = resolve_train(sc, load_train({**values, "updates": job["steps"] // batch}))
    trainer = Trainer(sc, cfg, tmp, record=False, progress=False)
    if trainer.run() != "done":
        raise RuntimeError(f"{job}: the run did not finish")
    return model_policy(trainer.model, greedy=True)


def _train_peer(job: dict, sc, tmp: str):
    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_frames = job["steps"]
    cfg.loggers, cfg.evaluation, cfg.render, cfg.create_json = [], False, False, False
    cfg.save_folder, cfg.checkpoint_at_end = tmp, False
    task = PursuitTask(sc)
    if job["variant"] == "tuned":
        cfg.lr, cfg.on_policy_n_minibatch_iters, cfg.on_policy_n_envs_per_worker = 3e-4, 10, 64
        cfg.on_policy_collected_frames_per_batch = 64 * 100
        task = PursuitTask(sc, reward_scale=1.0 / abs(sc.rewards.step))
    algo = (MappoConfig if job["algo"] == "mappo" else IppoConfig).get_from_yaml()
    model = MlpConfig.get_from_yaml()
    exp = Experiment(task=task, algorithm_config=algo, model_config=model,
                     critic_model_config=MlpConfig.get_from_yaml(), seed=job["seed"],
                     config=cfg)  # fmt: skip
    exp.run()
    return team_policy(sc, exp.policy, greedy=True)


def run_one(job: dict) -> dict:
    """Train one learner and play it greedily: the row of the results file."""
    torch.set_num_threads(1)
    sc = load_scenario(job["scenario"])
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        train = _train_ours if job["algo"] in OURS else _train_peer
        policy = train(job, sc, tmp)
        seconds = time.perf_counter() - start
    result = play(sc, policy, job["episodes"], 16, 1000 + job["seed"])
    return {
        **{k: job[k] for k in ("scenario", "algo", "variant", "seed", "steps", "episodes")},
        "mean_steps": float(result.lengths.mean()),
        "capture_rate": float(result.captured.mean()),
        "collisions": float(result.collisions.mean()),
        "train_seconds": seconds,
    }


def reference_steps(scenario: str, episodes: int) -> float:
    """The reference's capture steps: the exact optimum on grids (over the start
    distribution), else ``pursuit`` played on ``episodes`` games (seed 1000)."""
    sc = load_scenario(scenario)
    if sc.mode == "grid":
        return float(optimum(sc)["capture_steps"])
    return float(play(sc, pursuer_policy("pursuit", sc), episodes, 16, 1000).lengths.mean())


def table(rows: list[dict]) -> str:
    """The medians over seeds, per scenario, learner and variant."""
    lines = [
        "| scenario | learner | variant | steps | greedy ÷ reference (seeds) | median | "
        "captured | collisions a game | train s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    refs: dict[str, float] = {}
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["scenario"], r["algo"], r["variant"], r["steps"]), []).append(r)
    for (scenario, algo, variant, steps), rs in sorted(groups.items()):
        if scenario not in refs:
            refs[scenario] = reference_steps(scenario, rs[0]["episodes"])
        rs.sort(key=lambda r: r["seed"])
        ratios = [r["mean_steps"] / refs[scenario] for r in rs]
        cells = ", ".join(f"{x:.3f}" for x in ratios)
        lines.append(
            f"| `{scenario}` | {algo} | {variant} | {steps:,} | {cells} | "
            f"**{statistics.median(ratios):.3f}** | "
            f"{statistics.median(r['capture_rate'] for r in rs):.3f} | "
            f"{statistics.median(r['collisions'] for r in rs):.3f} | "
            f"{statistics.median(r['train_seconds'] for r in rs):.0f} |"
        )
    return "\n".join(lines)


def figure(rows: list[dict], path: Path) -> None:
    """Greedy steps ÷ the reference of every run (dots) and the median (bar), per
    scenario and learner, with the median training time written under each bar."""
    plt.switch_backend("Agg")
    scenarios = sorted({(r["scenario"], r["steps"]) for r in rows})
    fig, axes = plt.subplots(1, len(scenarios), figsize=(4.2 * len(scenarios), 3.6))
    for ax, (scenario, steps) in zip(np.atleast_1d(axes), scenarios, strict=True):
        ref = reference_steps(scenario, 2000)
        mine = [r for r in rows if r["scenario"] == scenario and r["steps"] == steps]
        labels = sorted(
            {(r["algo"], r["variant"]) for r in mine}, key=lambda k: (k[0] not in OURS, k)
        )
        for x, (algo, variant) in enumerate(labels):
            rs = [r for r in mine if (r["algo"], r["variant"]) == (algo, variant)]
            ratios = [r["mean_steps"] / ref for r in rs]
            ax.bar(x, statistics.median(ratios), color="C0" if algo in OURS else "C1", alpha=0.5)
            ax.plot([x] * len(ratios), ratios, "k.", ms=4)
            seconds = statistics.median(r["train_seconds"] for r in rs)
            ax.annotate(f"{seconds:.0f} s", (x, 0.05), ha="center", fontsize=7)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_xticks(range(len(labels)), [f"{a}\n{v}" for a, v in labels], fontsize=7)
        ax.set_title(f"{scenario}, {steps:,} steps", fontsize=9)
        ax.set_ylabel("greedy steps ÷ reference")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    """Run the missing rows, then print the table."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", default="grid_collision,grid_random")
    p.add_argument("--algos", default="a2cm,a2c,mappo,ippo")
    p.add_argument("--variants", default="defaults,tuned", help="the peers' settings")
    p.add_argument("--seeds", default="0-2")
    p.add_argument("--steps", type=int, default=640_000)
    p.add_argument("--episodes", type=int, default=2000)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/peers.jsonl"))
    p.add_argument("--figure", type=Path, help="also draw the runs to this PNG")
    args = p.parse_args()
    rows = [json.loads(x) for x in args.out.read_text().splitlines()] if args.out.exists() else []
    done = {(r["scenario"], r["algo"], r["variant"], r["seed"], r["steps"]) for r in rows}
    jobs = [
        {"scenario": s, "algo": a, "variant": v, "seed": seed, "steps": args.steps,
         "episodes": args.episodes}
        for s in args.scenarios.split(",") for seed in parse_seeds(args.seeds)
        for a in args.algos.split(",")
        for v in (["ours"] if a in OURS else args.variants.split(","))
        if (s, a, v, seed, args.steps) not in done
    ]  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with mp.get_context("spawn").Pool(args.jobs, maxtasksperchild=1) as pool:
        for row in pool.imap_unordered(run_one, jobs):
            print(json.dumps(row), flush=True)
            with args.out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            rows.append(row)
    print(table(rows))
    if args.figure is not None:
        figure(rows, args.figure)


if __name__ == "__main__":
    main()
