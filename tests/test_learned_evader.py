"""A learned evader (SPEC §1b): the evader as an agent whose actions come with each step, in
grid mode and in physics mode with both control types, through every API."""

from __future__ import annotations

import numpy as np
import pytest
from test_grid_rules import CASES, DOWN, LEFT, RIGHT, STAY, UP

from a2cm_phys import make_env
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.core import evader_reward
from a2cm_phys.envs.evaders import make_evader
from a2cm_phys.envs.factory import make_core
from a2cm_phys.envs.grid import GridCore
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.envs.workers import ProcessCore

VS = ["grid_vs", "phys_vs", "phys_cont_vs"]


def random_joint(sc, rng, b):
    """Random pursuer and evader actions for ``b`` games (commands partly off the unit disc)."""
    if sc.continuous:
        return rng.uniform(-1.2, 1.2, (b, sc.pursuers, 2)), rng.uniform(-1.2, 1.2, (b, 2))
    return rng.integers(0, sc.actions, (b, sc.pursuers)), rng.integers(0, sc.actions, b)


def rollout(core, steps, rng_seed, evader_rng_seed=None):
    """Random actions for both teams for ``steps``, restarting finished games; the positions
    after each step. ``evader_rng_seed`` draws the evader's actions from a generator of
    their own."""
    rng = np.random.default_rng(rng_seed)
    evader_rng = rng if evader_rng_seed is None else np.random.default_rng(evader_rng_seed)
    b, sc = core.num_envs, core.scenario
    seeds = np.arange(b, dtype=np.uint64) + np.uint64(5)
    core.reset(np.arange(b), seeds)
    trace = []
    for _ in range(steps):
        pursuers, _ = random_joint(sc, rng, b)
        _, evader = random_joint(sc, evader_rng, b)
        out = core.step(pursuers, evader)
        trace.append(core.positions())
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, seeds[done] + np.uint64(1))
    return np.stack(trace)


# --------------------------------------------------------------------------- the agent


@pytest.mark.parametrize("name", VS)
def test_the_evader_is_the_last_agent_observing_the_global_state(name):
    env = make_env(name)
    sc = env.scenario
    assert env.possible_agents == [*sc.agents, "evader"]
    assert env.action_space("evader") == env.action_space("pursuer_0")
    assert env.observation_space("evader") == env.observation_space("pursuer_0")
    obs, infos = env.reset(seed=0)
    assert set(obs) == set(infos) == set(env.possible_agents)
    np.testing.assert_array_equal(obs["evader"], env.state())
    obs, rewards, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
    np.testing.assert_array_equal(obs["evader"], obs["pursuer_0"])
    assert rewards["evader"] == -rewards["pursuer_0"] == 1.0  # zero-sum: step −1


def test_action_spaces_match_the_pursuers_kind():
    assert make_env("grid_vs").action_space("evader").n == 4
    assert make_env("grid_vs", actions=5).action_space("evader").n == 5
    box = make_env("phys_cont_vs").action_space("evader")
    assert box.shape == (2,) and (box.low == -1).all() and (box.high == 1).all()


def test_scripted_scenarios_keep_the_pursuers_as_the_only_agents():
    for name in ("grid", "phys", "phys_cont"):
        assert make_env(name).possible_agents == load_scenario(name).agents


# --------------------------------------------------------------------------- moves


def grid_step(evader_cell, evader_action):
    """One grid_vs step from pursuers bumping into their corners' walls; the evader's cell
    after it and the outcome."""
    core = GridCore(load_scenario("grid_vs"), 1)
    placed = {"pursuer_0": (0, 0), "pursuer_1": (4, 0), "pursuer_2": (0, 4), "evader": evader_cell}
    core.reset(np.array([0]), np.array([0], dtype=np.uint64), [placed])
    out = core.step(np.array([[DOWN, DOWN, UP]]), np.array([evader_action]))
    return tuple(int(v) for v in core.positions()[0, -1]), out


@pytest.mark.parametrize(
    ("cell", "action", "after"),
    [
        ((2, 2), RIGHT, (3, 2)),
        ((2, 2), LEFT, (1, 2)),
        ((2, 2), UP, (2, 3)),
        ((2, 2), DOWN, (2, 1)),
        ((4, 2), RIGHT, (4, 2)),  # blocked at the wall: stays
        ((2, 4), UP, (2, 4)),
    ],
)
def test_the_grid_evader_moves_as_told(cell, action, after):
    moved, out = grid_step(cell, action)
    assert moved == after
    assert int(out.evader_action[0]) == action and not out.captured[0]
    assert int(out.wall_contacts[0]) == 3  # the pursuers' bumps only


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_the_grid_rules_are_unchanged_with_a_learned_evader(case):
    """The hand-written rule table of test_grid_rules, played through a learned evader's step."""
    _, start, acts, ev, expected, captured, collisions, walls = case
    core = GridCore(load_scenario("grid_vs", {"actions": 5}), 1)
    names = [*core.scenario.agents, "evader"]
    placed = dict(zip(names, start, strict=True))
    core.reset(np.array([0]), np.array([0], dtype=np.uint64), [placed])
    out = core.step(np.array([acts]), np.array([ev]))
    got = [tuple(int(v) for v in xy) for xy in core.positions()[0]]
    assert (got, bool(out.captured[0]), int(out.collisions[0]), int(out.wall_contacts[0])) == (
        expected,
        captured,
        collisions,
        walls,
    )
    assert out.terminated[0] == captured and out.reward[0] == -1.0


def test_a_physics_evader_moves_as_told():
    for name, command in (("phys_vs", RIGHT), ("phys_cont_vs", (1.0, 0.0))):
        core = PhysicsCore(load_scenario(name), 1)
        core.reset(np.array([0]), np.array([0], dtype=np.uint64))
        before = core.positions()[0, -1]
        stay = np.zeros((1, 3, 2)) if core.scenario.continuous else np.array([[LEFT, RIGHT, LEFT]])
        for _ in range(5):
            core.step(stay, np.array([command]))
        dx, dy = core.positions()[0, -1] - before
        assert dx > 0.2 and abs(dy) < 1e-9, (name, dx, dy)


def test_continuous_evader_commands_are_clipped_to_the_unit_disc():
    traces = []
    for command in ((3.0, 0.0), (1.0, 0.0)):
        core = PhysicsCore(load_scenario("phys_cont_vs"), 1)
        core.reset(np.array([0]), np.array([0], dtype=np.uint64))
        for _ in range(10):
            core.step(np.zeros((1, 3, 2)), np.array([command]))
        traces.append(core.positions())
    np.testing.assert_array_equal(*traces)


# --------------------------------------------------------------------------- determinism


@pytest.mark.parametrize("name", VS)
def test_same_seed_and_actions_are_bit_identical_after_1000_steps(name):
    sc = load_scenario(name, {"max_steps": 200})
    a, b = (rollout(make_core(sc, 2), 1000, 3)[-1] for _ in range(2))
    np.testing.assert_array_equal(a, b)
    c = rollout(make_core(sc, 2), 1000, 3, evader_rng_seed=4)[-1]  # other evader actions
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("name", ["phys_vs", "phys_cont_vs"])
def test_the_process_core_plays_a_learned_evader_like_the_physics_core(name):
    sc = load_scenario(name, {"max_steps": 25})
    with ProcessCore(sc, 4, 2) as parallel:
        np.testing.assert_array_equal(rollout(parallel, 60, 1), rollout(PhysicsCore(sc, 4), 60, 1))


# --------------------------------------------------------------------------- rewards


@pytest.mark.parametrize("name", VS)
def test_the_vector_env_gives_each_team_its_reward_zero_sum(name):
    sc = load_scenario(name, {"max_steps": 15})
    env = VectorEnv(sc, 3)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    episodes = []
    for _ in range(40):
        step = env.step(*random_joint(sc, rng, 3))
        np.testing.assert_array_equal(step.evader_reward, -step.reward)
        episodes += step.episodes
    assert episodes and all(e.evader_ret == -e.ret for e in episodes)


def test_the_survival_reward_counts_the_steps_survived():
    sc = load_scenario("grid_vs", {"rewards.evader": "survival", "max_steps": 6})
    env = VectorEnv(sc, 4)
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    episodes = []
    for _ in range(60):
        step = env.step(*random_joint(sc, rng, 4))
        np.testing.assert_array_equal(step.evader_reward, 1.0 - step.outcome.captured)
        episodes += step.episodes
    assert any(e.captured for e in episodes) and any(e.truncated for e in episodes)
    assert all(e.evader_ret == e.length - e.captured for e in episodes)
    penv = make_env("grid_vs", **{"rewards.evader": "survival"})
    penv.reset(seed=0)
    _, rewards, *_ = penv.step(dict.fromkeys(penv.agents, 0))
    assert rewards["evader"] == 1.0 and rewards["pursuer_0"] == -1.0


def test_evader_reward_is_a_pure_function_of_the_outcome():
    core = GridCore(load_scenario("grid_vs"), 1)
    core.reset(np.array([0]), np.array([0], dtype=np.uint64), [{"pursuer_0": (2, 1)}])
    out = core.step(np.array([[UP, DOWN, UP]]), np.array([DOWN]))  # they swap cells
    assert out.captured[0]
    assert evader_reward(core.scenario, out)[0] == 1.0  # zero-sum: minus the step's −1
    survival = load_scenario("grid_vs", {"rewards.evader": "survival"})
    assert evader_reward(survival, out)[0] == 0.0  # captured in this step: not survived


def test_scripted_vector_env_steps_have_no_evader_reward():
    env = VectorEnv(load_scenario("grid"), 2)
    env.reset(seed=0)
    step = env.step(np.zeros((2, 3), dtype=np.int64))
    assert step.evader_reward is None and not env.learned_evader


def test_a_grid_vector_env_with_a_learned_evader_resumes_exactly():
    sc = load_scenario("grid_vs", {"max_steps": 12})
    env = VectorEnv(sc, 3)
    env.reset(seed=2)
    rng = np.random.default_rng(0)
    joint = [random_joint(sc, rng, 3) for _ in range(40)]
    for acts in joint[:17]:
        env.step(*acts)
    saved = env.state()
    rest = [env.step(*acts) for acts in joint[17:]]
    other = VectorEnv(sc, 3)
    other.load_state(saved)
    again = [other.step(*acts) for acts in joint[17:]]
    assert [s.episodes for s in rest] == [s.episodes for s in again]
    assert sum(len(s.episodes) for s in rest) > 0


# --------------------------------------------------------------------------- refusals


@pytest.mark.parametrize("name", VS)
def test_a_learned_evader_refuses_a_step_without_its_actions(name):
    sc = load_scenario(name)
    core = make_core(sc, 2)
    core.reset(np.arange(2), np.arange(2, dtype=np.uint64))
    pursuers, _ = random_joint(sc, np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match=r"learned evader.*needs evader_actions"):
        core.step(pursuers)
    assert (core.t == 0).all()
    env = VectorEnv(sc, 2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="needs evader_actions"):
        env.step(pursuers)
    penv = make_env(name)
    penv.reset(seed=0)
    actions = {a: penv.action_space(a).sample() for a in sc.agents}
    with pytest.raises(ValueError, match=r"missing \['evader'\]"):
        penv.step(actions)


@pytest.mark.parametrize("name", ["grid", "grid_flee", "phys", "phys_cont_flee"])
def test_a_scripted_evader_refuses_evader_actions(name):
    sc = load_scenario(name)
    core = make_core(sc, 2)
    core.reset(np.arange(2), np.arange(2, dtype=np.uint64))
    pursuers, evader = random_joint(sc, np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match=f"scripted evader \\(evader = '{sc.evader}'\\)"):
        core.step(pursuers, evader)
    assert (core.t == 0).all()
    env = VectorEnv(sc, 2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="takes no evader_actions"):
        env.step(pursuers, evader)
    penv = make_env(name)
    penv.reset(seed=0)
    actions = {a: penv.action_space(a).sample() for a in [*sc.agents, "evader"]}
    with pytest.raises(ValueError, match=r"unknown \['evader'\]"):
        penv.step(actions)


def test_the_process_core_refuses_like_the_physics_core():
    with ProcessCore(load_scenario("phys_vs"), 2, 2) as core:
        core.reset(np.arange(2), np.arange(2, dtype=np.uint64))
        with pytest.raises(ValueError, match="needs evader_actions"):
            core.step(np.zeros((2, 3), dtype=np.int64))
        with pytest.raises(ValueError, match="for evader in env 1"):
            core.step(np.zeros((2, 3), dtype=np.int64), np.array([0, 7]))
        core.step(np.zeros((2, 3), dtype=np.int64), np.array([0, 3]))  # still serving
    with ProcessCore(load_scenario("phys"), 2, 2) as core:
        core.reset(np.arange(2), np.arange(2, dtype=np.uint64))
        with pytest.raises(ValueError, match="takes no evader_actions"):
            core.step(np.zeros((2, 3), dtype=np.int64), np.zeros(2, dtype=np.int64))


@pytest.mark.parametrize(
    ("name", "evader", "message"),
    [
        ("grid_vs", 4, r"invalid action 4 for evader: expected an integer in \[0, 4\)"),
        ("grid_vs", -1, "invalid action -1 for evader"),
        ("grid_vs", 1.0, "invalid action 1.0 for evader"),
        ("phys_vs", True, "invalid action True for evader"),
        ("phys_cont_vs", (np.nan, 0.0), "invalid action .* for evader: expected two finite"),
        ("phys_cont_vs", (np.inf, 0.0), "for evader"),
        ("phys_cont_vs", 0.5, "invalid action 0.5 for evader"),
    ],
)
def test_invalid_evader_actions_name_the_evader(name, evader, message):
    env = make_env(name)
    env.reset(seed=0)
    actions = {a: env.action_space(a).sample() for a in env.agents}
    actions["evader"] = evader
    with pytest.raises(ValueError, match=message):
        env.step(actions)


@pytest.mark.parametrize(
    ("name", "evader", "message"),
    [
        ("grid_vs", np.array([0, 4]), r"invalid action 4 for evader in env 1"),
        ("grid_vs", np.array([0.0, 1.0]), "expected integer evader moves"),
        ("grid_vs", np.array([[0], [1]]), r"shape \(2,\)"),
        ("phys_cont_vs", np.array([[0.0, 0.0], [np.nan, 1.0]]), "for evader in env 1"),
        ("phys_cont_vs", np.zeros(2), r"shape \(2, 2\)"),
    ],
)
def test_invalid_batched_evader_actions_change_no_game(name, evader, message):
    sc = load_scenario(name)
    env = VectorEnv(sc, 2)
    env.reset(seed=0)
    before = env.core.positions()
    pursuers, _ = random_joint(sc, np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match=message):
        env.step(pursuers, evader)
    assert (env.core.t == 0).all()
    np.testing.assert_array_equal(env.core.positions(), before)


def test_a_core_plays_the_evader_policy_it_is_given():
    """Both cores take an injected policy: a flee evader given to a core of the random
    scenario plays exactly as the flee scenario's own evader (positions included)."""
    for name in ("grid", "phys"):
        flee = load_scenario(f"{name}_flee")
        core_type = GridCore if flee.mode == "grid" else PhysicsCore
        r = flee.physics.evader_radius  # the evader's centre stays in [low, high]
        low, high = (0, flee.size - 1) if flee.mode == "grid" else (r, flee.size - r)
        policy = make_evader(flee, 3, low, high)
        given = core_type(load_scenario(name, {"max_steps": 20}), 3, evader=policy)
        own = core_type(load_scenario(f"{name}_flee", {"max_steps": 20}), 3)
        (pos_a, ev_a), (pos_b, ev_b) = (rollout_scripted(core) for core in (given, own))
        np.testing.assert_array_equal(pos_a, pos_b)
        np.testing.assert_array_equal(ev_a, ev_b)


def rollout_scripted(core, steps=40):
    """Positions and evader actions of ``steps`` random pursuer moves, restarting games."""
    rng = np.random.default_rng(0)
    core.reset(np.arange(core.num_envs), np.arange(core.num_envs, dtype=np.uint64))
    positions, evader = [], []
    for _ in range(steps):
        out = core.step(rng.integers(0, 4, (core.num_envs, core.scenario.pursuers)))
        positions.append(core.positions())
        evader.append(out.evader_action)
        done = np.flatnonzero(out.terminated | out.truncated)
        core.reset(done, done.astype(np.uint64) + np.uint64(9))
    return np.stack(positions), np.stack(evader)


def test_the_static_evader_still_stays_with_four_actions():
    core = GridCore(load_scenario("grid", {"evader": "static", "actions": 4}), 2)
    core.reset(np.arange(2), np.arange(2, dtype=np.uint64))
    out = core.step(np.zeros((2, 3), dtype=np.int64))
    assert (out.evader_action == STAY).all()
    np.testing.assert_array_equal(core.positions()[:, -1], [(2, 2), (2, 2)])
