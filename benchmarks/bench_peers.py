"""A2CM and A2C against BenchMARL's MAPPO and IPPO on our scenarios, at equal environment steps.

    python benchmarks/bench_peers.py [--scenarios grid_collision,grid_random]
        [--algos a2cm,a2c,mappo,ippo] [--variants defaults,tuned] [--seeds 0-2]
        [--steps 640000] [--episodes 2000] [--jobs 2] [--out benchmarks/results/peers.jsonl]
        [--figure benchmarks/results/peers.png] [--curve-every 50000 --curve-episodes 500]

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

With ``--curve-every K`` every learner's greedy team is also played on ``--curve-episodes``
games (the same for every learner and point: seed 2000 + seed) each time another K
environment steps have been trained on, and at the end: the row's ``curve``, and from it
the steps it took to come within 5% of the reference (``steps_to_5pct``; ``None``: never
within the run). The evaluations' time is not counted in the training time.

Results go to ``--out`` as JSON lines as they come (a rerun skips the rows already there,
and with ``--curve-every`` only those with a curve; the last row of a run is the one read);
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
from benchmarl.experiment import Callback, Experiment, ExperimentConfig
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
WITHIN = 1.05  # steps_to_5pct: the first curve point at most this × the reference


class Curve:
    """The greedy team played every ``job["curve_every"]`` steps trained on (none when 0):
    ``points`` ``[steps, mean capture steps, capture rate]``, and the seconds spent
    playing (``seconds``), to be taken off the training time."""

    def __init__(self, job: dict, sc) -> None:
        self.job, self.sc, self.points, self.seconds = job, sc, [], 0.0
        self.next = job["curve_every"] or float("inf")

    def due(self, steps: int, last: bool = False) -> bool:
        """Whether ``steps`` trained on calls for a point (always at the end)."""
        return steps >= self.next or (last and bool(self.job["curve_every"]))

    def add(self, steps: int, policy) -> None:
        """Play ``policy`` (greedy) and note the point."""
        start = time.perf_counter()
        got = play(self.sc, policy, self.job["curve_episodes"], 16, 2000 + self.job["seed"])
        self.points.append([steps, float(got.lengths.mean()), float(got.captured.mean())])
        while self.next <= steps:
            self.next += self.job["curve_every"]
        self.seconds += time.perf_counter() - start


def _train_ours(job: dict, sc, tmp: str, curve: Curve):
    values = {"algo": job["algo"], "seed": job["seed"]}
    batch = resolve_train(sc, load_train(values)).batch_size  # the defaults' batch
    cfg = resolve_train(sc, load_train({**values, "updates": job["steps"] // batch}))

    class Traced(Trainer):
        """The trainer, its greedy team played as the curve asks."""

        def _one_update(self, on_step) -> None:
            super()._one_update(on_step)
            steps = self.update * cfg.batch_size
            if curve.due(steps, last=self.update == cfg.updates):
                curve.add(steps, model_policy(self.model, greedy=True))

    trainer = Traced(sc, cfg, tmp, record=False, progress=False)
    if trainer.run() != "done":
        raise RuntimeError(f"{job}: the run did not finish")
    return model_policy(trainer.model, greedy=True)


class _PeerCurve(Callback):
    """BenchMARL's hook after each training step: the pursuers' greedy team played as the
    curve asks."""

    def __init__(self, curve: Curve) -> None:
        super().__init__()
        self.curve = curve

    def on_train_end(self, training_td, group: str) -> None:
        exp = self.experiment
        if group != "pursuers":
            return
        last = exp.total_frames >= exp.config.max_n_frames
        if self.curve.due(exp.total_frames, last):
            self.curve.add(exp.total_frames, team_policy(self.curve.sc, exp.policy, greedy=True))


def _train_peer(job: dict, sc, tmp: str, curve: Curve):
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
                     config=cfg, callbacks=[_PeerCurve(curve)])  # fmt: skip
    exp.run()
    return team_policy(sc, exp.policy, greedy=True)


def run_one(job: dict) -> dict:
    """Train one learner and play it greedily: the row of the results file."""
    torch.set_num_threads(1)
    sc = load_scenario(job["scenario"])
    curve = Curve(job, sc)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        train = _train_ours if job["algo"] in OURS else _train_peer
        policy = train(job, sc, tmp, curve)
        seconds = time.perf_counter() - start - curve.seconds
    result = play(sc, policy, job["episodes"], 16, 1000 + job["seed"])
    row = {
        **{k: job[k] for k in ("scenario", "algo", "variant", "seed", "steps", "episodes")},
        "mean_steps": float(result.lengths.mean()),
        "capture_rate": float(result.captured.mean()),
        "collisions": float(result.collisions.mean()),
        "train_seconds": seconds,
    }
    if job["curve_every"]:
        goal = WITHIN * reference_steps(job["scenario"], job["episodes"])
        first = next((p[0] for p in curve.points if p[1] <= goal), None)
        row.update(curve=curve.points, curve_episodes=job["curve_episodes"], steps_to_5pct=first)
    return row


def _key(row: dict) -> tuple:
    return row["scenario"], row["algo"], row["variant"], row["seed"], row["steps"]


def latest(rows: list[dict]) -> list[dict]:
    """One row per scenario, learner, variant, seed and steps: the last one written (a run
    traced anew with ``--curve-every`` replaces the row it traces)."""
    return list({_key(r): r for r in rows}.values())


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
        "captured | collisions a game | train s | steps to within 5% (seeds) |",
        "|---|---|---|---|---|---|---|---|---|---|",
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
            f"{statistics.median(r['train_seconds'] for r in rs):.0f} | {_reach(rs)} |"
        )
    return "\n".join(lines)


def _reach(rows: list[dict]) -> str:
    """The steps to within 5% of the seeds that were traced: each seed's, "no" for one
    that never came within the run, "—" where no seed was traced."""
    traced = [r for r in rows if "curve" in r]
    if not traced:
        return "—"
    return ", ".join("no" if r["steps_to_5pct"] is None else f"{r['steps_to_5pct']:,}"
                     for r in traced)  # fmt: skip


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
    p.add_argument("--curve-every", type=int, default=0, help="steps between curve points")
    p.add_argument("--curve-episodes", type=int, default=500)
    args = p.parse_args()
    rows = [json.loads(x) for x in args.out.read_text().splitlines()] if args.out.exists() else []
    rows = latest(rows)
    done = {_key(r) for r in rows if not args.curve_every or "curve" in r}  # else traced anew
    jobs = [
        {"scenario": s, "algo": a, "variant": v, "seed": seed, "steps": args.steps,
         "episodes": args.episodes, "curve_every": args.curve_every,
         "curve_episodes": args.curve_episodes}
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
    rows = latest(rows)
    print(table(rows))
    if args.figure is not None:
        figure(rows, args.figure)


if __name__ == "__main__":
    main()
