"""Self-play: one run trains the pursuers and a learned evader, each on its own reward, and
resumes bit for bit in grid mode."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from a2cm_phys.commands.train import main
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training import checkpoint
from a2cm_phys.training.rollout import collect
from a2cm_phys.training.seeding import policy_rng
from a2cm_phys.training.teams import make_teams
from a2cm_phys.training.trainer import Trainer

VS = ("--scenario", "grid_vs", "--num-envs", "4", "--batch-size", "32", "--seed", "5")
CONSTANT_LR = ("--set", "train.lr_schedule=constant")  # an extended run: the same schedule


def test_both_teams_collect_their_own_actions_and_rewards() -> None:
    scenario = load_scenario("grid_vs")
    cfg = resolve_train(scenario, load_train({"num_envs": 4, "batch_size": 32}))
    pursuers, evader = make_teams(scenario, cfg)
    assert evader is not None and evader.model.n_agents == 1 and evader.model.n_critics == 1
    env = VectorEnv(scenario, 4)
    obs = env.reset(0)
    collect(
        env,
        pursuers.model.act,
        obs,
        policy_rng(0),
        pursuers.batch,
        evader=(evader.model.act, evader.batch),
    )
    p, e = pursuers.batch, evader.batch
    assert e["obs"] is p["obs"] and e["terminated"] is p["terminated"]  # shared, not copied
    np.testing.assert_array_equal(e["rewards"], -p["rewards"])  # zero-sum by default
    assert e["actions"].shape == (8, 4, 1) and p["actions"].shape == (8, 4, 3)
    assert len(np.unique(e["actions"])) > 1  # the evader's own sampled moves


def test_scripted_evader_has_no_evader_team() -> None:
    grid = load_scenario("grid")
    _, evader = make_teams(grid, resolve_train(grid, load_train({})))
    assert evader is None


def test_one_run_trains_both_teams(tmp_path: Path) -> None:
    scenario = load_scenario("grid_vs")
    cfg = load_train({"num_envs": 4, "batch_size": 32, "updates": 5})
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path, record=False)
    assert trainer.evader is not None
    before = [p.detach().clone() for p in trainer.evader.model.parameters()]
    assert trainer.run() == "done"
    after = list(trainer.evader.model.parameters())
    assert all(not torch.equal(a, b) for a, b in zip(before, after, strict=True))
    assert "evader_loss" in trainer.last_metrics
    summary = trainer.summary()
    assert summary["evader_mean_return_last_1000"] == -summary["mean_return_last_1000"]
    state = checkpoint.load(tmp_path)
    assert state["evader_learner"]["model"].keys() == trainer.evader.model.state_dict().keys()


@pytest.mark.parametrize(
    "opponents",
    [
        (),
        ("--set", "train.pool_every=2", "--set", "train.pool_size=2"),
        (
            "--set",
            "train.descent_every=3",
            "--set",
            "train.descent_teams=both",
            "--set",
            "size=3",
            "--set",
            "pursuers=2",
            "--set",
            "max_steps=50",
        ),
    ],
    ids=["simultaneous", "pool", "descent"],
)
def test_self_play_resumes_bit_for_bit(tmp_path: Path, opponents: tuple[str, ...]) -> None:
    full_dir, part_dir = tmp_path / "a", tmp_path / "b"
    args = [*VS, *CONSTANT_LR, *opponents]
    assert main([*args, "--updates", "12", "--logdir", str(full_dir)]) == 0
    assert main([*args, "--updates", "6", "--logdir", str(part_dir)]) == 0
    (full,) = full_dir.iterdir()
    (part,) = part_dir.iterdir()
    assert main(["--resume", str(part), "--updates", "12", "--no-progress"]) == 0
    a, b = checkpoint.load(full), checkpoint.load(part)
    for team in ("learner", "evader_learner"):
        for key, value in a[team]["model"].items():
            assert torch.equal(value, b[team]["model"][key]), (team, key)
    assert a["rng"] == b["rng"]
    if "train.descent_every=3" in opponents:  # the same best response and Adam state
        da, db = a["descent"], b["descent"]
        assert torch.equal(da["values"], db["values"]) and da["rng"] == db["rng"]
        assert torch.equal(da["evader_values"], db["evader_values"])
        assert da["evader_rng"] == db["evader_rng"]
        assert torch.equal(
            da["optimizer"]["state"][0]["exp_avg"], db["optimizer"]["state"][0]["exp_avg"]
        )
        assert a["pool"] is None
    elif opponents:  # the pool: same draws, same snapshots (the newest two: updates 10 and 12)
        assert a["pool"]["rng"] == b["pool"]["rng"] and a["pool"]["counts"] == b["pool"]["counts"]
        for side in ("pursuers", "evader"):
            pa, pb = a["pool"]["snapshots"][side], b["pool"]["snapshots"][side]
            assert [s["update"] for s in pa] == [s["update"] for s in pb] == [10, 12]
            for x, y in zip(pa, pb, strict=True):
                assert all(torch.equal(v, y["weights"][k]) for k, v in x["weights"].items())
    else:
        assert a["pool"] is None
    sa, sb = (json.loads((p / "summary.json").read_text()) for p in (full, part))
    for key in ("episodes", "mean_length_last_1000", "evader_mean_return_last_1000", "opponents"):
        assert sa[key] == sb[key]


def test_exploitability_is_logged_every_k_updates_on_small_grids(tmp_path: Path) -> None:
    scenario = load_scenario("grid_vs", {"size": 3, "pursuers": 2, "max_steps": 50})
    cfg = load_train({"num_envs": 4, "batch_size": 32, "updates": 4, "exploit_every": 2})
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path, record=False)
    seen = []
    update = trainer._one_update

    def spy(on_step: object) -> None:
        update(on_step)
        seen.append("exploit_worst_case" in trainer.last_metrics)

    trainer._one_update = spy  # type: ignore[method-assign]
    assert trainer.run() == "done"
    assert seen == [False, True, False, True]
    worst, best = (trainer.last_metrics[k] for k in ("exploit_worst_case", "exploit_pursuers_br"))
    # the best team against this evader is at least as fast as any team's worst case
    assert 1.0 <= best <= worst <= 50.0
