"""What each piece of the learner buys (issue 12's ablation on the collision scenarios, issue
13's on continuous control).

    python benchmarks/bench_collision.py --variants paper16,ours --seeds 0-4 \
        --scenarios grid_collision,grid_collision_continue [--algos a2cm,a2c] [--jobs 2]

A variant is ``ours`` (the defaults), or the paper's method (``--preset paper``) with 16
games plus ``+``-separated pieces (``PIECES``), e.g. ``+split+advnorm+anneal``. Every run
has 640,000 steps unless ``--steps`` says otherwise. A run is trained, then its greedy and
sampled policies play ``--episodes`` evaluation episodes (each run is printed, with the
final Gaussian log-std and Lagrange multiplier); a row gives medians over seeds of
the mean capture steps (greedy, sampled), the collisions per episode, the return relative
to the reference's (raw reward) and the wall time, beside the reference: the exact optimum
on grids, the better of the oracle driven in physics and pursuit in physics mode. Runs go
to a process pool (``--jobs``), so wall times are only comparable within one invocation.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

PIECES: dict[str, dict[str, Any]] = {
    "advnorm": {"normalize_advantages": True},
    "popart": {"value_norm": True},
    "split": {"value_norm": True, "split_rewards": True},
    "splitraw": {"value_norm": True, "split_rewards": True, "balance_rewards": False},
    "gae": {"gae_lambda": 0.95},
    "gae.9": {"gae_lambda": 0.9},
    "adam": {"optimizer": "adam", "lr": 1e-3},
    "adam3e-3": {"optimizer": "adam", "lr": 3e-3},
    "b256": {"num_envs": 32, "batch_size": 256},
    "ent1e-2": {"entropy_coef": 1e-2},
    "ent1e-3": {"entropy_coef": 1e-3},
    "clip": {"max_grad_norm": 0.5},
    "anneal": {"lr_schedule": "linear"},
    "lr3e-3": {"lr": 3e-3},
    "lr1e-2": {"lr": 1e-2},
    "lr2e-2": {"lr": 2e-2},
    "beta.99": {"value_norm_beta": 0.99},
    "cw3": {"collision_weight": 3.0},
    "cw.7": {"collision_weight": 0.7},
    "cw.6": {"collision_weight": 0.6},
    "cw.5": {"collision_weight": 0.5},
    "cw.3": {"collision_weight": 0.3},
    "ent0": {"entropy_coef": 0.0},
    "ent3e-2": {"entropy_coef": 3e-2},
    "entlin": {"entropy_schedule": "linear"},
    "entconst": {"entropy_schedule": "constant"},
    # the defaults before the entropy schedule: `ours+ent1e-4` is the "ours" of older rows
    "ent1e-4": {"entropy_coef": 1e-4, "entropy_schedule": "constant"},
    "shape": {"distance_shaping": 1.0},
    # continuous control's progress shaping and clipping (issue 13): `ours+area0+noclip` is
    # the "ours" of the runs before the cell-area term
    "area0": {"area_shaping": 0.0},
    "area1": {"area_shaping": 1.0},
    "area2": {"area_shaping": 2.0},
    "dist0": {"distance_shaping": 0.0},
    "dist.5": {"distance_shaping": 0.5},
    "dist2": {"distance_shaping": 2.0},
    "h256": {"hidden": 256},
    "gru": {"recurrent": "gru"},  # recurrent actors (issue 33)
    "onehot": {"encoding": "onehot"},
    "rel": {"encoding": "relative"},  # each actor sees the others from its own body
    "metric": {"encoding": "metric"},  # the same, the offsets in metres (cells)
    "l2": {"layers": 2},
    "n16": {"batch_size": 256},  # 16-step rollouts (16 games)
    "n32": {"batch_size": 512},  # 32-step rollouts
    "n64": {"batch_size": 1024},  # 64-step rollouts
    "noclip": {"max_grad_norm": 0.0},
    "gamma.995": {"gamma": 0.995},
    "gamma.999": {"gamma": 0.999},
    "ls1": {"log_std_init": 1.0},
    "ls.5": {"log_std_init": 0.5},
    "ls0": {"log_std_init": 0.0},
    "ls-.5": {"log_std_init": -0.5},
    "ls-1": {"log_std_init": -1.0},
    "mb3": {"mean_bound": 3.0},  # the soft bound on Gaussian means from ±3, not ±1.1
    "lagrange": {"value_norm": True, "split_rewards": True, "constrain_collisions": True},
    # the collision constraint with a budget (collisions per step, in training)
    "lag2e-4": {"constrain_collisions": True, "collision_budget": 2e-4},
    "lag5e-4": {"constrain_collisions": True, "collision_budget": 5e-4},
    "lagrange10": {
        "value_norm": True,
        "split_rewards": True,
        "constrain_collisions": True,
        "lagrange_lr": 10.0,
    },
}
"""The pieces a variant name combines: ``+split+advnorm+anneal`` is the union of three."""


def variant_options(name: str) -> dict[str, Any]:
    """Training options of a variant: ``ours`` (the defaults) or ``paper16`` (the paper's
    method with 16 games), either plus ``+``-separated :data:`PIECES` (``ours+cw.5``)."""
    from a2cm_phys.config import preset

    base, *pieces = name.split("+")  # "+advnorm" is short for "paper16+advnorm"
    if base not in ("ours", "paper16", ""):
        raise ValueError(f"variant {name!r}: start with 'ours' or 'paper16'")
    options = {} if base == "ours" else {**preset("paper"), "num_envs": 16}
    for piece in pieces:
        if piece not in PIECES:
            raise ValueError(f"unknown piece {piece!r} in {name!r} (pieces: {', '.join(PIECES)})")
        options.update(PIECES[piece])
    return options


def run(scenario: str, algo: str, variant: str, seed: int, steps: int, episodes: int) -> dict:
    """Train one run and evaluate it; returns a row of figures."""
    import torch

    from a2cm_phys.analysis.evaluation import play
    from a2cm_phys.config import load_scenario, load_train, resolve_train
    from a2cm_phys.training.runs import model_policy
    from a2cm_phys.training.trainer import Trainer

    torch.set_num_threads(1)
    options = variant_options(variant)
    sc = load_scenario(scenario)
    batch = resolve_train(sc, load_train(options)).batch_size
    cfg = load_train({**options, "algo": algo, "seed": seed, "updates": steps // batch})
    with tempfile.TemporaryDirectory() as tmp:
        trainer = Trainer(sc, resolve_train(sc, cfg), tmp, record=False)
        start = time.perf_counter()
        status = trainer.run()
        seconds = time.perf_counter() - start
    greedy = play(sc, model_policy(trainer.model, greedy=True), episodes, seed=1)
    sampled = play(sc, model_policy(trainer.model), episodes, seed=1)
    return {
        "scenario": scenario,
        "algo": algo,
        "variant": variant,
        "seed": seed,
        "status": status,
        "greedy": float(greedy.lengths.mean()),
        "greedy_coll": float(greedy.collisions.mean()),
        "greedy_return": float(greedy.returns.mean()),
        "sampled": float(sampled.lengths.mean()),
        "sampled_coll": float(sampled.collisions.mean()),
        "seconds": seconds,
        "multiplier": trainer.learner.multiplier,  # the collision constraint's λ (0 without)
        "log_std": (
            None if trainer.model.log_std is None else float(trainer.model.log_std.detach().mean())
        ),
    }


def optimum(scenario: str, episodes: int) -> tuple[float, float, str]:
    """The reference's capture steps and return: the exact optimum on grids; in physics
    mode the better (by return) of the oracle driven in physics and pursuit, played greedy
    over ``episodes`` episodes. Returns ``(steps, return, description)``."""
    from a2cm_phys.analysis.evaluation import optimum as exact
    from a2cm_phys.analysis.evaluation import play
    from a2cm_phys.analysis.policies import pursuer_policy
    from a2cm_phys.config import load_scenario

    sc = load_scenario(scenario)
    best = exact(sc)
    if best is not None:
        return best["capture_steps"], best["return"], "exact optimum"
    rows = []
    for name in ("oracle", "pursuit"):
        r = play(sc, pursuer_policy(name, sc), episodes, seed=1)
        steps = float(r.lengths[r.captured].mean())
        rows.append((float(r.returns.mean()), steps, name, float(r.collisions.mean())))
        print(
            f"reference {name} on {scenario}: capture steps {steps:.3f}, return "
            f"{rows[-1][0]:,.1f}, collisions/ep {rows[-1][3]:.4f}"
        )
    ret, steps, name, _ = max(rows)
    return steps, ret, f"{name} (the better reference)"


def parse_seeds(text: str) -> list[int]:
    """``0-4`` or ``1,3``."""
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        out += range(int(lo), int(hi) + 1) if hi else [int(lo)]
    return out


def main() -> int:
    """Run the grid of variants × scenarios × algos × seeds and print the table."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--variants", default="paper16,+advnorm,+split+advnorm+anneal,ours")
    p.add_argument("--scenarios", default="grid_collision")
    p.add_argument("--algos", default="a2cm")
    p.add_argument("--seeds", default="0-1")
    p.add_argument("--steps", type=int, default=640_000)
    p.add_argument("--episodes", type=int, default=5000)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument(
        "--record",
        metavar="FILE",
        help="append each run, with its scenario's reference, to this .jsonl (the report's"
        " claims read benchmarks/results/collision.jsonl)",
    )
    args = p.parse_args()
    variants = args.variants.split(",")
    try:
        for v in variants:
            variant_options(v)
    except ValueError as err:
        p.error(str(err))
    jobs = [
        (s, a, v, seed, args.steps, args.episodes)
        for s in args.scenarios.split(",")
        for a in args.algos.split(",")
        for v in variants
        for seed in parse_seeds(args.seeds)
    ]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run, *zip(*jobs, strict=True)))
    for r in rows:  # every run, for the record
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()})
    print("command: python benchmarks/bench_collision.py " + " ".join(sys.argv[1:]))
    print(
        "| scenario | algo | variant | seeds | greedy steps (median; all) | greedy collisions/ep"
        " (median; all)"
        " | return / optimum | sampled steps | sampled collisions/ep | wall s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in args.scenarios.split(","):
        best, best_return, what = optimum(s, args.episodes)
        for a in args.algos.split(","):
            for v in variants:
                rs = [r for r in rows if (r["scenario"], r["algo"], r["variant"]) == (s, a, v)]
                keys = ("greedy", "greedy_coll", "sampled", "sampled_coll", "seconds")
                med = {k: statistics.median(r[k] for r in rs) for k in keys}
                each = ", ".join(f"{r['greedy']:.2f}" for r in rs)
                each_coll = ", ".join(f"{r['greedy_coll']:.4f}" for r in rs)
                ratio = statistics.median(r["greedy_return"] / best_return for r in rs)
                print(
                    f"| {s} | {a} | {v} | {len(rs)} | {med['greedy']:.3f} ({each}) |"
                    f" {med['greedy_coll']:.4f} ({each_coll}) | {ratio:.3f} |"
                    f" {med['sampled']:.3f} | {med['sampled_coll']:.4f} | {med['seconds']:.1f} |"
                )
        print(f"\n{what} of {s}: {best:.3f} steps, return {best_return:,.0f}")
        if args.record:
            with open(args.record, "a") as out:
                for r in (r for r in rows if r["scenario"] == s):
                    row = {**r, "reference": best, "reference_policy": what, "steps": args.steps}
                    out.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
