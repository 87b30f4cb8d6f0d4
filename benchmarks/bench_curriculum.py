"""A collision curriculum (issues 45 and 46): A2CM first learns the arena with collisions
free (``collisions.mode = "off"``, no collision penalty), then the scenario as it ships (a
collision ends the game, -1.5e8), warm-started from the first phase's actors, critics and
value normalisers (fresh optimiser).

    python benchmarks/bench_curriculum.py [--scenario phys_diff_obstacles] [--seed 0]
        [--steps 2000000,2000000] [--episodes 2000] [--set KEY=VALUE ...]

Prints, greedy over ``--episodes`` games of the shipped scenario (seed 0): the first
phase's team, the second's, and the scenario's reference policy on the same games (the
adapted ``pursuit`` in continuous physics, the exact oracle on grids; steps over the
captured games, capture rate, collisions a game); and appends them as one JSON line to
``--out``. Each phase is the train command's defaults for the budget it is given, with the
training keys of ``--set`` (both phases).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from a2cm_phys.analysis.evaluation import play, reference_policy
from a2cm_phys.analysis.policies import pursuer_policy
from a2cm_phys.config import Scenario, Train, load_scenario, load_train, resolve_train
from a2cm_phys.config.parse import parse_assignments
from a2cm_phys.training.runs import model_policy
from a2cm_phys.training.trainer import Trainer

FREE = {"collisions": {"mode": "off"}, "rewards": {"collision": 0.0}}
"""The first phase's changes to the scenario."""


def budget(scenario: Scenario, seed: int, steps: int, keys: dict[str, Any]) -> Train:
    """The defaults for ``scenario`` with ``steps`` environment steps and ``keys`` set."""
    values = {**keys, "seed": seed}
    batch = resolve_train(scenario, load_train(values)).batch_size
    return resolve_train(scenario, load_train({**values, "updates": steps // batch}))


def figures(scenario: Scenario, policy, episodes: int) -> dict[str, float]:
    """Greedy steps over captured games, capture rate and collisions a game."""
    got = play(scenario, policy, episodes, seed=0)
    return {
        "steps": float(got.lengths[got.captured].mean()),
        "captured": float(got.captured.mean()),
        "collisions": float(got.collisions.mean()),
    }


def main() -> None:
    """Train both phases and print their figures beside the reference's."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="phys_diff_obstacles")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", default="2000000,2000000", help="the two phases' steps")
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a training key, both phases",
    )
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/curriculum.jsonl"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    first_steps, second_steps = (int(x) for x in args.steps.split(","))
    keys = parse_assignments(args.set)  # training keys, as train's --set train.KEY=VALUE
    shipped = load_scenario(args.scenario)
    free = load_scenario(args.scenario, FREE)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        first = Trainer(
            free, budget(free, args.seed, first_steps, keys), Path(tmp, "1"), record=False
        )
        if first.run() != "done":
            raise RuntimeError("the first phase did not finish")
        second = Trainer(
            shipped, budget(shipped, args.seed, second_steps, keys), Path(tmp, "2"), record=False
        )
        second.model.load_state_dict(first.model.state_dict())
        if first.learner.value_norm is not None:
            second.learner.value_norm.load_state_dict(first.learner.value_norm.state_dict())
        if second.run() != "done":
            raise RuntimeError("the second phase did not finish")
    reference = reference_policy(shipped)
    row = {
        "scenario": args.scenario,
        "train": keys,
        "seed": args.seed,
        "steps": [first_steps, second_steps],
        "episodes": args.episodes,
        "first": figures(shipped, model_policy(first.model, greedy=True), args.episodes),
        "second": figures(shipped, model_policy(second.model, greedy=True), args.episodes),
        reference: figures(shipped, pursuer_policy(reference, shipped), args.episodes),
        "seconds": time.perf_counter() - start,
    }
    print(json.dumps(row))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("a") as fh:
        fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
