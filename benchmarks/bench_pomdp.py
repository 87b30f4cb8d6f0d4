"""Partial observability: recurrent teams against memoryless ones and the references.

    python benchmarks/bench_pomdp.py [--scenarios grid_pomdp,grid_pomdp_share,phys_cont_pomdp]
        [--algos a2cm,a2c] [--seeds 5] [--episodes 5000] [--jobs 2] [--out FILE]
        [--set train.KEY=VALUE ...] [--cost-only] [--no-references]

For each scenario, algorithm and seed it trains a memoryless team (``recurrent = "none"``)
and a recurrent one (``"gru"``) with the run's defaults (no episode log), then plays each
trained team greedily for ``--episodes`` episodes (seed 1000 + seed). Results go to ``--out``
as JSON lines as they come (a rerun skips the runs already there), and the table printed at
the end gives per scenario and algorithm the median capture steps of the memoryless and
the recurrent teams, their ratio (the issue's target: ≤ 0.85), and the references over the
same number of episodes: the full-observation optimum (grids: the exact oracle of the game
without sensing), the belief planner ``qmdp`` (grids), ``search`` and the full-observation
``pursuit`` (continuous control), each where it can be computed (``qmdp`` needs the dense
oracle: up to 8×8 with 3 pursuers).

How often the team is blind: every played team (and reference) counts the steps at which no
pursuer senses the evader (the mask bits of the observation it acts on, pooled over the
pursuers whatever ``sensing.share``), as a share of all steps ("blind"), and the mean length
of a spell without sight ("spell", in steps). Memory can pay only where the team is blind
often and for long.

Training cost: the median time of one learner update (recurrent and feed-forward, on the
same rollout batch, 20 repeats, interleaved) per 1,000 steps, and each run's wall time per
1,000 steps, medians over seeds.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from a2cm_phys.algos import Learner, make_model
from a2cm_phys.analysis.evaluation import optimum, play
from a2cm_phys.analysis.policies import pursuer_policy
from a2cm_phys.config import ConfigError, Scenario, load_scenario, load_train, resolve_train
from a2cm_phys.config.parse import parse_assignments
from a2cm_phys.envs.sensing import agent_slice, features
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training.rollout import Policy, allocate_batch, collect, episodes_ended
from a2cm_phys.training.runs import model_policy
from a2cm_phys.training.trainer import Trainer

KINDS = ("none", "gru")


class SightCount:
    """A pursuer policy, unchanged, that counts the steps at which no pursuer senses the
    evader (from the observation it is given) and the spells without sight."""

    def __init__(self, scenario: Scenario, policy: Policy) -> None:
        k, n = features(scenario), scenario.pursuers
        # each pursuer's mask bit for the evader, the last of its "others" (SPEC §6b)
        self.columns = [agent_slice(scenario, i).start + k + (n - 1) * (1 + k) for i in range(n)]
        self.policy, self.steps, self.blind = policy, 0, 0
        self.spells: list[int] = []
        self.run: np.ndarray | None = None

    def __call__(self, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        blind = ~(obs[:, self.columns] > 0.5).any(axis=1)
        if self.run is None:
            self.run = np.zeros(len(obs), dtype=np.int64)
        self.steps, self.blind = self.steps + len(obs), self.blind + int(blind.sum())
        self._close(~blind)
        self.run[blind] += 1
        return self.policy(obs, rng)

    def _close(self, games: np.ndarray) -> None:
        """End the spells of ``games`` (bool) that are running."""
        done = games & (self.run > 0)
        self.spells.extend(self.run[done].tolist())
        self.run[done] = 0

    def episodes_ended(self, ended: np.ndarray) -> None:
        """Spells end with the episode; the wrapped policy forgets as it would."""
        self._close(ended)
        episodes_ended(self.policy, ended)

    def figures(self) -> dict[str, float]:
        """``blind``: the share of steps without sight; ``spell``: a spell's mean length."""
        spell = float(np.mean(self.spells)) if self.spells else 0.0
        return {"blind": self.blind / max(self.steps, 1), "spell": spell}


def run_one(job: dict) -> dict:
    """Train one team and play it greedily: the row of the results file."""
    torch.set_num_threads(1)
    sc = load_scenario(job["scenario"])
    cfg = load_train(
        {**job["train"], "algo": job["algo"], "recurrent": job["recurrent"], "seed": job["seed"]}
    )
    cfg = resolve_train(sc, cfg)
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(sc, cfg, tmp, record=False, progress=False)
        start = time.perf_counter()
        status = trainer.run()
        seconds = time.perf_counter() - start
    if status != "done":
        raise RuntimeError(f"{job}: the run ended with {status}")
    steps = cfg.updates * cfg.batch_size
    policy = SightCount(sc, model_policy(trainer.model, greedy=True))
    result = play(sc, policy, job["episodes"], 16, 1000 + job["seed"])
    return {
        **{k: job[k] for k in ("scenario", "algo", "recurrent", "seed", "episodes")},
        "mean_steps": float(result.lengths.mean()),
        **policy.figures(),
        "capture_rate": float(result.captured.mean()),
        "collisions": float(result.collisions.mean()),
        "train_seconds": seconds,
        "train_steps": steps,
    }


def reference(name: str, scenario: str, episodes: int) -> dict[str, float] | None:
    """Mean capture steps (``steps``) of the pursuer policy ``name`` over ``episodes``
    greedy episodes, and where it senses its blind figures (:class:`SightCount`); ``None``
    where the policy cannot be built for the scenario (``qmdp`` beyond the dense oracle)."""
    sc = load_scenario(scenario)
    if name == "optimum":
        return {"steps": float(optimum(sc)["capture_steps"])}
    try:
        policy = pursuer_policy(name, sc)
    except ConfigError as err:
        print(f"{scenario}: no {name} reference ({err})", flush=True)
        return None
    if sc.sensing.on:
        policy = SightCount(sc, policy)
    steps = float(play(sc, policy, episodes, 16, 1000).lengths.mean())
    return {"steps": steps, **(policy.figures() if sc.sensing.on else {})}


def _reference_text(figures: dict[str, dict[str, float] | None]) -> str:
    """``name steps (blind share, spell)`` per reference, comma-separated."""
    parts = []
    for name, got in figures.items():
        if got is None:
            continue
        blind = f" (blind {got['blind']:.1%}, spell {got['spell']:.1f})" if "blind" in got else ""
        parts.append(f"{name} {got['steps']:.3f}{blind}")
    return ", ".join(parts)


def update_cost(scenario: str, train: dict, repeats: int = 20) -> dict[str, float]:
    """Median seconds of one learner update per 1,000 steps, feed-forward and recurrent."""
    torch.set_num_threads(1)
    sc = load_scenario(scenario)
    setups = {}
    for kind in KINDS:
        cfg = resolve_train(sc, load_train({**train, "recurrent": kind}))
        model = make_model(cfg, sc)
        env = VectorEnv(sc, cfg.num_envs)
        batch = allocate_batch(
            cfg.steps_per_env,
            cfg.num_envs,
            env.obs_dim,
            sc.pursuers,
            model.dist.action_shape,
            model.dist.action_dtype,
        )
        policy = model.rollout_policy()
        if model.recurrent:
            batch["memory"] = policy.start(cfg.num_envs).copy()
        collect(env, policy, env.reset(0), np.random.default_rng(0), batch)
        env.close()
        setups[kind] = (Learner(model, cfg), batch, cfg.batch_size)
    times: dict[str, list[float]] = {k: [] for k in KINDS}
    for _ in range(repeats):
        for kind, (learner, batch, size) in setups.items():
            start = time.perf_counter()
            learner.update(batch)
            times[kind].append((time.perf_counter() - start) * 1e6 / size)
    return {kind: statistics.median(t) for kind, t in times.items()}


def _median_of(rows: list[dict], key: str, **match) -> tuple[float, float, float, int] | None:
    """``(median, min, max, n)`` of ``key`` over the rows matching ``match``."""
    got = [r[key] for r in rows if key in r and all(r[k] == v for k, v in match.items())]
    return (statistics.median(got), min(got), max(got), len(got)) if got else None


def _table(rows: list[dict], refs: dict, costs: dict) -> str:
    """The results as two markdown tables: capture steps, then training cost."""
    out = [
        "| scenario | algo | memoryless | recurrent | ratio | seeds | blind, spell"
        " (memoryless / recurrent) | references |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for scenario, algo in sorted({(r["scenario"], r["algo"]) for r in rows}):
        med = {
            kind: _median_of(rows, "mean_steps", scenario=scenario, algo=algo, recurrent=kind)
            for kind in KINDS
        }
        none, gru = med["none"], med["gru"]
        ratio = f"{gru[0] / none[0]:.3f}" if none and gru else "—"
        cells = [f"{m[0]:.3f} ({m[1]:.2f}–{m[2]:.2f})" if m else "—" for m in (none, gru)]
        seeds = "/".join(str(m[3]) if m else "0" for m in (none, gru))
        sight = []
        for kind in KINDS:
            match = {"scenario": scenario, "algo": algo, "recurrent": kind}
            blind, spell = (_median_of(rows, key, **match) for key in ("blind", "spell"))
            sight.append(f"{blind[0]:.1%}, {spell[0]:.1f}" if blind and spell else "—")
        ref = _reference_text(refs.get(scenario, {}))
        out.append(
            f"| `{scenario}` | {algo} | {cells[0]} | {cells[1]} | {ratio} | {seeds}"
            f" | {' / '.join(sight)} | {ref} |"
        )
    out += [
        "",
        "| scenario | update, feed-forward (ms / 1,000 steps) | recurrent | ratio"
        " | run wall time / 1,000 steps, memoryless | recurrent |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        r["seconds_per_1000"] = 1000 * r["train_seconds"] / r["train_steps"]
    for scenario, cost in costs.items():
        wall = [_median_of(rows, "seconds_per_1000", scenario=scenario, recurrent=k) for k in KINDS]
        walls = [f"{w[0]:.3f} s" if w else "—" for w in wall]
        out.append(
            f"| `{scenario}` | {cost['none']:.2f} | {cost['gru']:.2f} |"
            f" {cost['gru'] / cost['none']:.2f} | {walls[0]} | {walls[1]} |"
        )
    return "\n".join(out)


REFERENCES = {"grid": ("qmdp",), "physics": ("search",)}
FULL_VIEW = {  # the same game seen whole; grids' optimum is the oracle's on the grid twin anyway
    "grid_pomdp": "grid",
    "grid_pomdp_share": "grid",
    "grid_pomdp_random": "grid_random",
    "grid9_pomdp_random": "grid9_pomdp_random",
    "phys_cont_pomdp": "phys_cont",
    "phys_cont_pomdp_random": "phys_cont_random",
}


def main() -> None:
    """Train, play and tabulate (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", default="grid_pomdp,grid_pomdp_share,phys_cont_pomdp")
    parser.add_argument("--algos", default="a2cm,a2c")
    parser.add_argument("--kinds", default="none,gru", help="recurrent settings to train")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=5000)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", default="benchmarks/results/pomdp.jsonl")
    parser.add_argument("--set", action="append", default=[], help="train.KEY=VALUE")
    parser.add_argument("--cost-only", action="store_true", help="only the update cost")
    parser.add_argument("--no-references", action="store_true")
    args = parser.parse_args()
    sets = parse_assignments(args.set)
    train = {"num_envs": 16, **{k.removeprefix("train."): v for k, v in sets.items()}}
    scenarios = args.scenarios.split(",")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = [json.loads(line) for line in out.read_text().splitlines()] if out.exists() else []
    done = {(r["scenario"], r["algo"], r["recurrent"], r["seed"]) for r in rows}
    jobs = [
        {"scenario": s, "algo": a, "recurrent": k, "seed": seed, "train": train,
         "episodes": args.episodes}
        for s in scenarios for seed in range(args.seeds) for a in args.algos.split(",")
        for k in args.kinds.split(",") if (s, a, k, seed) not in done
    ]  # fmt: skip
    if not args.cost_only and jobs:
        with mp.get_context("spawn").Pool(args.jobs) as pool, out.open("a") as sink:
            for row in pool.imap_unordered(run_one, jobs):
                sink.write(json.dumps(row) + "\n")
                sink.flush()
                print(json.dumps(row), flush=True)
    rows = [json.loads(line) for line in out.read_text().splitlines()] if out.exists() else []
    rows = [r for r in rows if r["scenario"] in scenarios]
    refs: dict[str, dict[str, dict[str, float] | None]] = {}
    if not args.no_references:
        for s in scenarios:
            mode = load_scenario(s).mode
            refs[s] = {name: reference(name, s, args.episodes) for name in REFERENCES[mode]}
            if mode == "physics":
                refs[s]["pursuit (full view)"] = reference("pursuit", FULL_VIEW[s], args.episodes)
            else:
                refs[s]["optimum"] = reference("optimum", FULL_VIEW[s], args.episodes)
    costs = {s: update_cost(s, train) for s in scenarios}
    print(_table(rows, refs, costs))


if __name__ == "__main__":
    main()
