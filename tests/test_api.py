"""The public APIs over every scenario: PettingZoo parallel, Gymnasium, vector env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

import a2cm_phys
from a2cm_phys import make_env
from a2cm_phys.config import ConfigError, load_scenario, scenario_names
from a2cm_phys.envs.vector import VectorEnv

ALL_SCENARIOS = scenario_names()
LEARNED = [name for name in ALL_SCENARIOS if load_scenario(name).evader == "learned"]
SCRIPTED = [name for name in ALL_SCENARIOS if name not in LEARNED]


def random_actions(scenario, agents, rng):
    """One random action per agent: a move, or a velocity command (continuous control)."""
    if scenario.continuous:
        return {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in agents}
    return {a: int(rng.integers(4)) for a in agents}


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_pettingzoo_parallel_api(scenario):
    parallel_api_test(make_env(scenario, max_steps=60), num_cycles=200)


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_pettingzoo_seed(scenario):
    parallel_seed_test(lambda: make_env(scenario, max_steps=60), num_cycles=100)


def test_the_learned_evader_scenarios_ship():
    assert {"grid_vs", "phys_vs", "phys_cont_vs"} <= set(LEARNED)


@pytest.mark.parametrize("scenario", SCRIPTED)
def test_gymnasium_env_checker(scenario):
    env = gym.make(a2cm_phys.GYM_ID, scenario=scenario, max_steps=60)
    check_env(env.unwrapped, skip_render_check=True)
    joint = gym.spaces.Box if env.unwrapped.scenario.continuous else gym.spaces.MultiDiscrete
    assert isinstance(env.action_space, joint)


@pytest.mark.parametrize("scenario", LEARNED)
def test_gymnasium_joint_view_refuses_a_learned_evader_naming_the_key(scenario):
    with pytest.raises(ConfigError, match=r"key 'evader'.*scripted evaders only"):
        gym.make(a2cm_phys.GYM_ID, scenario=scenario)
    gym.make(a2cm_phys.GYM_ID, scenario=scenario, evader="flee")  # scripted again: served


def test_gymnasium_joint_view_gives_the_team_reward():
    env = gym.make(a2cm_phys.GYM_ID, scenario="grid_collision")
    env.reset(seed=3, options={"positions": {"pursuer_0": (1, 1), "pursuer_1": (3, 1)}})
    _, reward, terminated, truncated, info = env.step(np.array([3, 2, 1]))
    assert reward == -1000.0 - 150_000_000.0 and terminated and not truncated
    assert info["collisions"] == 1


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_same_seed_same_trajectory(scenario):
    def run(seed):
        env = make_env(scenario, max_steps=40)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(123)
        trace = [obs["pursuer_0"]]
        for _ in range(120):
            if not env.agents:
                obs, _ = env.reset()
            obs, *_ = env.step(random_actions(env.scenario, env.agents, rng))
            trace.append(obs["pursuer_0"])
        return np.stack(trace)

    a, b, c = run(7), run(7), run(8)
    np.testing.assert_array_equal(a, b)
    if scenario in SCRIPTED:  # with a learned evader the seed decides nothing: all is actions
        assert not np.array_equal(a, c)


@pytest.mark.parametrize(
    ("positions", "message"),
    [
        ({"pursuer_0": (5, 0)}, "pursuer_0"),
        ({"evader": (-1, 2)}, "evader"),
        ({"pursuer_2": (1.5, 2)}, "integer cell"),
        ({"pursuer_0": (2, 2)}, "overlap"),
        ({"pursuer_7": (1, 1)}, "pursuer_7"),
        ({"pursuer_0": "here"}, "pursuer_0"),
    ],
)
def test_invalid_positions_name_the_agent(positions, message):
    env = make_env("grid")
    with pytest.raises(ValueError, match=message):
        env.reset(options={"positions": positions})


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        ({"pursuer_0": 4, "pursuer_1": 0, "pursuer_2": 0}, "pursuer_0"),
        ({"pursuer_0": 0, "pursuer_1": -1, "pursuer_2": 0}, "pursuer_1"),
        ({"pursuer_0": 0, "pursuer_1": 0, "pursuer_2": 1.0}, "pursuer_2"),
        ({"pursuer_0": 0, "pursuer_1": True, "pursuer_2": 0}, "pursuer_1"),
        ({"pursuer_0": 0, "pursuer_1": 0, "pursuer_2": np.int64(9)}, "pursuer_2"),
        ({"pursuer_0": 0, "pursuer_1": 0}, r"missing \['pursuer_2'\]"),
        ({}, "missing"),
        ({"pursuer_0": 0, "pursuer_1": 0, "pursuer_2": 0, "pursuer_3": 0}, "unknown"),
        ({"pursuer_0": 0, "pursuer_1": 0, "pursuer_3": 0}, r"missing \['pursuer_2'\]"),
    ],
)
def test_invalid_actions_name_the_agent(actions, message):
    env = make_env("grid")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(actions)


def test_infos_carry_the_step_facts():
    env = make_env("grid")
    _, infos = env.reset(seed=0)
    assert set(infos) == set(env.agents)
    _, _, _, _, infos = env.step({a: 0 for a in env.agents})
    assert {"captured", "collisions", "wall_contacts", "evader_action", "t"} <= set(
        infos["pursuer_0"]
    )


def test_vector_env_reports_finished_episodes_and_final_observation():
    sc = load_scenario("grid", {"max_steps": 5, "evader": "static"})
    env = VectorEnv(sc, num_envs=3)
    obs = env.reset(seed=0)
    start = obs.copy()
    # env 0 walks up 5 times (truncated at t=5); the others stay put by bumping walls
    actions = np.array([[0, 1, 1], [1, 1, 0], [1, 1, 0]])
    for _ in range(5):
        step = env.step(actions)
    assert step.truncated.all() and not step.terminated.any()
    assert [e.env for e in step.episodes] == [0, 1, 2]
    assert all(e.length == 5 and e.ret == -5.0 and e.truncated for e in step.episodes)
    np.testing.assert_array_equal(step.obs, start)  # auto-reset to the start
    assert step.final_obs[0, 1] == 1.0  # pursuer_0 at the top after the walk, y = 4 / 4
    assert step.episodes[0].seed != env.episode_seeds()[0]


def test_vector_env_episode_counts_match_a_single_env():
    """Each vector episode replays exactly in a single env from its seed (one seed path)."""
    sc = load_scenario("grid_collision_continue", {"max_steps": 30})
    env = VectorEnv(sc, num_envs=4)
    env.reset(seed=11)
    rng = np.random.default_rng(0)
    traces = {i: [] for i in range(4)}
    finished = []
    seeds = env.episode_seeds()
    for _ in range(100):
        acts = rng.integers(0, 4, (4, 3))
        for i in range(4):
            traces[i].append(acts[i])
        step = env.step(acts)
        for ep in step.episodes:
            finished.append((ep, seeds[ep.env], traces[ep.env]))
            traces[ep.env] = []
        seeds = env.episode_seeds()
    assert len(finished) >= 4
    for ep, seed, acts in finished:
        single = VectorEnv(sc, 1)
        single.reset(0)
        single.core.reset(np.array([0]), np.array([seed], dtype=np.uint64))
        total, coll = 0.0, 0
        for a in acts:
            out = single.step(np.asarray(a)[None])
            total += out.reward[0]
            coll += out.outcome.collisions[0]
        assert (total, coll, len(acts)) == (ep.ret, ep.collisions, ep.length)
