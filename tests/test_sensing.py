"""Sensing (SPEC §6b, issue 33): masks at the radius' edge, no leaks, the full observation
unchanged with sensing off, config errors, the APIs' views and short training runs."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import a2cm_phys
from a2cm_phys.algos import make_model
from a2cm_phys.commands.replay import main as replay_main
from a2cm_phys.commands.train import main as train_main
from a2cm_phys.config import ConfigError, load_scenario, load_train, resolve_train
from a2cm_phys.envs.parallel import make_env
from a2cm_phys.envs.sensing import agent_observations, team_dim, team_observation
from a2cm_phys.envs.vector import VectorEnv


def _reset(scenario, positions, **overrides):
    env = make_env(scenario, evader="static", **overrides)
    obs, _ = env.reset(seed=0, options={"positions": positions})
    return env, obs


GRID = {"pursuer_0": (0, 0), "pursuer_1": (1, 1), "pursuer_2": (2, 0), "evader": (2, 2)}


def test_grid_masks_at_the_radius_edge_without_sharing():
    env, obs = _reset("grid_pomdp", GRID)
    assert env.observation_space("pursuer_0").shape == (11,)
    # own (x, y) / 4, then (mask, x, y) for the other pursuers in order, then the evader
    np.testing.assert_array_equal(obs["pursuer_0"], [0, 0, 1, 0.25, 0.25, 0, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(obs["pursuer_1"], [0.25, 0.25, 1, 0, 0, 1, 0.5, 0, 1, 0.5, 0.5])
    np.testing.assert_array_equal(obs["pursuer_2"], [0.5, 0, 0, 0, 0, 1, 0.25, 0.25, 0, 0, 0])
    np.testing.assert_array_equal(env.state(), [0, 0, 0.25, 0.25, 0.5, 0, 0.5, 0.5])


def test_grid_masks_with_sharing_pool_the_teams_sightings():
    _, obs = _reset("grid_pomdp_share", GRID)
    # pursuer_1 sees the evader, so everyone knows it; teammates are always known
    for name in ("pursuer_0", "pursuer_2"):
        assert obs[name][[2, 5, 8]].tolist() == [1, 1, 1]
    np.testing.assert_array_equal(obs["pursuer_0"][-3:], [1, 0.5, 0.5])
    # nobody sees it: masked for all, even with sharing
    far = {**GRID, "pursuer_1": (0, 4), "evader": (4, 4)}
    _, obs = _reset("grid_pomdp_share", far)
    for name in ("pursuer_0", "pursuer_1", "pursuer_2"):
        np.testing.assert_array_equal(obs[name][-3:], [0, 0, 0])


def test_a_learned_evader_senses_alone_within_the_radius():
    env = make_env("grid_vs", **{"sensing.radius": 1, "sensing.share": True})
    obs, _ = env.reset(seed=0, options={"positions": GRID})
    # the evader at (2, 2): pursuer_1 at (1, 1) only; pursuers in index order
    np.testing.assert_array_equal(obs["evader"], [0.5, 0.5, 0, 0, 0, 1, 0.25, 0.25, 0, 0, 0])


def test_physics_masks_at_the_radius_edge():
    placed = {
        "pursuer_0": (1.0, 1.0),
        "pursuer_1": (1.0, 2.6),  # 1.6 m from pursuer_0: out of range
        "pursuer_2": (4.0, 4.0),
        "evader": (2.5, 1.0),  # exactly 1.5 m from pursuer_0: in range
    }
    for share in (False, True):
        _, obs = _reset("phys_cont_pomdp", placed, **{"sensing.share": share})
        p0 = obs["pursuer_0"]
        assert p0.shape == (19,)  # 4 + 3 · 5
        np.testing.assert_allclose(p0[:4], [0.2, 0.2, 0, 0], atol=1e-6)
        assert p0[[4, 9, 14]].tolist() == ([1, 1, 1] if share else [0, 0, 1])
        np.testing.assert_allclose(p0[15:17], [0.5, 0.2])
        if not share:
            np.testing.assert_array_equal(p0[4:9], 0)
        p1 = obs["pursuer_1"]  # 1.6 m from the evader, too
        assert p1[14] == (1 if share else 0)


def _brute_force(scenario, cells):
    """Who knows whom, by loops: distance at most the radius, pooled when sharing."""
    n = scenario.pursuers
    grid = scenario.mode == "grid"
    r = scenario.sensing.radius

    def sees(i, j):
        d = np.abs(cells[i] - cells[j])
        return (d.max() if grid else np.hypot(*d)) <= r

    knows = [[sees(i, j) for j in range(n + 1)] for i in range(n + 1)]
    if scenario.sensing.share:
        for i in range(n):
            knows[i] = [j < n or any(sees(k, j) for k in range(n)) for j in range(n + 1)]
    return knows


@pytest.mark.parametrize("name", ["grid_pomdp", "grid_pomdp_share", "phys_cont_pomdp"])
@pytest.mark.parametrize("share", [False, True])
def test_unsensed_values_never_leak(name, share):
    scenario = load_scenario(name, {"sensing.share": share, "pursuers": 4, "size": 7})
    rng = np.random.default_rng(5)
    n, k, b = scenario.pursuers, 4 if scenario.mode == "physics" else 2, 200
    if scenario.mode == "grid":
        pos = rng.integers(0, scenario.size, (b, n + 1, 2)).astype(np.float64)
        state = (pos / (scenario.size - 1)).reshape(b, -1)
    else:
        pos = rng.uniform(0, scenario.size, (b, n + 1, 2))
        vel = rng.uniform(-1, 1, (b, n + 1, 2))
        state = np.concatenate([pos.reshape(b, -1) / scenario.size, vel.reshape(b, -1)], 1)
    state = state.astype(np.float32)
    truth = (
        state.reshape(b, n + 1, 2)
        if k == 2
        else np.concatenate(
            [
                state[:, : 2 * (n + 1)].reshape(b, n + 1, 2),
                state[:, 2 * (n + 1) :].reshape(b, n + 1, 2),
            ],
            -1,
        )
    )
    obs = agent_observations(scenario, state, pos)
    assert obs.shape == (b, n + 1, scenario.obs_dim)
    for g, i in itertools.product(range(b), range(n + 1)):
        knows = _brute_force(scenario, pos[g])
        np.testing.assert_array_equal(obs[g, i, :k], truth[g, i])
        others = [j for j in range(n + 1) if j != i]
        for slot, j in enumerate(others):
            row = obs[g, i, k + slot * (1 + k) : k + (slot + 1) * (1 + k)]
            if knows[i][j]:
                assert row[0] == 1
                np.testing.assert_array_equal(row[1:], truth[g, j])
            else:  # +0.0 everywhere: not even the sign of a velocity
                assert not np.signbit(row).any() and not row.any()
    team = team_observation(scenario, state, pos)
    assert team.shape == (b, team_dim(scenario))
    np.testing.assert_array_equal(team[:, : scenario.state_dim], state)


def test_sensing_off_gives_todays_observation():
    for name in ("grid", "phys_cont"):
        scenario = load_scenario(name)
        assert scenario.obs_dim == scenario.state_dim == team_dim(scenario)
        env = VectorEnv(scenario, num_envs=3)
        obs = env.reset(seed=1)
        np.testing.assert_array_equal(obs, env.core.observe())
        env.close()
    env = make_env("grid")
    obs, _ = env.reset(seed=0)
    expected = [0, 0, 1, 0, 0, 1, 0.5, 0.5]  # the corners, the evader in the centre
    for agent in env.agents:
        np.testing.assert_array_equal(obs[agent], expected)
    assert env.observation_space("pursuer_0") == env.state_space


@pytest.mark.parametrize("radius", [0, -1.5, "near"])
def test_config_errors_name_sensing_radius(radius):
    with pytest.raises(ConfigError, match=r"sensing\.radius"):
        load_scenario("grid", {"sensing": {"radius": radius}})
    with pytest.raises(ConfigError, match=r"sensing\.range"):
        load_scenario("grid", {"sensing": {"range": 1}})


def test_gym_joint_view_concatenates_the_pursuers_observations():
    env = gym.make(a2cm_phys.GYM_ID, scenario="grid_pomdp", evader="static")
    obs, _ = env.reset(seed=0, options={"positions": GRID})
    _, own = _reset("grid_pomdp", GRID)
    assert env.observation_space.shape == (33,)
    np.testing.assert_array_equal(obs, np.concatenate([own[f"pursuer_{i}"] for i in range(3)]))
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize("algo", ["a2cm", "a2c"])
def test_each_actor_reads_only_its_own_observation(algo):
    scenario = load_scenario("grid_pomdp")
    cfg = resolve_train(scenario, load_train({"algo": algo}))
    model = make_model(cfg, scenario)
    env = VectorEnv(scenario, num_envs=4)
    obs = env.reset(seed=3)
    env.close()
    base = model.outputs_np(obs)
    with torch.no_grad():
        np.testing.assert_allclose(model.actor_outputs(torch.as_tensor(obs)).numpy(), base, 1e-5)
        values = model.value(torch.as_tensor(obs)).numpy()
    d, s = scenario.obs_dim, scenario.state_dim
    for i in range(scenario.pursuers):
        changed = obs.copy()
        changed[:, s + i * d : s + (i + 1) * d] = 0.37
        out = model.outputs_np(changed)
        moved = [not np.allclose(out[:, j], base[:, j]) for j in range(scenario.pursuers)]
        assert moved == [j == i for j in range(scenario.pursuers)]
    # A2CM's critic reads the global state only; A2C's critic i agent i's observation
    blind = obs.copy()
    blind[:, s:] = 0.0
    with torch.no_grad():
        after = model.value(torch.as_tensor(blind)).numpy()
    assert np.allclose(after, values) == (algo == "a2cm")


def _train(tmp_path: Path, scenario: str, updates: int) -> Path:
    run = tmp_path / scenario
    args = ["--scenario", scenario, "--updates", str(updates), "--run-dir", str(run)]
    assert train_main([*args, "--no-progress"]) == 0
    return run


def test_short_training_runs_on_grid_pomdp_and_replay_verifies(tmp_path, capsys):
    run = _train(tmp_path, "grid_pomdp", 20)
    assert json.loads((run / "summary.json").read_text())["episodes"] > 0
    capsys.readouterr()
    assert replay_main([str(run), "--verify"]) == 0
    assert "all match" in capsys.readouterr().out


def test_short_training_runs_on_phys_cont_pomdp(tmp_path):
    run = _train(tmp_path, "phys_cont_pomdp", 3)
    assert json.loads((run / "summary.json").read_text())["updates"] == 3


def test_a_sensing_run_is_refused_by_export_in_one_line(tmp_path, capsys) -> None:
    """Each actor of a sensing run reads its own masked vector, which the exported runtime
    does not feed yet: the export says so rather than writing a team that plays wrong."""
    from a2cm_phys.commands.export import main as export
    from a2cm_phys.commands.train import main as train

    run = tmp_path / "run"
    argv = ["--scenario", "grid_pomdp", "--updates", "2", "--run-dir", str(run)]
    assert train([*argv, "--no-progress", "--no-record"]) == 0
    capsys.readouterr()
    assert export([str(run), "--out", str(tmp_path / "onnx")]) == 2
    err = capsys.readouterr().err
    assert "sensing scenario" in err and err.count("\n") == 1
    assert not (tmp_path / "onnx").exists()
