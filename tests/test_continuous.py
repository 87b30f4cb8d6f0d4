"""Continuous control in physics mode (SPEC §3b): configuration, commands, real contacts driven
by action vectors, determinism, the batched and process cores, and the pursuit baseline."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import a2cm_phys
from a2cm_phys import make_env
from a2cm_phys.analysis.baselines import pursuit_actions
from a2cm_phys.config import ConfigError, load_scenario, scenario_names
from a2cm_phys.envs.contacts import PURSUER_EVADER, PURSUER_PURSUER
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.render import render_rgb
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.envs.workers import ProcessCore

CONT = [  # scripted evaders (tests/test_learned_evader.py has the learned one)
    name
    for name in scenario_names()
    if name.startswith("phys_cont") and load_scenario(name).evader != "learned"
]
RIGHT, LEFT, UP, DOWN, STOP = (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0), (0.0, 0.0)
HEAD_ON = {"pursuer_0": (1.5, 2.5), "pursuer_1": (3.5, 2.5)}
AWAY = {"pursuer_2": (0.5, 4.5), "evader": (4.5, 4.5)}


def scene(positions, scenario="phys_cont_collision_continue", **overrides):
    """A continuous physics env with a static evader and agents placed explicitly."""
    env = make_env(scenario, evader="static", **overrides)
    env.reset(seed=0, options={"positions": positions})
    return env


def drive(env, plan):
    """Step ``plan`` (one (v0, v1, v2) per step) until the episode ends; per-step infos with
    the positions after the step."""
    steps = []
    for commands in plan:
        actions = {f"pursuer_{i}": np.array(v, np.float64) for i, v in enumerate(commands)}
        _, rewards, terms, truncs, infos = env.step(actions)
        info = {**infos["pursuer_0"], "reward": rewards["pursuer_0"]}
        info.update(terminated=terms["pursuer_0"], positions=env.game.core.positions()[0])
        steps.append(info)
        if terms["pursuer_0"] or truncs["pursuer_0"]:
            break
    return steps


def collision_steps(steps):
    return [s["t"] for s in steps if s["collisions"]]


def box_gap(positions, i, j, side=0.6):
    """Clearance between two pursuer boxes along the axis where they are farthest apart."""
    return float(np.abs(positions[i] - positions[j]).max() - side)


# --------------------------------------------------------------------------- configuration


def test_grid_mode_rejects_continuous_control_naming_the_key():
    with pytest.raises(ConfigError, match="key 'control'"):
        load_scenario("grid", {"control": "continuous"})


def test_the_control_period_defaults_by_control_type():
    assert load_scenario("phys").physics.dt == 1.0
    assert load_scenario("phys", {"control": "continuous"}).physics.dt == 0.1
    assert load_scenario("phys_cont", {"physics.dt": 0.05}).physics.dt == 0.05
    with pytest.raises(ConfigError, match=r"key 'physics\.dt'"):
        load_scenario("phys_cont", {"physics.dt": 0.0})


def test_the_substeps_bound_scales_with_the_control_period():
    # 2 m/s closing speed: 0.2 m per 0.1 s substep passes no 0.6 m body; 1 s would.
    assert load_scenario("phys_cont", {"physics.substeps": 1}).physics.substeps == 1
    with pytest.raises(ConfigError, match=r"key 'physics\.substeps'.*dt = 1 s"):
        load_scenario("phys_cont", {"physics.dt": 1.0, "physics.substeps": 2})


def test_action_spaces_are_boxes():
    env = make_env("phys_cont")
    space = env.action_space("pursuer_0")
    assert isinstance(space, gym.spaces.Box) and space.shape == (2,)
    assert space.dtype == np.float32 and (space.low == -1).all() and (space.high == 1).all()
    joint = gym.make(a2cm_phys.GYM_ID, scenario="phys_cont").action_space
    assert isinstance(joint, gym.spaces.Box) and joint.shape == (3, 2)


# --------------------------------------------------------------------------- commands


def test_full_speed_covers_max_speed_times_dt_per_step():
    env = scene({"pursuer_0": (0.5, 0.5), **AWAY, "pursuer_1": (4.5, 0.5)})
    ph = env.scenario.physics
    steps = drive(env, [(RIGHT, STOP, STOP)] * 5)
    xs = [0.5] + [s["positions"][0, 0] for s in steps]
    moved = np.diff(xs)
    assert moved[0] == pytest.approx(ph.max_speed * ph.dt * (1 - 1 / ph.substeps))
    np.testing.assert_allclose(moved[1:], ph.max_speed * ph.dt, rtol=1e-9)


def test_commands_outside_the_unit_disc_are_clipped_onto_it():
    placed = {"pursuer_0": (0.5, 0.5), **AWAY, "pursuer_1": (4.5, 0.5)}
    long, unit = scene(placed), scene(placed)
    a = drive(long, [((3.0, 4.0), (-9.0, 0.0), STOP)] * 6)
    b = drive(unit, [((0.6, 0.8), (-1.0, 0.0), STOP)] * 6)
    for sa, sb in zip(a, b, strict=True):
        np.testing.assert_array_equal(sa["positions"], sb["positions"])
    speed = np.hypot(*long.game.core.velocities()[0, 0])
    assert speed == pytest.approx(long.scenario.physics.max_speed)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_non_finite_command_raises_naming_the_agent(bad):
    env = make_env("phys_cont")
    env.reset(seed=0)
    actions = {a: np.zeros(2, np.float32) for a in env.agents}
    actions["pursuer_1"] = np.array([0.5, bad], np.float32)
    with pytest.raises(ValueError, match="pursuer_1"):
        env.step(actions)
    joint = gym.make(a2cm_phys.GYM_ID, scenario="phys_cont").unwrapped
    joint.reset(seed=0)
    with pytest.raises(ValueError, match="pursuer_2"):
        joint.step(np.array([[0, 0], [0, 0], [bad, 0]], np.float32))
    vec = VectorEnv(load_scenario("phys_cont"), 2)
    vec.reset(0)
    commands = np.zeros((2, 3, 2))
    commands[1, 0, 0] = bad
    with pytest.raises(ValueError, match="pursuer_0 in env 1"):
        vec.step(commands)


@pytest.mark.parametrize("value", [1, "up", (1.0, 2.0, 3.0), None])
def test_a_command_that_is_not_a_pair_raises_naming_the_agent(value):
    env = make_env("phys_cont")
    env.reset(seed=0)
    actions = {a: np.zeros(2, np.float32) for a in env.agents}
    actions["pursuer_2"] = value
    with pytest.raises(ValueError, match="pursuer_2"):
        env.step(actions)


def test_infos_carry_the_evader_command():
    env = make_env("phys_cont")
    env.reset(seed=3)
    _, _, _, _, infos = env.step({a: np.zeros(2, np.float32) for a in env.agents})
    vx, vy = infos["pursuer_0"]["evader_action"]
    assert np.hypot(vx, vy) == pytest.approx(0.8)  # the random evader's speed


# --------------------------------------------------------------------------- real contacts


def test_head_on_at_full_speed_is_one_collision_on_the_step_they_meet():
    steps = drive(scene({**HEAD_ON, **AWAY}), [(RIGHT, LEFT, STOP)] * 15)
    rw = load_scenario("phys_cont_collision_continue").rewards
    (hit,) = collision_steps(steps)
    before, after = steps[hit - 2]["positions"], steps[hit - 1]["positions"]
    assert box_gap(before, 0, 1) > 0.0 >= box_gap(after, 0, 1) - 0.01  # they met in that step
    assert steps[hit - 1]["events"] == [(PURSUER_PURSUER, "pursuer_0", "pursuer_1", hit)]
    assert steps[hit - 1]["reward"] == rw.step + rw.collision
    assert all(s["reward"] == rw.step for s in steps if s["t"] != hit)


def test_a_glancing_touch_is_one_collision_and_they_slide_past():
    placed = {"pursuer_0": (1.5, 2.5), "pursuer_1": (3.5, 3.08), **AWAY}  # 2 cm of overlap
    steps = drive(scene(placed), [(RIGHT, LEFT, STOP)] * 25)
    assert sum(s["collisions"] for s in steps) == 1
    end = steps[-1]["positions"]
    assert end[0, 0] > end[1, 0] + 0.6  # past each other: the corners only brushed


def test_pushing_each_other_along_a_wall_stays_one_collision():
    placed = {"pursuer_0": (0.5, 0.5), "pursuer_1": (1.5, 0.5), **AWAY}
    # pursuer_0 runs into the slower pursuer_1 and shoves it along the bottom wall
    steps = drive(scene(placed), [((1.0, -1.0), (0.3, -1.0), STOP)] * 40)
    assert sum(s["collisions"] for s in steps) == 1
    assert steps[-1]["positions"][1, 0] > 2.0  # pushed well along
    assert box_gap(steps[-1]["positions"], 0, 1) < 0.01  # and still touching


def test_three_pursuers_meeting_count_every_pair_once():
    placed = {**HEAD_ON, "pursuer_2": (2.5, 0.5), "evader": (4.5, 4.5)}
    steps = drive(scene(placed), [(RIGHT, LEFT, UP)] * 30)
    pairs = [(a, b) for s in steps for kind, a, b, _ in s["events"] if kind == PURSUER_PURSUER]
    assert sorted(pairs) == [
        ("pursuer_0", "pursuer_1"),
        ("pursuer_0", "pursuer_2"),
        ("pursuer_1", "pursuer_2"),
    ]
    assert sum(s["collisions"] for s in steps) == 3


def test_separating_and_touching_again_is_a_second_collision():
    plan = [(RIGHT, LEFT, STOP)] * 10 + [(LEFT, RIGHT, STOP)] * 5 + [(RIGHT, LEFT, STOP)] * 10
    steps = drive(scene({**HEAD_ON, **AWAY}), plan)
    first, second = collision_steps(steps)
    assert first <= 10 < 15 < second
    apart = [box_gap(s["positions"], 0, 1) for s in steps[first:second]]
    assert max(apart) > 0.3


def test_a_pursuer_touching_the_evader_captures():
    placed = {"pursuer_0": (1.5, 2.5), "pursuer_1": (4.5, 0.5), "pursuer_2": (0.5, 4.5)}
    steps = drive(scene({**placed, "evader": (2.5, 2.5)}), [(RIGHT, STOP, STOP)] * 20)
    last = steps[-1]
    assert last["terminated"] and last["captured"] and last["collisions"] == 0
    assert last["events"] == [(PURSUER_EVADER, "pursuer_0", "evader", last["t"])]
    assert 4 <= last["t"] <= 6  # 0.4 m of clearance at 1 m/s, one substep of lag


# --------------------------------------------------------------------------- determinism


def rollout(core, seeds, steps, rng_seed):
    """Random commands (some outside the unit disc) for ``steps``, restarting finished games;
    per step the positions and the outcome."""
    rng = np.random.default_rng(rng_seed)
    core.reset(np.arange(core.num_envs), seeds)
    trace = []
    for _ in range(steps):
        out = core.step(rng.uniform(-1.2, 1.2, (core.num_envs, core.scenario.pursuers, 2)))
        trace.append((core.positions(), out))
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, seeds[done] + np.uint64(1))
    return trace


@pytest.mark.parametrize("name", CONT)
def test_same_seed_and_commands_are_bit_identical_after_1000_steps(name):
    sc = load_scenario(name)
    seeds = np.arange(2, dtype=np.uint64) + np.uint64(5)
    a, b = (rollout(PhysicsCore(sc, 2), seeds, 1000, 3)[-1][0] for _ in range(2))
    np.testing.assert_array_equal(a, b)
    c = rollout(PhysicsCore(sc, 2), seeds + np.uint64(1), 1000, 3)[-1][0]
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("evader", ["random", "flee"])
def test_a_game_plays_the_same_in_any_batch(evader):
    """Game 5 of a batch of 8 is the game of its seed played alone (the evader's randomness
    and look-ahead are per game)."""
    sc = load_scenario("phys_cont", {"evader": evader})
    rng = np.random.default_rng(1)
    commands = rng.uniform(-1, 1, (150, 8, sc.pursuers, 2))
    seeds = np.arange(8, dtype=np.uint64) * np.uint64(77)
    batch, alone = PhysicsCore(sc, 8), PhysicsCore(sc, 1)
    batch.reset(np.arange(8), seeds)
    alone.reset(np.array([0]), seeds[5:6])
    for k, acts in enumerate(commands):
        out_b, out_a = batch.step(acts), alone.step(acts[5:6])
        np.testing.assert_array_equal(batch.positions()[5], alone.positions()[0], f"step {k}")
        np.testing.assert_array_equal(out_b.evader_action[5], out_a.evader_action[0])
        if out_a.terminated[0]:
            break


def test_process_core_equals_physics_core_with_continuous_commands():
    sc = load_scenario("phys_cont_flee")
    seeds = np.arange(5, dtype=np.uint64) * np.uint64(1000)
    with ProcessCore(sc, 5, 2) as split:
        theirs = rollout(split, seeds, 120, 1)
    ours = rollout(PhysicsCore(sc, 5), seeds, 120, 1)
    for (pos_a, out_a), (pos_b, out_b) in zip(theirs, ours, strict=True):
        np.testing.assert_array_equal(pos_a, pos_b)
        assert out_a.events == out_b.events
        np.testing.assert_array_equal(out_a.evader_action, out_b.evader_action)
        assert out_a.evader_action.shape == (5, 2)


# --------------------------------------------------------------------------- pursuit baseline


def test_pursuit_drives_every_pursuer_straight_at_the_evader():
    sc = load_scenario("phys_cont")
    positions = np.array([(0.5, 0.5), (4.5, 0.5), (2.5, 4.5), (2.5, 2.5)])
    commands = pursuit_actions(sc, positions)
    assert commands.dtype == np.float32 and commands.shape == (3, 2)
    np.testing.assert_allclose(commands, [(0.5**0.5, 0.5**0.5), (-(0.5**0.5), 0.5**0.5), DOWN])
    discrete = pursuit_actions(load_scenario("phys"), positions + np.array([(0.0, 0.4)] * 4))
    np.testing.assert_array_equal(discrete, [3, 2, 1])  # right (x on a tie), left, down
    grid = load_scenario("grid", {"actions": 5})
    cells = np.array([[(0, 0), (2, 1), (2, 2), (2, 1)]])
    np.testing.assert_array_equal(pursuit_actions(grid, cells), [[3, 4, 1]])  # batched


@pytest.mark.parametrize("name", ["phys_cont", "phys"])
def test_pursuit_catches_the_random_evader(name):
    sc = load_scenario(name)
    env = VectorEnv(sc, 4)
    env.reset(0)
    episodes = []
    for _ in range(sc.max_steps):
        episodes += env.step(pursuit_actions(sc, env.core.positions())).episodes
        if len(episodes) >= 4:
            break
    assert len(episodes) >= 4 and all(e.captured for e in episodes)


def test_frames_can_show_the_paths_taken():
    sc = load_scenario("phys_cont")
    core = PhysicsCore(sc, 1)
    core.reset(np.array([0]), np.array([2], dtype=np.uint64))
    trail = []
    for _ in range(20):
        trail.append(core.positions()[0])
        core.step(pursuit_actions(sc, core.positions()))
    plain = render_rgb(sc, core.positions()[0])
    traced = render_rgb(sc, core.positions()[0], trail=np.array(trail))
    assert plain.shape == traced.shape and (plain != traced).any(axis=-1).sum() > 100
