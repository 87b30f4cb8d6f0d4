"""Physics mode on real pymunk scenes: contacts → penalties first, then motion, placement,
determinism, the process-split core and the public API conformance suites."""

from __future__ import annotations

import os
import signal
from functools import partial

import numpy as np
import pymunk
import pytest

from a2cm_phys import make_env
from a2cm_phys.config import load_scenario, scenario_names
from a2cm_phys.envs import chipmunk, physics
from a2cm_phys.envs.contacts import AGENT_WALL, PURSUER_EVADER, PURSUER_PURSUER
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.envs.workers import ProcessCore, WorkerError
from a2cm_phys.envs.world import World, pair_table

UP, DOWN, LEFT, RIGHT, STAY = range(5)
PHYS = [name for name in scenario_names() if name.startswith("phys")]
CONTINUE = load_scenario("phys_collision_continue")
HEAD_ON = {"pursuer_0": (1.5, 2.5), "pursuer_1": (3.5, 2.5)}
AWAY = {"pursuer_2": (0.5, 4.5), "evader": (4.5, 4.5)}  # far from the action


def scene(positions, scenario="phys_collision_continue", **overrides):
    """A physics env with a stay action and a static evader, agents placed explicitly."""
    env = make_env(scenario, actions=5, evader="static", **overrides)
    env.reset(seed=0, options={"positions": positions})
    return env


def drive(env, plan):
    """Step ``plan`` (one (a0, a1, a2) per step) until the episode ends; per-step infos."""
    steps = []
    for acts in plan:
        _, rewards, terms, truncs, infos = env.step({f"pursuer_{i}": a for i, a in enumerate(acts)})
        steps.append({**infos["pursuer_0"], "reward": rewards["pursuer_0"]})
        steps[-1]["terminated"] = terms["pursuer_0"]
        if terms["pursuer_0"] or truncs["pursuer_0"]:
            break
    return steps


def collision_steps(steps):
    return [s["t"] for s in steps if s["collisions"]]


# --------------------------------------------------------------------------- contacts


def test_head_on_is_one_collision_penalised_on_its_step():
    steps = drive(scene({**HEAD_ON, **AWAY}), [(RIGHT, LEFT, STAY)] * 3)
    rw = CONTINUE.rewards
    assert collision_steps(steps) == [1]
    assert steps[0]["events"] == [(PURSUER_PURSUER, "pursuer_0", "pursuer_1", 1)]
    assert steps[0]["reward"] == rw.step + rw.collision
    assert [s["reward"] for s in steps[1:]] == [rw.step] * 2


def test_pushing_against_each_other_stays_one_collision():
    steps = drive(scene({**HEAD_ON, **AWAY}), [(RIGHT, LEFT, STAY)] * 40)
    assert sum(s["collisions"] for s in steps) == 1


def test_separating_and_touching_again_is_a_second_collision():
    plan = [(RIGHT, LEFT, STAY)] * 2 + [(LEFT, RIGHT, STAY)] + [(RIGHT, LEFT, STAY)] * 3
    steps = drive(scene({**HEAD_ON, **AWAY}), plan)
    first, second = collision_steps(steps)
    assert first == 1 and second > 3  # apart in step 3, touching again on the way back


def test_three_pursuers_meeting_count_every_pair_once():
    # 0 and 1 meet head-on, then 2 comes up from below into both of them.
    placed = {**HEAD_ON, "pursuer_2": (2.5, 0.5), "evader": (4.5, 4.5)}
    steps = drive(scene(placed), [(RIGHT, LEFT, UP)] * 8)
    pairs = [(a, b) for s in steps for kind, a, b, _ in s["events"] if kind == PURSUER_PURSUER]
    assert sorted(pairs) == [
        ("pursuer_0", "pursuer_1"),
        ("pursuer_0", "pursuer_2"),
        ("pursuer_1", "pursuer_2"),
    ]
    assert sum(s["collisions"] for s in steps) == 3


def test_a_jam_in_a_corner_is_counted_at_its_begin_only():
    placed = {"pursuer_0": (0.5, 0.5), "pursuer_1": (1.5, 0.5), "pursuer_2": (0.5, 1.5)}
    steps = drive(scene({**placed, "evader": (4.5, 4.5)}), [(LEFT, LEFT, DOWN)] * 30)
    assert collision_steps(steps) == [1]
    assert steps[0]["collisions"] == 3  # all three boxes squeezed together at once


def test_pursuer_touching_the_evader_captures_and_terminates():
    placed = {"pursuer_0": (1.5, 2.5), "pursuer_1": (4.5, 0.5), "pursuer_2": (0.5, 4.5)}
    steps = drive(scene({**placed, "evader": (2.5, 2.5)}), [(RIGHT, STAY, STAY)] * 3)
    assert len(steps) == 1 and steps[0]["terminated"] and steps[0]["captured"]
    assert steps[0]["events"] == [(PURSUER_EVADER, "pursuer_0", "evader", 1)]
    assert steps[0]["collisions"] == 0


def test_pursuer_against_a_wall_is_recorded_not_a_collision():
    wall = -7.0
    env = scene({"pursuer_0": (0.5, 2.5), **AWAY}, **{"rewards.wall": wall})
    steps = drive(env, [(LEFT, STAY, STAY)] * 5)
    rw = CONTINUE.rewards
    assert steps[0]["events"] == [(AGENT_WALL, "pursuer_0", "wall", 1)]
    assert steps[0]["reward"] == rw.step + wall and steps[0]["wall_contacts"] == 1
    assert all(s["collisions"] == 0 for s in steps)
    assert [s["reward"] for s in steps[1:]] == [rw.step] * 4  # the push is one contact


@pytest.mark.parametrize(
    ("scenario", "penalised", "terminates"),
    [
        ("phys", False, False),
        ("phys_collision", True, True),
        ("phys_collision_continue", True, False),
    ],
)
def test_collision_modes(scenario, penalised, terminates):
    rw = load_scenario(scenario).rewards
    steps = drive(scene({**HEAD_ON, **AWAY}, scenario), [(RIGHT, LEFT, STAY)] * 3)
    assert steps[0]["collisions"] == 1 and steps[0]["terminated"] is terminates
    assert steps[0]["reward"] == rw.step + (rw.collision if penalised else 0.0)
    assert len(steps) == (1 if terminates else 3)


# --------------------------------------------------------------------------- motion


def test_full_speed_crosses_one_cell_per_step():
    env = scene({"pursuer_0": (0.5, 0.5), "pursuer_1": (4.5, 4.5), "pursuer_2": (0.5, 4.5)})
    core, ph = env.game.core, CONTINUE.physics
    xs = [core.positions()[0, 0, 0]]
    for _ in range(4):
        env.step({"pursuer_0": RIGHT, "pursuer_1": STAY, "pursuer_2": STAY})
        xs.append(core.positions()[0, 0, 0])
    moved = np.diff(xs)
    # From rest the servo needs one substep to reach full speed, then it holds it.
    assert moved[0] == pytest.approx(ph.max_speed * (1 - 1 / ph.substeps))
    np.testing.assert_allclose(moved[1:], ph.max_speed, rtol=1e-9)
    np.testing.assert_allclose(core.velocities()[0, 0], (ph.max_speed, 0.0), rtol=1e-9)
    obs = env.state()
    n = CONTINUE.pursuers + 1
    assert obs.dtype == np.float32
    np.testing.assert_allclose(obs[: 2 * n], core.positions()[0].ravel() / CONTINUE.size, rtol=1e-6)
    np.testing.assert_allclose(obs[2 * n :], core.velocities()[0].ravel() / ph.max_speed)


def test_start_positions_are_the_grid_cells_centres():
    env = make_env("phys")
    env.reset(seed=0)
    np.testing.assert_array_equal(
        env.game.core.positions()[0], [(0.5, 0.5), (4.5, 0.5), (0.5, 4.5), (2.5, 2.5)]
    )


@pytest.mark.parametrize(
    ("positions", "message"),
    [
        ({"pursuer_0": (0.2, 2.5)}, "pursuer_0"),  # box into the wall
        ({"evader": (2.5, 4.9)}, "evader"),
        ({"pursuer_1": (6.0, 1.0)}, "pursuer_1"),
        ({"pursuer_0": (2.0, 2.3)}, "pursuer_0 .* evader .* overlap"),
        ({"pursuer_0": (1.0, 1.0), "pursuer_2": (1.5, 1.3)}, "pursuer_0 .* pursuer_2 .* overlap"),
        ({"pursuer_2": (1.0, "x")}, "pursuer_2"),
    ],
)
def test_invalid_positions_name_the_agent(positions, message):
    env = make_env("phys")
    with pytest.raises(ValueError, match=message):
        env.reset(options={"positions": positions})


def test_touching_but_not_overlapping_is_a_valid_placement():
    side = CONTINUE.physics.box_side
    env = scene({"pursuer_0": (1.0, 1.0), "pursuer_1": (1.0 + side, 1.0), **AWAY})
    np.testing.assert_array_equal(env.game.core.positions()[0, 1], (1.0 + side, 1.0))


def test_substeps_that_would_let_bodies_pass_through_each_other_are_refused():
    with pytest.raises(ValueError, match=r"physics\.substeps"):
        PhysicsCore(load_scenario("phys", {"physics.substeps": 1}), 1)


# --------------------------------------------------------------------------- determinism


def rollout(core, seeds, steps, rng_seed):
    """Random pursuer actions for ``steps``, restarting finished games with ``seeds``;
    per step the positions, the observations (after any restart) and the outcome."""
    rng = np.random.default_rng(rng_seed)
    core.reset(np.arange(core.num_envs), seeds)
    trace = []
    for _ in range(steps):
        out = core.step(rng.integers(0, 4, (core.num_envs, core.scenario.pursuers)))
        positions = core.positions()
        done = np.flatnonzero(out.terminated | out.truncated)
        if len(done):
            core.reset(done, seeds[done] + np.uint64(1))
        trace.append((positions, core.observe(), out))
    return trace


def test_same_seed_and_actions_are_bit_identical_after_1000_steps():
    sc = load_scenario("phys_flee")
    seeds = np.arange(2, dtype=np.uint64) + np.uint64(5)
    a, b = (rollout(PhysicsCore(sc, 2), seeds, 1000, 3)[-1][0] for _ in range(2))
    np.testing.assert_array_equal(a, b)


def test_reset_rebuilds_the_world():
    """An episode replays bit for bit whatever the game went through before its reset."""
    sc = load_scenario("phys_collision_continue", {"evader": "flee"})
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 4, (60, 1, sc.pursuers))
    fresh, used = PhysicsCore(sc, 1), PhysicsCore(sc, 1)
    for acts in rng.integers(0, 4, (37, 1, sc.pursuers)):  # bumps, pushes, contacts
        used.step(acts)
    seed = np.array([9], dtype=np.uint64)
    traces = []
    for core in (fresh, used):
        core.reset(np.array([0]), seed)
        traces.append([(core.step(acts).events, core.positions()) for acts in actions])
    for (ev_a, pos_a), (ev_b, pos_b) in zip(*traces, strict=True):
        assert ev_a == ev_b
        np.testing.assert_array_equal(pos_a, pos_b)


def play_world(world, actions):
    """Drive a :class:`World` directly (every agent, evader included, follows
    ``actions``); per step each body's position and velocity and the new contacts."""
    velocity = [tuple(map(float, v)) for v in physics.ACTION_DELTAS]
    trace = []
    for step, row in enumerate(actions.tolist(), start=1):
        for control, a in zip(world.controls, row, strict=True):
            control.velocity = velocity[a]
        for _ in range(10):
            world.step(0.1)
        state = [(*b.position, *b.velocity) for b in world.bodies]
        trace.append((state, world.tracker.end_step(step)))
    return trace


def test_a_rebuilt_world_is_a_new_world():
    """One world rebuilt after episodes of pile-ups, pushes and captures plays every episode
    exactly as a world that was never used: nothing (contact cache, servo impulses, the
    solver's position correction) carries over."""
    sc = load_scenario("phys_collision_continue")
    table, start = pair_table(sc), physics.start_positions(sc)
    rng = np.random.default_rng(4)
    recycled = World(sc, start, table)
    for episode in range(60):
        actions = rng.integers(0, 5, (int(rng.integers(1, 30)), sc.pursuers + 1))
        if episode % 3 == 0:  # everyone the same way: a pile-up against a wall
            actions[:] = rng.integers(0, 4)
        recycled.rebuild(start)
        assert play_world(recycled, actions) == play_world(World(sc, start, table), actions), (
            f"episode {episode}"
        )


def test_servos_read_only_the_control_bodies_velocity():
    """The control bodies stay outside the space, so their positions never move: the servo
    joints must not depend on them (anchors at the centres, max_bias = 0)."""
    sc = load_scenario("phys_collision_continue")
    table, start = pair_table(sc), physics.start_positions(sc)
    actions = np.random.default_rng(5).integers(0, 5, (40, sc.pursuers + 1))
    actions[:15] = RIGHT  # a pile-up against the right wall first
    moved = World(sc, start, table)
    assert all(control.space is None for control in moved.controls)
    for i, control in enumerate(moved.controls):
        control.position = (40.0 + i, -7.0 * i)  # far from the bodies they drive
    assert play_world(moved, actions) == play_world(World(sc, start, table), actions)


def test_worlds_built_ahead_are_the_same_as_worlds_built_at_reset():
    sc = load_scenario("phys_flee")
    seeds = np.arange(4, dtype=np.uint64) + np.uint64(70)
    ahead = PhysicsCore(sc, 4)
    while ahead.build_spare() < 50:  # more than the rollout's resets: every one uses a spare
        pass
    traces = [rollout(core, seeds, 150, 6) for core in (ahead, PhysicsCore(sc, 4))]
    assert ahead.spare_worlds < 50  # spares were used
    for (pos_a, obs_a, out_a), (pos_b, obs_b, out_b) in zip(*traces, strict=True):
        np.testing.assert_array_equal(pos_a, pos_b)
        np.testing.assert_array_equal(obs_a, obs_b)
        assert out_a.events == out_b.events


def test_direct_calls_are_bit_identical_to_pymunks_api(monkeypatch):
    sc = load_scenario("phys_collision_continue", {"evader": "flee"})
    seeds = np.arange(3, dtype=np.uint64) + np.uint64(40)
    fast_core = PhysicsCore(sc, 3)
    world = fast_core._worlds[0]
    direct = [world.step.func, world.steering[0].func, *(p.func for p in world.probes[::4])]
    cp = pymunk.cp
    assert direct == [
        cp.cpSpaceStep,
        cp.cpBodySetVelocity,
        cp.cpBodyGetPosition,
        cp.cpBodyGetVelocity,
    ]
    # The contact callbacks find their shapes without pymunk's Arbiter.shapes.
    lookups = []
    shapes = pymunk.Arbiter.shapes
    counted = property(lambda arbiter: lookups.append(1) or shapes.fget(arbiter))
    monkeypatch.setattr(pymunk.Arbiter, "shapes", counted)
    fast = rollout(fast_core, seeds, 300, 2)
    assert sum(len(game) for _, _, out in fast for game in out.events) > 20
    assert not lookups
    monkeypatch.setattr(chipmunk, "DIRECT_CALLS", False)
    slow_core = PhysicsCore(sc, 3)
    assert not isinstance(slow_core._worlds[0].step, partial)  # pymunk's own Space.step
    slow = rollout(slow_core, seeds, 300, 2)
    assert lookups
    for (pos_a, _, out_a), (pos_b, _, out_b) in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(pos_a, pos_b)
        assert out_a.events == out_b.events


@pytest.mark.parametrize(("name", "workers"), [("phys_flee", 2), ("phys", 1), ("phys", 3)])
def test_process_core_equals_physics_core_step_for_step(name, workers):
    """Whether this process steps every game (1), or a slice beside one or two workers; in
    ``phys`` every slice restarts games, this process's from the spares it built."""
    sc = load_scenario(name)
    seeds = np.arange(6, dtype=np.uint64) * np.uint64(1000)
    with ProcessCore(sc, 6, workers) as split:
        assert len(split._procs) == workers - 1
        theirs = rollout(split, seeds, 80, 1)
        t_split = split.t.copy()
        if workers > 1:  # this process built spares for its slice while the workers stepped
            assert split._own.spare_worlds > 0
    single = PhysicsCore(sc, 6)
    ours = rollout(single, seeds, 80, 1)
    np.testing.assert_array_equal(t_split, single.t)
    for (pos_a, obs_a, out_a), (pos_b, obs_b, out_b) in zip(theirs, ours, strict=True):
        np.testing.assert_array_equal(pos_a, pos_b)
        np.testing.assert_array_equal(obs_a, obs_b)
        assert out_a.events == out_b.events
        for field in ("reward", "terminated", "truncated", "captured", "collisions"):
            np.testing.assert_array_equal(getattr(out_a, field), getattr(out_b, field))


def test_process_core_shares_its_memory_with_spawned_workers_too():
    """The shared arrays reach workers started by ``spawn`` (pickled, not inherited)."""
    sc = load_scenario("phys_flee")
    seeds = np.arange(3, dtype=np.uint64) + np.uint64(90)
    with ProcessCore(sc, 3, 2, start_method="spawn") as split:
        theirs = rollout(split, seeds, 20, 4)
    ours = rollout(PhysicsCore(sc, 3), seeds, 20, 4)
    for (pos_a, obs_a, out_a), (pos_b, obs_b, out_b) in zip(theirs, ours, strict=True):
        np.testing.assert_array_equal(pos_a, pos_b)
        np.testing.assert_array_equal(obs_a, obs_b)
        np.testing.assert_array_equal(out_a.reward, out_b.reward)
        assert out_a.events == out_b.events


def test_process_core_places_agents_like_physics_core():
    """Placed resets in both workers' games, and a placement that a later plain reset of
    the same game (before any step) overrides, as in one process."""
    sc = load_scenario("phys_collision_continue")
    placed = {"pursuer_0": (2.5, 1.5), "evader": (2.5, 2.5)}
    requests = [
        (np.array([0, 3]), np.array([5, 6], dtype=np.uint64), [placed, placed]),
        (np.array([1]), np.array([7], dtype=np.uint64), [HEAD_ON]),
        (np.array([1, 2]), np.array([8, 9], dtype=np.uint64), None),  # drops game 1's
    ]
    rng = np.random.default_rng(2)
    actions = rng.integers(0, 4, (25, 4, sc.pursuers))
    traces = []
    for core in (ProcessCore(sc, 4, 2), PhysicsCore(sc, 4)):
        for envs, seeds, where in requests:
            core.reset(envs, seeds, where)
        trace = [core.positions()]
        for step, acts in enumerate(actions):
            out = core.step(acts)
            trace.append((core.positions(), out.events, out.reward))
            if step == 10:  # and once more between steps
                core.reset(np.array([2]), np.array([11], dtype=np.uint64), [HEAD_ON])
                trace.append(core.positions())
        if isinstance(core, ProcessCore):
            core.close()
        traces.append(trace)
    np.testing.assert_array_equal(traces[0][0][1], physics.start_positions(sc))  # overridden
    np.testing.assert_array_equal(traces[0][0][3, [0, -1]], [(2.5, 1.5), (2.5, 2.5)])
    for a, b in zip(*traces, strict=True):
        if isinstance(a, tuple):
            np.testing.assert_array_equal(a[0], b[0])
            assert a[1] == b[1]
            np.testing.assert_array_equal(a[2], b[2])
        else:
            np.testing.assert_array_equal(a, b)


def test_vector_env_with_workers_equals_one_process():
    sc = load_scenario("phys_collision")
    rng = np.random.default_rng(0)
    actions = rng.integers(0, sc.actions, (60, 4, sc.pursuers))
    runs = []
    for workers in (1, 2):
        env = VectorEnv(sc, 4, workers=workers)
        obs = [env.reset(seed=3)]
        episodes = []
        for acts in actions:
            out = env.step(acts)
            obs.append(out.obs)
            episodes += out.episodes
        env.close()
        runs.append((np.stack(obs), episodes))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][1] == runs[1][1] and runs[0][1]  # the same finished episodes, some


def test_process_core_stops_a_worker_that_does_not_answer():
    sc = load_scenario("phys")
    with pytest.raises(ValueError, match="timeout"):
        ProcessCore(sc, 2, 2, timeout=0)
    core = ProcessCore(sc, 4, 2, timeout=60)  # starting may take long on a loaded machine
    try:
        actions = np.zeros((4, sc.pursuers), dtype=np.int64)
        core.step(actions)
        core.timeout = 0.5
        hung = core._procs[0]  # worker 1: this process steps slice 0
        os.kill(hung.pid, signal.SIGSTOP)  # alive, but it will never answer
        with pytest.raises(WorkerError, match=r"worker 1 .* did not answer within 0.5 s"):
            core.step(actions)
        assert not hung.is_alive()  # killed: SIGTERM stays pending while it is stopped
        with pytest.raises(WorkerError, match="closed"):
            core.step(actions)
    finally:
        core.close()


def test_process_core_reports_bad_positions_and_worker_death():
    sc = load_scenario("phys")
    core = ProcessCore(sc, 4, 2)
    try:
        core.step(np.zeros((4, sc.pursuers), dtype=np.int64))
        bad = [{"pursuer_0": (1.5, 1.5)}, {"pursuer_0": (0.0, 0.0)}]  # games 0 and 3: 2nd bad
        with pytest.raises(ValueError, match=r"pursuer_0.*off the arena"):
            core.reset(np.array([0, 3]), np.array([1, 2], dtype=np.uint64), bad)
        assert core.t.tolist() == [1] * 4  # no game was restarted
        core.step(np.zeros((4, sc.pursuers), dtype=np.int64))  # still usable
        core._procs[0].kill()  # worker 1: this process steps slice 0
        with pytest.raises(WorkerError, match=r"worker 1 .* died"):
            core.step(np.zeros((4, sc.pursuers), dtype=np.int64))
    finally:
        core.close()
