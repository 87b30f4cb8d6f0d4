"""Fictitious self-play (:mod:`a2cm_phys.training.opponents`): a bounded pool of past actors, seeded
draws of who plays whom, snapshots that are copies, only the live side learning, an exact
resume and clear configuration errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from a2cm_phys.commands.train import EXIT_INTERRUPTED, main
from a2cm_phys.config import ConfigError, load_scenario, load_train, resolve_train
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training import checkpoint
from a2cm_phys.training.opponents import LATEST, OpponentPool, Pairing, actor_weights
from a2cm_phys.training.teams import make_teams
from a2cm_phys.training.trainer import Trainer

SMALL = {"num_envs": 4, "batch_size": 32}
VS = ("--scenario", "grid_vs", "--num-envs", "4", "--batch-size", "32", "--seed", "5")
POOL = (
    "--set",
    "train.pool_every=2",
    "--set",
    "train.pool_size=2",
    "--set",
    "train.pool_latest=0.3",
)


def _pool(size: int = 3, latest: float = 0.5, seed: int = 0) -> OpponentPool:
    vs = load_scenario("grid_vs")
    pursuers, evader = make_teams(vs, resolve_train(vs, load_train({**SMALL, "seed": seed})))
    assert evader is not None
    return OpponentPool(pursuers.model, evader.model, size, latest, seed)


def _perturb(model: torch.nn.Module) -> None:
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.5)


def test_pool_keeps_the_newest_snapshots_of_both_teams() -> None:
    pool = _pool(size=3)
    for update in range(1, 6):
        pool.add(update * 10)
    assert len(pool) == 3
    for side in ("pursuers", "evader"):
        assert [u for u, _ in pool.snapshots[side]] == [30, 40, 50]


def test_draws_are_latest_while_empty_then_seeded_and_reproducible() -> None:
    pool = _pool()
    before = pool.rng.bit_generator.state
    assert [pool.draw() for _ in range(5)] == [LATEST] * 5
    assert pool.rng.bit_generator.state == before  # nothing to draw from: no draws

    def draws(seed: int) -> list[Pairing]:
        p = _pool(seed=seed)
        for u in (1, 2, 3):
            p.add(u)
        return [p.draw() for _ in range(200)]

    a = draws(0)
    assert a == draws(0)
    assert a != draws(1)
    kinds = [d.kind for d in a]
    assert 60 < kinds.count("latest") < 140  # p = 0.5
    assert kinds.count("past_evader") > 20 and kinds.count("past_pursuers") > 20
    assert {d.index for d in a if d.kind != "latest"} == {0, 1, 2}  # every snapshot used
    assert all(d.taken_at == d.index + 1 for d in a if d.kind != "latest")


@pytest.mark.parametrize(
    ("latest", "expect"), [(1.0, {"latest"}), (0.0, {"past_evader", "past_pursuers"})]
)
def test_pool_latest_extremes(latest: float, expect: set[str]) -> None:
    pool = _pool(latest=latest)
    pool.add(1)
    assert {pool.draw().kind for _ in range(50)} == expect


def test_snapshots_are_copies_and_play_as_the_past_policy() -> None:
    pool = _pool()
    live = pool.live["evader"]
    obs = np.random.default_rng(0).random((64, live.obs_dim), dtype=np.float32)
    then = live.action_probs_np(obs)
    pool.add(1)
    saved = {k: v.clone() for k, v in pool.snapshots["evader"][0][1].items()}
    _perturb(live)  # training the live actor ...
    assert not np.allclose(live.action_probs_np(obs), then)
    for key, value in pool.snapshots["evader"][0][1].items():  # ... leaves the snapshot
        assert torch.equal(value, saved[key]), key
    past = pool.player("evader", Pairing("past_evader", 0, 1))
    assert past is not live
    np.testing.assert_array_equal(past.action_probs_np(obs), then)
    assert pool.player("pursuers", Pairing("past_evader", 0, 1)) is pool.live["pursuers"]
    assert pool.player("evader", LATEST) is live
    assert set(actor_weights(live)) == {k for k in live.state_dict() if k.startswith("actor_")}


def test_only_the_live_side_learns(tmp_path: Path) -> None:
    scenario = load_scenario("grid_vs")
    cfg = load_train({**SMALL, "updates": 12, "pool_every": 1, "pool_latest": 0.0})
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path, record=False)
    assert trainer.pool is not None and trainer.evader is not None
    teams = {"pursuers": trainer.model, "evader": trainer.evader.model}
    seen = set()
    for _ in range(cfg.updates):
        before = {side: [p.clone() for p in m.parameters()] for side, m in teams.items()}
        trainer._one_update(None)
        kind = trainer.pairing.kind
        seen.add(kind)
        for side, model in teams.items():
            changed = any(
                not torch.equal(a, b) for a, b in zip(before[side], model.parameters(), strict=True)
            )
            assert changed == trainer.pairing.learns(side), (kind, side)
        metrics = trainer.last_metrics
        assert ("policy_loss" in metrics) == trainer.pairing.learns("pursuers")
        assert ("evader_policy_loss" in metrics) == trainer.pairing.learns("evader")
    assert seen == {"latest", "past_evader", "past_pursuers"}  # latest: the first update
    assert len(trainer.pool) == cfg.pool_size  # bounded: 12 snapshots offered, 10 kept
    assert "vs past evader" in trainer.summary()["opponents"]


def _assert_same(a: Path, b: Path) -> None:
    ca, cb = checkpoint.load(a), checkpoint.load(b)
    for team in ("learner", "evader_learner"):
        for key, value in ca[team]["model"].items():
            assert torch.equal(value, cb[team]["model"][key]), (team, key)
    assert ca["rng"] == cb["rng"] and ca["pool"]["rng"] == cb["pool"]["rng"]
    assert ca["pool"]["counts"] == cb["pool"]["counts"]
    for side in ("pursuers", "evader"):
        sa, sb = ca["pool"]["snapshots"][side], cb["pool"]["snapshots"][side]
        assert [s["update"] for s in sa] == [s["update"] for s in sb] != []
        for x, y in zip(sa, sb, strict=True):
            assert all(torch.equal(x["weights"][k], y["weights"][k]) for k in x["weights"])
    sa, sb = (json.loads((p / "summary.json").read_text()) for p in (a, b))
    for key in ("episodes", "mean_length_last_1000", "evader_mean_return_last_1000", "opponents"):
        assert sa[key] == sb[key], key


def test_pool_resumes_bit_for_bit_after_a_mid_rollout_interrupt(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    full, part = tmp_path / "a", tmp_path / "b"
    assert main([*VS, *POOL, "--updates", "12", "--run-dir", str(full), "--no-progress"]) == 0
    step, calls = VectorEnv.step, []

    def interrupted_step(self: VectorEnv, *args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == 8 * 7 + 3:  # inside the rollout of update 8, after its draw
            raise KeyboardInterrupt
        return step(self, *args, **kwargs)

    monkeypatch.setattr(VectorEnv, "step", interrupted_step)
    code = main([*VS, *POOL, "--updates", "12", "--run-dir", str(part), "--no-progress"])
    assert code == EXIT_INTERRUPTED and checkpoint.load(part)["update"] == 7
    monkeypatch.setattr(VectorEnv, "step", step)
    assert main(["--resume", str(part), "--no-progress"]) == 0
    _assert_same(full, part)
    assert (
        "pool (every 2, size 2, latest 0.3)"
        in json.loads((full / "summary.json").read_text())["opponents"]
    )


@pytest.mark.parametrize(
    ("key", "value"),
    [("pool_every", -1), ("pool_size", 0), ("pool_latest", 1.5), ("pool_size", 10**6)],
)
def test_bad_pool_values_name_the_key(key: str, value: float) -> None:
    with pytest.raises(ConfigError, match=f"key '{key}'"):
        load_train({key: value})


def test_pool_needs_a_learned_evader(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = load_train({**SMALL, "pool_every": 5})
    with pytest.raises(ConfigError, match=r"key 'pool_every'.*learned evader"):
        resolve_train(load_scenario("grid"), cfg)
    logdir = tmp_path / "logs"
    args = ["--scenario", "grid_flee", "--set", "train.pool_every=5", "--logdir", str(logdir)]
    assert main(args) == 2
    assert "pool_every" in capsys.readouterr().err and not logdir.exists()
    # a scripted evader with the pool off trains as before (pool_every = 0 is the default)
    grid = load_scenario("grid")
    trainer = Trainer(grid, resolve_train(grid, load_train({**SMALL, "updates": 1})), tmp_path)
    assert trainer.pool is None


def test_exploitability_and_pairings_are_logged_with_a_pool(tmp_path: Path) -> None:
    from a2cm_phys.record import read_run

    scenario = load_scenario("grid_vs", {"size": 3, "pursuers": 2, "max_steps": 50})
    cfg = load_train({**SMALL, "updates": 6, "exploit_every": 3, "pool_every": 1})
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path)
    assert trainer.run() == "done"
    updates = read_run(tmp_path).updates
    assert [u["update"] for u in updates] == [1, 2, 3, 4, 5, 6]
    assert [("exploit_worst_case" in u) for u in updates] == [False, False, True] * 2
    assert all(1.0 <= u["exploit_worst_case"] <= 50.0 for u in updates if "exploit_worst_case" in u)
    codes = {"latest": 0, "past_evader": 1, "past_pursuers": 2}
    assert sum(trainer.pool.counts.values()) == 6  # type: ignore[union-attr]
    for u in updates:
        assert u["pool_pairing"] in codes.values()
        assert (u["pool_snapshot_update"] == -1) == (u["pool_pairing"] == 0)
        assert ("policy_loss" in u) == (u["pool_pairing"] != 2)
