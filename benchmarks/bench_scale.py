"""Cost as the game grows (issue 35): stepping speed and memory, and training to the reference.

    python benchmarks/bench_scale.py --part cost [--modes grid,phys,phys_cont]
        [--sizes 5,8,10,15] [--teams 3,4,6] [--batch 16] [--seconds 0.6] [--repeats 3] [--passes 2]
        [--out benchmarks/results/scale_cost.json] [--figure benchmarks/results/scale_cost.png]
    python benchmarks/bench_scale.py --part train [--configs grid5x3,grid5x6,grid10x3,
        grid10x6,phys_cont5x3,phys_cont10x3] [--seeds 3] [--cap 5000000] [--every 250000]
        [--episodes 1000] [--jobs 2] [--to-cap] [--out benchmarks/results/scale_train.jsonl]
        [--set train.KEY=VALUE ...]

``--part cost`` (minutes): for every mode (grid; physics with discrete moves, ``phys``;
physics with continuous commands, ``phys_cont``), arena size and team size, the env-steps
per second (games x steps / s) of one game and of a batch of ``--batch`` games, stepped
as the trainer steps them (:class:`~a2cm_phys.envs.vector.VectorEnv` with auto-reset,
``validate=False``, in-process, uniformly random actions drawn beforehand): the median
of ``--repeats`` timings of ``--seconds`` each in each of ``--passes`` passes over the
cells (every other one in reverse order). Memory: the growth of the process's peak
resident set size (``ru_maxrss``) while the batch is built, reset and stepped, each cell
in a fresh process, after the one game has been timed (so that imports and first
allocations are not counted; the batch may reuse some of what the one game freed); the
median over the passes. Also the episodes ended per 1,000 env-steps of the batch (each
ended game is restarted within the step: restarts are much of a step's cost). A table on
stdout, JSON in ``--out``, the figure (steps/s against arena size, one line per mode and
team; one game and the batch side by side) in ``--figure``.

``--part train`` (hours; run it on a quiet machine): for each configuration (``MODE`` +
``SIZE`` ``x`` ``PURSUERS``: the shipped scenario ``grid``, ``grid10``, ``phys_cont`` or
``phys_cont10``, with ``pursuers`` overridden) and seed, trains with the project's
defaults but ``updates = cap // batch_size``, so that the run (and its learning-rate
anneal) ends at the cap, and every ``--every`` steps plays the greedy team for
``--episodes`` episodes (seed 1000 + seed). It records the first steps and training wall
time (evaluations excluded) at which the greedy mean capture steps is within 10% of the
reference: the exact optimum where the oracle solves the game, the scripted ``pursuit``
team otherwise (its mean over ``--episodes`` episodes, seed 10,000). A run stops there
unless ``--to-cap``; one that never gets there is "not reached". Rows go to ``--out`` as
JSON lines as runs finish (a rerun skips the runs already there); a table at the end.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import re
import resource
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from a2cm_phys.base.progress import Progress
from a2cm_phys.config import Scenario, load_scenario

MODES = {"grid": "grid", "phys": "phys", "phys_cont": "phys_cont"}
"""The cost part's modes and the 5x5 scenario each starts from."""
TARGET = 1.10
"""Reached: the greedy mean capture steps at most 10% above the reference."""
CONFIGS = "grid5x3,grid5x6,grid10x3,grid10x6,phys_cont5x3,phys_cont10x3"


def scale_scenario(mode: str, size: int, pursuers: int) -> Scenario:
    """The scenario of ``mode`` (``grid``, ``phys``, ``phys_cont``) on a ``size`` arena with
    ``pursuers`` pursuers: the shipped 10x10 scenario where there is one, else the 5x5 one
    resized, its step cap grown with the area as the 10x10 scenarios' is."""
    if size == 10 and mode in ("grid", "phys_cont"):
        return load_scenario(f"{mode}10", {"pursuers": pursuers})
    base = load_scenario(MODES[mode])
    cap = max(base.max_steps, round(base.max_steps * size * size / 25))
    return load_scenario(MODES[mode], {"size": size, "pursuers": pursuers, "max_steps": cap})


# --------------------------------------------------------------------------- cost


def _random_actions(env: Any, count: int, seed: int) -> np.ndarray:
    """``count`` joint actions for every game of ``env``, uniformly random."""
    rng = np.random.default_rng(seed)
    shape = (count, env.num_envs, *env.action_shape)
    if env.scenario.continuous:
        return rng.uniform(-1.0, 1.0, shape).astype(np.float32)
    return rng.integers(0, env.n_actions, shape, dtype=np.int64)


def _steps_per_second(env: Any, seconds: float, repeats: int) -> tuple[list[float], float]:
    """Env-steps per second (games x steps / s) of ``repeats`` timings of ``seconds``, and
    the episodes that ended per 1,000 env-steps meanwhile (each one a restart)."""
    actions = _random_actions(env, 256, 0)
    env.reset(0)
    for t in range(20):  # warm up
        env.step(actions[t], validate=False)
    rates, steps, ended = [], 0, 0
    for _ in range(repeats):
        n, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds:
            ended += len(env.step(actions[n % len(actions)], validate=False).episodes)
            n += 1
        rates.append(n * env.num_envs / elapsed)
        steps += n * env.num_envs
    return rates, 1000 * ended / steps


def _max_rss_mib() -> float:
    """The process's peak resident set size so far (MiB; Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def measure_cell(job: dict[str, Any]) -> dict[str, Any]:
    """One cell of the cost table, in a fresh process: the steps per second of one game,
    then of the batch, with the growth of the peak RSS while the batch is built and
    stepped (above the one game's, which it may partly reuse)."""
    from a2cm_phys.envs import physics  # noqa: F401  (pymunk loaded before the baseline)
    from a2cm_phys.envs.vector import VectorEnv

    sc = scale_scenario(job["mode"], job["size"], job["pursuers"])
    env = VectorEnv(sc, 1)  # first, so that imports and first allocations are not counted
    try:
        single, _ = _steps_per_second(env, job["seconds"], job["repeats"])
    finally:
        env.close()
    before = _max_rss_mib()
    env = VectorEnv(sc, job["batch"])
    try:
        batch, ended = _steps_per_second(env, job["seconds"], job["repeats"])
        memory = _max_rss_mib() - before
    finally:
        env.close()
    return {
        **{k: job[k] for k in ("mode", "size", "pursuers", "batch", "seconds", "repeats")},
        "max_steps": sc.max_steps,
        "single_runs": single,
        "batch_runs": batch,
        "episodes_per_1000_steps": ended,
        "batch_peak_rss_growth_mib": memory,
    }


def merge_passes(passes: list[dict[str, Any]]) -> dict[str, Any]:
    """One cell's passes as one row: medians over every timing, and over the passes'
    memories and episode rates."""
    row = {k: v for k, v in passes[0].items() if not k.endswith("_runs")}
    for key in ("single", "batch"):
        runs = [x for p in passes for x in p[f"{key}_runs"]]
        row[f"{key}_steps_per_s"] = statistics.median(runs)
        row[f"{key}_runs"] = runs
    for key in ("episodes_per_1000_steps", "batch_peak_rss_growth_mib"):
        row[key] = statistics.median(p[key] for p in passes)
    row["passes"] = len(passes)
    return row


def cost_table(rows: list[dict[str, Any]]) -> str:
    """The cost rows as a markdown table."""
    batch = rows[0]["batch"] if rows else 16
    out = [
        f"| mode | size | pursuers | steps/s, 1 game | steps/s, {batch} games"
        f" | memory of {batch} games (MiB, peak RSS growth) | episodes / 1,000 steps |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(
            f"| {r['mode']} | {r['size']}x{r['size']} | {r['pursuers']}"
            f" | {r['single_steps_per_s']:,.0f} | {r['batch_steps_per_s']:,.0f}"
            f" | {r['batch_peak_rss_growth_mib']:.1f} | {r['episodes_per_1000_steps']:.1f} |"
        )
    return "\n".join(out)


def cost_figure(rows: list[dict[str, Any]], path: Path) -> None:
    """Steps/s against arena size, one line per mode and team; one game and the batch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    colours = {"grid": "tab:blue", "phys": "tab:orange", "phys_cont": "tab:green"}
    styles = ["-", "--", ":", "-."]
    teams = sorted({r["pursuers"] for r in rows})
    for ax, key, title in (
        (axes[0], "single_steps_per_s", "one game"),
        (axes[1], "batch_steps_per_s", f"batch of {rows[0]['batch']} games"),
    ):
        for mode in [m for m in colours if any(r["mode"] == m for r in rows)]:
            for i, team in enumerate(teams):
                got = sorted(
                    (r["size"], r[key]) for r in rows if r["mode"] == mode and r["pursuers"] == team
                )
                if got:
                    xs, ys = zip(*got, strict=True)
                    ax.plot(xs, ys, styles[i % len(styles)], marker="o", ms=3,
                            color=colours[mode], label=f"{mode}, {team} pursuers")  # fmt: skip
        ax.set_yscale("log")
        ax.set_xticks(sorted({r["size"] for r in rows}))
        ax.set_xlabel("arena size (cells per side)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("env-steps per second (games x steps / s)")
    axes[1].legend(fontsize=7, ncol=1, loc="best")
    fig.suptitle("Stepping cost as the game grows (random actions, in-process)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_cost(args: argparse.Namespace) -> None:
    """The cost part (module docstring)."""
    cells = [
        {"mode": m, "size": s, "pursuers": n, "batch": args.batch, "seconds": args.seconds,
         "repeats": args.repeats}
        for m in args.modes.split(",") for s in _ints(args.sizes) for n in _ints(args.teams)
    ]  # fmt: skip
    # every other pass in reverse order, so that a slow spell of the machine's other work
    # falls on different cells in each
    jobs = [c for k in range(args.passes) for c in (cells if k % 2 == 0 else cells[::-1])]
    got: dict[tuple[str, int, int], list[dict[str, Any]]] = {}
    ctx = mp.get_context("spawn")
    # one process per cell (its peak RSS is its own), one at a time (the timings)
    with Progress("cost cells", len(jobs), "cell") as bar, ctx.Pool(1, maxtasksperchild=1) as pool:
        for one in pool.imap(measure_cell, jobs):
            got.setdefault((one["mode"], one["size"], one["pursuers"]), []).append(one)
            bar.update(1)
    rows = [merge_passes(got[(c["mode"], c["size"], c["pursuers"])]) for c in cells]
    out = Path(args.out or "benchmarks/results/scale_cost.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1) + "\n")
    cost_figure(rows, Path(args.figure))
    print(cost_table(rows))
    print(f"\nJSON: {out}; figure: {args.figure}")


# --------------------------------------------------------------------------- train


def parse_config(name: str) -> tuple[str, int, int]:
    """``grid10x3`` → ``("grid", 10, 3)``; a ``ValueError`` for anything else."""
    match = re.fullmatch(r"(grid|phys_cont|phys)(\d+)x(\d+)", name)
    if match is None:
        raise ValueError(f"config {name!r}: expected MODE SIZE x PURSUERS, e.g. grid10x3")
    return match[1], int(match[2]), int(match[3])


def reference(sc: Scenario, episodes: int) -> tuple[str, float]:
    """The reference's name and mean capture steps: the exact optimum where the oracle
    solves ``sc`` (it returns ``None`` where it refuses), else the ``pursuit`` team."""
    from a2cm_phys.analysis.evaluation import REFERENCE_SEED, optimum, play
    from a2cm_phys.analysis.policies import pursuer_policy

    best = optimum(sc) if sc.mode == "grid" else None
    if best is not None:
        return "optimum", float(best["capture_steps"])
    played = play(sc, pursuer_policy("pursuit", sc), episodes, 16, REFERENCE_SEED)
    return "pursuit", float(played.lengths.mean())


def train_one(job: dict[str, Any]) -> dict[str, Any]:
    """Train one configuration and seed up to the cap, evaluating as it goes (the row)."""
    import torch

    from a2cm_phys.analysis.evaluation import play
    from a2cm_phys.config import load_train, resolve_train
    from a2cm_phys.training.runs import model_policy
    from a2cm_phys.training.trainer import Trainer

    torch.set_num_threads(1)
    sc = scale_scenario(*parse_config(job["config"]))
    probe = resolve_train(sc, load_train({**job["train"], "seed": job["seed"]}))
    updates = max(1, job["cap"] // probe.batch_size)
    cfg = resolve_train(sc, load_train({**job["train"], "seed": job["seed"], "updates": updates}))
    every = max(1, round(job["every"] / cfg.batch_size))  # updates between evaluations
    goal = TARGET * job["reference"]
    evals: list[list[float]] = []
    clock = {"start": 0.0, "eval": 0.0}

    def evaluate(trainer: Trainer) -> None:
        """Play the greedy team; ask the run to stop once it is good enough."""
        t0 = time.perf_counter()
        steps, wall = trainer.update * cfg.batch_size, t0 - clock["start"] - clock["eval"]
        got = play(sc, model_policy(trainer.model, greedy=True), job["episodes"], 16,
                   1000 + job["seed"])  # fmt: skip
        mean = float(got.lengths.mean())
        evals.append([steps, wall, mean, float(got.captured.mean())])
        clock["eval"] += time.perf_counter() - t0
        if mean <= goal and not job["to_cap"] and trainer.signals is not None:
            trainer.signals.stop_requested = True  # as a SIGTERM: stop after this update

    class Evaluated(Trainer):
        """The trainer, evaluating the greedy team every ``every`` updates and at the end."""

        def _one_update(self, on_step: Any) -> None:
            super()._one_update(on_step)
            if self.update % every == 0 or self.update == self.cfg.updates:
                evaluate(self)

    with tempfile.TemporaryDirectory() as tmp:
        trainer = Evaluated(sc, cfg, tmp, record=False, checkpoint_seconds=math.inf)
        clock["start"] = time.perf_counter()
        status = trainer.run()
        seconds = time.perf_counter() - clock["start"] - clock["eval"]
        trainer.close()
    if status not in ("done", "interrupted"):
        raise RuntimeError(f"{job['config']} seed {job['seed']}: the run ended {status}")
    first = next((e for e in evals if e[2] <= goal), None)
    return {
        **{k: job[k] for k in ("config", "seed", "cap", "every", "episodes")},
        "scenario": sc.name, "size": sc.size, "pursuers": sc.pursuers, "max_steps": sc.max_steps,
        "reference_policy": job["reference_policy"], "reference": job["reference"],
        "batch_size": cfg.batch_size, "updates": cfg.updates,
        "reached": first is not None,
        "steps_to_reach": first[0] if first else None,
        "seconds_to_reach": first[1] if first else None,
        "last_mean_steps": evals[-1][2] if evals else None,
        "last_steps": evals[-1][0] if evals else 0,
        "train_seconds": seconds, "eval_seconds": clock["eval"],
        "evaluations": evals,  # [steps, train seconds, greedy mean steps, capture rate]
    }  # fmt: skip


def _median_or_none(values: list[float | None]) -> float | None:
    """The median (the upper one of an even count), counting ``None`` (not reached) as
    worse than any value: ``None`` unless more than half the values are reached."""
    ordered = sorted(values, key=lambda v: math.inf if v is None else v)
    return ordered[len(ordered) // 2] if ordered else None


def train_table(rows: list[dict[str, Any]], configs: list[str]) -> str:
    """Per configuration: the reference, the seeds that reached it, and the median steps
    and wall time to reach it (:func:`_median_or_none`: "not reached" unless most seeds
    reached it)."""
    out = [
        "| config | reference (mean capture steps) | reached | steps to reach (median)"
        " | wall time to reach (median) | last greedy mean steps (median) |",
        "|---|---|---|---|---|---|",
    ]
    for config in configs:
        got = [r for r in rows if r["config"] == config]
        if not got:
            continue
        steps = _median_or_none([r["steps_to_reach"] for r in got])
        wall = _median_or_none([r["seconds_to_reach"] for r in got])
        last = statistics.median(r["last_mean_steps"] for r in got)
        ref = f"{got[0]['reference_policy']} {got[0]['reference']:.2f}"
        out.append(
            f"| {config} | {ref} | {sum(r['reached'] for r in got)}/{len(got)}"
            f" | {f'{steps:,.0f}' if steps is not None else 'not reached'}"
            f" | {f'{wall:,.0f} s' if wall is not None else 'not reached'} | {last:.2f} |"
        )
    return "\n".join(out)


def run_train(args: argparse.Namespace) -> None:
    """The train part (module docstring)."""
    from a2cm_phys.config.parse import parse_assignments

    sets = parse_assignments(args.set)
    train = {k.removeprefix("train."): v for k, v in sets.items()}
    configs = args.configs.split(",")
    out = Path(args.out or "benchmarks/results/scale_train.jsonl")
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = [json.loads(line) for line in out.read_text().splitlines()] if out.exists() else []
    done = {(r["config"], r["seed"], r["cap"]) for r in rows}
    refs = {}
    for config in configs:
        refs[config] = reference(scale_scenario(*parse_config(config)), args.episodes)
        print(f"reference {config}: {refs[config][0]} {refs[config][1]:.3f}", flush=True)
    jobs = [
        {"config": c, "seed": seed, "cap": args.cap, "every": args.every,
         "episodes": args.episodes, "to_cap": args.to_cap, "train": train,
         "reference_policy": refs[c][0], "reference": refs[c][1]}
        for c in configs for seed in range(args.seeds) if (c, seed, args.cap) not in done
    ]  # fmt: skip
    if jobs:
        with (
            Progress("training runs", len(jobs), "run") as bar,
            mp.get_context("spawn").Pool(args.jobs) as pool,
            out.open("a") as sink,
        ):
            for row in pool.imap_unordered(train_one, jobs):
                sink.write(json.dumps(row) + "\n")
                sink.flush()
                bar.update(1)
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    rows = [r for r in rows if r["cap"] == args.cap and r["seed"] < args.seeds]
    print(train_table(rows, configs))


def _ints(text: str) -> list[int]:
    """``"5,8,10"`` → ``[5, 8, 10]``."""
    return [int(x) for x in text.split(",")]


def main() -> None:
    """Parse the options and run the part asked for (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--part", choices=("cost", "train"), required=True)
    parser.add_argument("--modes", default="grid,phys,phys_cont", help="cost: modes")
    parser.add_argument("--sizes", default="5,8,10,15", help="cost: arena sizes")
    parser.add_argument("--teams", default="3,4,6", help="cost: numbers of pursuers")
    parser.add_argument("--batch", type=int, default=16, help="cost: games in the batch")
    parser.add_argument("--seconds", type=float, default=0.6, help="cost: seconds per timing")
    parser.add_argument("--repeats", type=int, default=3, help="cost: timings per cell and pass")
    parser.add_argument("--passes", type=int, default=2, help="cost: passes over the cells")
    parser.add_argument("--figure", default="benchmarks/results/scale_cost.png")
    parser.add_argument("--configs", default=CONFIGS, help="train: MODE SIZE x PURSUERS")
    parser.add_argument("--seeds", type=int, default=3, help="train: seeds 0..K-1")
    parser.add_argument("--cap", type=int, default=5_000_000, help="train: steps per run")
    parser.add_argument("--every", type=int, default=250_000, help="train: steps per evaluation")
    parser.add_argument("--episodes", type=int, default=1000, help="train: episodes per evaluation")
    parser.add_argument("--to-cap", action="store_true", help="train: go on after reaching")
    parser.add_argument("--jobs", type=int, default=2, help="train: runs at once")
    parser.add_argument("--set", action="append", default=[], help="train: train.KEY=VALUE")
    parser.add_argument("--out", default=None, help="results file (default: by part)")
    args = parser.parse_args()
    if args.part == "cost":
        run_cost(args)
    else:
        run_train(args)


if __name__ == "__main__":
    main()
