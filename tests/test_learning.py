"""A short learning run: A2CM on ``grid`` beats the random policy within 60,000 steps."""

from __future__ import annotations

import math
from pathlib import Path

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.policies import random_policy
from a2cm_phys.analysis.stats import mean_and_se
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.training.runs import model_policy
from a2cm_phys.training.trainer import Trainer

Z = 4.0
"""Standard errors the improvement must exceed (one-sided; chance ~3e-5 if no effect)."""


def test_a2cm_learns_to_catch_faster_than_random(tmp_path: Path) -> None:
    scenario = load_scenario("grid")
    cfg = load_train({"num_envs": 16, "updates": 60_000 // 128, "seed": 0})
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path, record=False)
    assert trainer.run() == "done"

    trained = play(scenario, model_policy(trainer.model), 2000, seed=1).lengths
    baseline = play(scenario, random_policy(scenario), 2000, seed=1).lengths
    (mt, st), (mr, sr) = mean_and_se(trained), mean_and_se(baseline)
    margin = Z * math.hypot(st, sr)
    assert mt + margin < mr, f"trained {mt:.2f}±{st:.2f} vs random {mr:.2f}±{sr:.2f}"
