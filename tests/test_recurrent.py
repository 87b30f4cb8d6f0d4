"""Recurrent actors (``train.recurrent = "gru"``): the cell, the memories the learner
recomputes, resets at episode ends, a memory task, and a bit-for-bit resume."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from a2cm_phys.algos import Learner, make_model
from a2cm_phys.algos.recurrent import (
    RecurrentActorCritic,
    RecurrentPolicy,
    StackedGRUCell,
    learner_inputs,
)
from a2cm_phys.commands.train import EXIT_INTERRUPTED, main
from a2cm_phys.config import ConfigError, load_scenario, load_train, resolve_train
from a2cm_phys.config.resolve import network_weights
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training import checkpoint
from a2cm_phys.training.rollout import allocate_batch, collect

GRU = {"num_envs": 4, "batch_size": 32, "recurrent": "gru", "hidden": 16}


def _setup(name: str = "grid_pomdp", **over):
    scenario = load_scenario(name)
    cfg = resolve_train(scenario, load_train({**GRU, **over}))
    return scenario, cfg, make_model(cfg, scenario)


def test_stacked_cells_compute_what_torch_grucell_computes() -> None:
    gen = torch.Generator().manual_seed(0)
    cells = StackedGRUCell(3, 5, 7, gen)
    x, h = torch.randn(4, 3, 5, generator=gen), torch.randn(4, 3, 7, generator=gen)
    out = cells(x, h)
    for i in range(3):
        ref = torch.nn.GRUCell(5, 7)
        with torch.no_grad():
            ref.weight_ih.copy_(cells.weight_ih[i])
            ref.weight_hh.copy_(cells.weight_hh[i])
            ref.bias_ih.copy_(cells.bias_ih[i])
            ref.bias_hh.copy_(cells.bias_hh[i])
        torch.testing.assert_close(out[:, i], ref(x[:, i], h[:, i]), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("algo", ["a2cm", "a2c"])
def test_the_weight_count_is_the_models(algo: str) -> None:
    scenario, cfg, model = _setup(algo=algo)
    assert isinstance(model, RecurrentActorCritic)
    assert network_weights(scenario, cfg) == sum(p.numel() for p in model.parameters())


def _rollout(scenario, cfg, model, steps: int = 24):
    """A rollout whose policy notes the memory it acted on at every step."""
    env = VectorEnv(scenario, cfg.num_envs)
    obs, rng = env.reset(3), np.random.default_rng(3)
    policy = RecurrentPolicy(model)
    acted: list[np.ndarray] = []

    def noting(o, r):
        actions = policy(o, r)
        acted.append(policy.memory.copy())
        return actions

    noting.episodes_ended = policy.episodes_ended  # type: ignore[attr-defined]
    batch = allocate_batch(steps, cfg.num_envs, env.obs_dim, scenario.pursuers)
    batch["memory"] = policy.start(cfg.num_envs).copy()
    collect(env, noting, obs, rng, batch)
    return batch, np.stack(acted)


@pytest.mark.parametrize("algo", ["a2cm", "a2c"])
def test_the_learner_recomputes_the_memories_the_rollout_acted_on(algo: str) -> None:
    scenario, cfg, model = _setup(algo=algo)
    batch, acted = _rollout(scenario, cfg, model)
    done = batch["terminated"] | batch["truncated"]
    assert done[:-1].any(), "the rollout must cross an episode's end"
    obs = torch.as_tensor(batch["obs"])
    x, view = learner_inputs(model, obs, batch)
    memories = model.split(x)[1].detach().numpy()
    np.testing.assert_allclose(memories, acted, rtol=1e-5, atol=1e-6)
    # after an episode's end the memory starts again from zero: h = GRU(obs, 0)
    t, b = np.argwhere(done[:-1])[0]
    fresh = model.remember(obs[t + 1, b][None], torch.zeros(1, *model.memory_shape(1)[1:]))
    np.testing.assert_allclose(memories[t + 1, b], fresh[0].detach().numpy(), atol=1e-6)
    # the state after the batch carries the memory it would be acted on with
    after = model.split(torch.as_tensor(view["next_obs"]))[1]
    last = memories[-1] * ~done[-1][:, None, None]
    want = model.remember(torch.as_tensor(batch["next_obs"]), torch.as_tensor(last))
    torch.testing.assert_close(after, want.detach())


def test_episodes_ended_forgets_only_the_games_that_ended() -> None:
    scenario, _, model = _setup()
    env = VectorEnv(scenario, 4)
    policy = RecurrentPolicy(model)
    policy(env.reset(0), np.random.default_rng(0))
    before = policy.memory.copy()
    assert np.abs(before).sum(axis=(1, 2)).min() > 0
    policy.episodes_ended(np.array([False, True, False, True]))
    assert not policy.memory[[1, 3]].any()
    np.testing.assert_array_equal(policy.memory[[0, 2]], before[[0, 2]])


def test_actor_losses_train_the_memory_and_a2c_critics_do_not() -> None:
    scenario, cfg, model = _setup(algo="a2c")
    batch, _ = _rollout(scenario, cfg, model, steps=8)
    x, _ = learner_inputs(model, torch.as_tensor(batch["obs"]), batch)
    model.value(x).sum().backward()
    assert model.actor_memory.weight_hh.grad is None or not model.actor_memory.weight_hh.grad.any()
    model.zero_grad()
    x, _ = learner_inputs(model, torch.as_tensor(batch["obs"]), batch)
    model.actor_outputs(x).square().sum().backward()
    assert model.actor_memory.weight_hh.grad.abs().sum() > 0


@pytest.mark.parametrize("key", ["pool_every", "exploit_every", "descent_every"])
def test_what_reads_a_policy_state_by_state_is_refused(key: str) -> None:
    with pytest.raises(ConfigError, match=f"'recurrent', '{key}'"):
        resolve_train(load_scenario("grid_vs"), load_train({**GRU, key: 2}))


# ---------------------------------------------------------------------- a memory task


class _CueTask:
    """A cue (0 or 1) shown at an episode's first step only; the agent is rewarded at the
    third step for the action equal to the cue. Without memory the best is a coin flip."""

    length = 3

    def __init__(self, games: int, rng: np.random.Generator) -> None:
        self.rng, self.t = rng, np.zeros(games, dtype=np.int64)
        self.cue = rng.integers(0, 2, games)

    def obs(self) -> np.ndarray:
        first, last = self.t == 0, self.t == self.length - 1
        cue = np.where(first, 2 * self.cue - 1, 0)
        return np.stack([first, cue, last], axis=1).astype(np.float32)

    def step(self, actions: np.ndarray):
        last = self.t == self.length - 1
        reward = (last & (actions[:, 0] == self.cue)).astype(np.float64)
        self.t = np.where(last, 0, self.t + 1)
        self.cue = np.where(last, self.rng.integers(0, 2, len(self.t)), self.cue)
        return reward, last


def _train_cue(recurrent: str, updates: int = 300, games: int = 16, steps: int = 6) -> float:
    cfg = load_train(
        {"recurrent": recurrent, "hidden": 32, "split_rewards": False, "value_norm": False,
         "entropy_coef": 0.01, "lr": 3e-3, "optimizer": "adam", "lr_schedule": "constant"}
    )  # fmt: skip
    gen = torch.Generator().manual_seed(1)
    net = RecurrentActorCritic if recurrent == "gru" else None
    kw = {"hidden": 32, "shared_critic": True, "generator": gen}
    from a2cm_phys.algos.models import ActorCritic

    model = (net or ActorCritic)(3, 1, 2, **kw)
    learner, rng = Learner(model, cfg), np.random.default_rng(1)
    task, policy = _CueTask(games, rng), model.rollout_policy()
    batch = allocate_batch(steps, games, 3, 1)
    for _ in range(updates):
        if model.recurrent:
            batch["memory"] = policy.start(games).copy()
        obs = task.obs()
        for t in range(steps):
            batch["obs"][t] = obs
            batch["actions"][t] = policy(obs, rng)
            batch["rewards"][t], batch["terminated"][t] = task.step(batch["actions"][t])
            if model.recurrent:
                policy.episodes_ended(batch["terminated"][t])
            obs = batch["final_obs"][t] = task.obs()
        batch["next_obs"][:] = obs
        learner.update(batch)
    greedy, hits, ends = model.rollout_policy(greedy=True), 0, 0
    task = _CueTask(200, np.random.default_rng(9))
    for _ in range(3 * task.length):
        reward, last = task.step(greedy(task.obs(), rng))
        if model.recurrent:
            greedy.episodes_ended(last)
        hits, ends = hits + int(reward.sum()), ends + int(last.sum())
    return hits / ends


def test_a_cue_seen_once_is_acted_on_later_only_with_memory() -> None:
    # 600 greedy episodes: a coin flip's accuracy lies within 0.5 ± 0.07 (3.4 sigma)
    assert _train_cue("gru") >= 0.95
    assert _train_cue("none") <= 0.57


# ---------------------------------------------------------------------- resume

ARGS = ("--scenario", "grid_pomdp", "--num-envs", "4", "--batch-size", "32", "--seed", "5")
SETS = ("--set", "train.recurrent=gru", "--set", "train.hidden=16", "--no-progress")


@pytest.mark.parametrize("algo", ["a2cm", "a2c"])
def test_a_run_interrupted_mid_rollout_resumes_bit_for_bit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, algo: str
) -> None:
    full, part = tmp_path / "a", tmp_path / "b"
    run = [*ARGS, *SETS, "--algo", algo, "--updates", "12"]
    assert main([*run, "--run-dir", str(full)]) == 0
    step, calls = VectorEnv.step, []

    def interrupted_step(self: VectorEnv, *args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == 8 * 7 + 3:  # inside the rollout of update 8
            raise KeyboardInterrupt
        return step(self, *args, **kwargs)

    monkeypatch.setattr(VectorEnv, "step", interrupted_step)
    assert main([*run, "--run-dir", str(part)]) == EXIT_INTERRUPTED
    at = checkpoint.load(part)
    assert at["update"] == 7 and at["memory"]["pursuers"].shape == (4, 3, 16)
    monkeypatch.setattr(VectorEnv, "step", step)
    assert main(["--resume", str(part), "--no-progress"]) == 0
    ca, cb = checkpoint.load(full), checkpoint.load(part)
    for key, value in ca["learner"]["model"].items():
        assert torch.equal(value, cb["learner"]["model"][key]), key
    np.testing.assert_array_equal(ca["memory"]["pursuers"], cb["memory"]["pursuers"])
    assert ca["rng"] == cb["rng"]
    sa, sb = (json.loads((p / "summary.json").read_text()) for p in (full, part))
    assert (
        sa["episodes"] == sb["episodes"]
        and sa["mean_length_last_1000"] == sb["mean_length_last_1000"]
    )


def test_a_trained_recurrent_run_is_evaluated_with_its_memory(tmp_path: Path) -> None:
    from a2cm_phys.analysis.evaluation import play
    from a2cm_phys.training.runs import load_trained_run, model_policy

    run = tmp_path / "r"
    assert main([*ARGS, *SETS, "--updates", "3", "--run-dir", str(run)]) == 0
    trained = load_trained_run(run)
    policy = model_policy(trained.pursuers, greedy=True)
    assert isinstance(policy, RecurrentPolicy)
    again = model_policy(trained.pursuers, greedy=True)
    a = play(trained.scenario, policy, 40, num_envs=4, seed=2).lengths
    b = play(trained.scenario, again, 40, num_envs=4, seed=2).lengths
    np.testing.assert_array_equal(a, b)


def test_a_learned_evader_remembers_too(tmp_path: Path) -> None:
    run = tmp_path / "vs"
    sets = ("--set", "sensing.radius=1", "--scenario", "grid_vs")
    assert main([*ARGS[2:], *SETS, *sets, "--updates", "3", "--run-dir", str(run)]) == 0
    state = checkpoint.load(run)
    assert state["memory"]["evader"].shape == (4, 1, 16)
    assert "actor_memory.weight_hh" in state["evader_learner"]["model"]
