"""Differential-drive pursuers (``physics.drive = "differential"``): the non-holonomic
constraint at every solver substep (pushes, pile-ups, walls and obstacles included), the
turn rate, the discrete turn-then-drive primitive, observations and spaces, determinism,
the direct (memory) path against pymunk's API, the process-split core, and the pursuit
reference steering by headings."""

from __future__ import annotations

import numpy as np
import pymunk
import pytest

from a2cm_phys import make_env
from a2cm_phys.analysis.baselines import pursuit_actions, steer
from a2cm_phys.analysis.policies import headings_from_obs, positions_from_obs, pursuit_policy
from a2cm_phys.config import load_scenario
from a2cm_phys.envs import chipmunk
from a2cm_phys.envs.drive import ALIGNED, lateral_speed
from a2cm_phys.envs.parallel import observation_space, state_space
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.rails import ACROSS
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.envs.workers import ProcessCore

UP, DOWN, LEFT, RIGHT, STAY = range(5)
LATERAL = 1e-9  # m/s: what the projection leaves across a heading is rounding, ~1e-16
STRAIGHT = {"pursuer_0": (1.5, 1.5), "pursuer_1": (3.5, 1.5), "pursuer_2": (2.5, 3.5)}
DISCRETE = {"control": "discrete", "physics.dt": 1.0, "physics.substeps": 10}


def heading(core: PhysicsCore) -> np.ndarray:
    """Each pursuer's heading angle (rad), ``(B, N)``."""
    h = core.headings()
    return np.arctan2(h[..., 1], h[..., 0])


def before_substeps(core: PhysicsCore, look) -> None:
    """Make ``core``'s direct stepping call ``look(world)`` just before every substep of
    every game (so after every earlier substep's projection)."""
    step = core._worlds._cp_step

    def looked(cp_space, dt):
        look(next(w for w in core._worlds if w.cp_space == cp_space))
        step(cp_space, dt)

    core._worlds._cp_step = looked


def watch_substeps(core: PhysicsCore, seen: list) -> None:
    """Record before every substep each pursuer's lateral speed, read through pymunk's own
    getters (independently of the memory path being checked)."""

    def look(world):
        for body in world.bodies[: core.scenario.pursuers]:
            v, u = np.array(body.velocity), np.array(body.rotation_vector)
            seen.append(float(lateral_speed(v, u)))

    before_substeps(core, look)


def pile_up_commands(core: PhysicsCore, rng: np.random.Generator, k: int) -> np.ndarray:
    """(forward, turn) commands: every pursuer steered at one point (pile-ups, pushes and
    head-on contacts), into the nearest wall every 40 steps, some at random."""
    n = core.scenario.pursuers
    target = np.array([2.5, 2.5]) if (k // 40) % 2 else np.array([0.0, 2.5])
    gap = target - core.positions()[:, :n]
    unit = gap / np.maximum(np.linalg.norm(gap, axis=-1, keepdims=True), 1e-9)
    actions = steer(core.scenario, unit, core.headings()).astype(np.float64)
    actions[:, :, 0] = np.maximum(actions[:, :, 0], 0.8)  # keep pushing while turning
    actions[1::3] = rng.uniform(-1.5, 1.5, (len(actions[1::3]), n, 2))  # also out of range
    return actions


@pytest.mark.parametrize("name", ["phys_diff", "phys_diff_obstacles"])
def test_no_sideways_velocity_after_any_substep_even_in_pile_ups(name):
    sc = load_scenario(name, {"collisions.mode": "off", "evader": "flee"})
    core = PhysicsCore(sc, 6)
    assert core._worlds.drive_addresses is not None  # the memory path is the one checked
    seen: list[float] = []
    watch_substeps(core, seen)
    rng = np.random.default_rng(0)
    core.reset(np.arange(6), np.arange(6, dtype=np.uint64))
    contacts = 0
    for k in range(240):
        out = core.step(pile_up_commands(core, rng, k))
        contacts += sum(len(e) for e in out.events)
        end = lateral_speed(core.velocities()[:, : sc.pursuers], core.headings())
        assert end.max() < LATERAL  # and after the last substep of the step
    assert len(seen) == 240 * sc.physics.substeps * 6 * sc.pursuers
    assert max(seen) < LATERAL
    assert contacts > 60  # pushes, collisions and wall (and obstacle) contacts happened
    assert np.abs(core.velocities()[:, : sc.pursuers]).max() > 0.1  # not all at rest


def test_no_sideways_velocity_with_discrete_moves_and_a_body_moves_only_along_its_heading():
    """Discrete primitives in a pile-up keep the constraint too; a pursuer driving free
    (no contact) moves exactly along its heading at every substep."""
    sc = load_scenario("phys_diff", {**DISCRETE, "evader": "static", "actions": 5})
    core = PhysicsCore(sc, 4)
    seen: list[float] = []
    watch_substeps(core, seen)
    core.reset(np.arange(4), np.arange(4, dtype=np.uint64))
    rng = np.random.default_rng(1)
    for _ in range(30):
        core.step(rng.integers(0, 5, (4, sc.pursuers)))
    assert len(seen) == 30 * 10 * 4 * sc.pursuers and max(seen) < LATERAL

    env = make_env("phys_diff", evader="static")
    env.reset(seed=0, options={"positions": {**STRAIGHT, "evader": (4.5, 4.5)}})
    core = env.game.core
    before = []
    body = core._worlds[0].bodies[0]
    before_substeps(core, lambda world: before.append((np.array(body.position), body.angle)))
    commands = [(1.0, 1.0), (1.0, -0.5), (0.5, 0.25)]
    for forward, turn in commands * 4:  # arcs: turning while driving
        action = np.array([forward, turn], dtype=np.float32)
        env.step({a: action for a in env.agents})
        assert not env.game.last.events[0]  # nothing touched
    positions = np.array([p for p, _ in before])
    angles = np.array([a for _, a in before])
    moves = np.diff(positions, axis=0)
    across = moves[:, 1] * np.cos(angles[:-1]) - moves[:, 0] * np.sin(angles[:-1])
    assert np.abs(moves).max() > 0.02 and np.abs(across).max() < 1e-12


@pytest.mark.parametrize("turn", [1.0, 0.5, -0.25])
def test_heading_changes_at_the_commanded_turn_rate(turn):
    sc = load_scenario("phys_diff", {"evader": "static"})
    core = PhysicsCore(sc, 1)
    core.reset(np.array([0]), np.array([0], dtype=np.uint64))
    rate = turn * sc.physics.max_turn_rate
    h = sc.physics.dt / sc.physics.substeps
    angles = []
    for _ in range(8):
        core.step(np.array([[[0.0, turn]] * 3]))
        angles.append(heading(core)[0])
    steps = np.diff(np.unwrap(np.array(angles), axis=0), axis=0)
    # From rest the first substep's position update precedes the servo's first solve.
    np.testing.assert_allclose(angles[0], rate * (sc.physics.dt - h), atol=1e-12)
    np.testing.assert_allclose(steps, rate * sc.physics.dt, atol=1e-12)
    np.testing.assert_allclose(core.positions()[0, :3], [(0.5, 0.5), (4.5, 0.5), (0.5, 4.5)])


def test_turn_and_forward_commands_are_clipped_per_component():
    sc = load_scenario("phys_diff", {"evader": "static"})
    cores = [PhysicsCore(sc, 1) for _ in range(2)]
    placed = [{**STRAIGHT, "evader": (4.5, 4.5)}]  # room to circle without touching
    for core, command in zip(cores, ([3.0, -7.0], [1.0, -1.0]), strict=True):
        core.reset(np.array([0]), np.array([0], dtype=np.uint64), placed)
        for _ in range(5):
            core.step(np.array([[command] * 3]))
    np.testing.assert_array_equal(cores[0].positions(), cores[1].positions())
    np.testing.assert_array_equal(cores[0].headings(), cores[1].headings())
    speed = np.linalg.norm(cores[0].velocities()[0, :3], axis=-1)
    np.testing.assert_allclose(speed, 1.0, atol=1e-6)  # full speed: not scaled onto a disc


def test_discrete_move_turns_to_its_heading_then_drives():
    """From heading 0, ``up`` turns a quarter turn at ``max_turn_rate`` (0.5 s), without
    moving, and drives only once aligned: 0.4 m in the rest of the 1 s period (the first
    driving substep starts from rest). ``stay`` stops; a half turn takes more than the
    period, which then ends without driving."""
    sc = load_scenario("phys_diff", {**DISCRETE, "evader": "static", "actions": 5})
    core = PhysicsCore(sc, 1)
    core.reset(np.array([0]), np.array([0], dtype=np.uint64))
    start = core.positions()[0, 0].copy()
    core.step(np.array([[UP, STAY, STAY]]))
    np.testing.assert_allclose(heading(core)[0, 0], np.pi / 2, atol=1e-12)
    np.testing.assert_allclose(core.positions()[0, 0] - start, (0.0, 0.4), atol=1e-12)
    np.testing.assert_allclose(heading(core)[0, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(core.velocities()[0, 1:3], 0.0, atol=1e-12)
    core.step(np.array([[UP, STAY, STAY]]))
    np.testing.assert_allclose(core.positions()[0, 0] - start, (0.0, 1.4), atol=1e-12)
    core.step(np.array([[STAY, STAY, STAY]]))
    np.testing.assert_allclose(core.velocities()[0, 0], 0.0, atol=1e-12)
    at = core.positions()[0, 0].copy()
    core.step(np.array([[RIGHT, STAY, STAY]]))  # a quarter turn clockwise, then 0.4 m
    np.testing.assert_allclose(heading(core)[0, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(core.positions()[0, 0] - at, (0.4, 0.0), atol=1e-12)
    at = core.positions()[0, 0].copy()
    core.step(np.array([[LEFT, STAY, STAY]]))  # a half turn takes the whole second
    np.testing.assert_allclose(abs(heading(core)[0, 0]), 0.9 * np.pi, atol=1e-12)
    # only the first substep's carry at the speed the last step ended at, then no drive
    np.testing.assert_allclose(core.positions()[0, 0] - at, (0.1, 0.0), atol=1e-12)
    np.testing.assert_allclose(core.velocities()[0, 0], 0.0, atol=1e-12)
    assert ALIGNED < 0.1


def test_observations_carry_the_headings_after_the_holonomic_layout():
    sc = load_scenario("phys_diff")
    n = sc.pursuers
    assert sc.state_dim == 4 * (n + 1) + 2 * n == 22
    core = PhysicsCore(sc, 3)
    core.reset(np.arange(3), np.arange(3, dtype=np.uint64))
    obs = core.observe()
    np.testing.assert_array_equal(obs[:, 16:], np.tile([1.0, 0.0], (3, n)))  # heading 0
    for _ in range(4):
        core.step(np.tile([0.5, 1.0], (3, n, 1)))
    obs = core.observe()
    np.testing.assert_array_equal(obs[:, 16:], core.headings().reshape(3, -1).astype(np.float32))
    np.testing.assert_array_equal(headings_from_obs(sc, obs), obs[:, 16:].reshape(3, n, 2))
    np.testing.assert_allclose(positions_from_obs(sc, obs), core.positions(), atol=1e-5)
    space = state_space(sc)
    assert space.contains(obs[0]) and (space.low[16:] == -1).all()
    assert state_space(load_scenario("phys_cont")).shape == (16,)
    sensed = load_scenario("phys_diff", {"sensing": {"radius": 2.0}})
    k = sensed.body_features
    assert k == 6 and sensed.obs_dim == k + n * (1 + k)
    env = make_env(sensed)
    observations, _ = env.reset(seed=0)
    me = observations["pursuer_0"]
    assert observation_space(sensed).contains(me)
    np.testing.assert_array_equal(me[4:6], (1.0, 0.0))  # its own heading
    evader = me[k + (1 + k) * (n - 1) :]  # mask bit, then the evader's features
    np.testing.assert_array_equal(evader[5:], 0.0)  # the evader has no heading


def rollout(core, steps: int, seed: int) -> list:
    """(forward, turn) commands or moves, games reset when they end and at random; per step
    positions, velocities, headings, observations and outcome."""
    sc, b, n = core.scenario, core.num_envs, core.scenario.pursuers
    rng = np.random.default_rng(seed)
    core.reset(np.arange(b), rng.integers(0, 2**63, b).astype(np.uint64))
    trace = []
    for _ in range(steps):
        if sc.continuous:
            actions = pursuit_actions(sc, core.positions(), core.headings()).astype(np.float64)
            actions[1::2] = rng.uniform(-1.5, 1.5, (len(actions[1::2]), n, 2))
        else:
            actions = rng.integers(0, sc.actions, (b, n))
        out = core.step(actions)
        trace.append((core.positions(), core.velocities(), core.headings(), core.observe(), out))
        done = np.flatnonzero(out.terminated | out.truncated | (rng.random(b) < 0.03))
        if len(done):
            core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
    return trace


def same(trace_a: list, trace_b: list) -> None:
    for (*arrays_a, out_a), (*arrays_b, out_b) in zip(trace_a, trace_b, strict=True):
        for a, b in zip(arrays_a, arrays_b, strict=True):
            np.testing.assert_array_equal(a, b)
        assert out_a.events == out_b.events
        for field in ("reward", "terminated", "collisions", "wall_contacts", "obstacle_contacts"):
            np.testing.assert_array_equal(getattr(out_a, field), getattr(out_b, field))


@pytest.mark.parametrize("name", ["phys_diff", "phys_diff_obstacles"])
def test_same_seed_same_trajectory_and_rebuilt_worlds_forget(name):
    sc = load_scenario(name)
    spared = PhysicsCore(sc, 4)
    while spared.build_spare() < 30:  # resets take worlds rebuilt ahead
        pass
    a, b = rollout(PhysicsCore(sc, 4), 200, 5), rollout(spared, 200, 5)
    # random starts rebuild the games' own worlds in place; fixed ones take the spares
    assert spared.spare_worlds == 30 if sc.start.random else spared.spare_worlds < 30
    same(a, b)


@pytest.mark.parametrize("overrides", [{}, DISCRETE])
def test_memory_path_equals_pymunks_api(overrides, monkeypatch):
    assert chipmunk.rotation_layout()
    sc = load_scenario("phys_diff_obstacles", {"collisions.mode": "penalize", **overrides})
    fast = PhysicsCore(sc, 5)
    assert fast._worlds.drive_addresses is not None
    ours = rollout(fast, 150, 3)
    monkeypatch.setattr(chipmunk, "DIRECT_CALLS", False)
    slow = PhysicsCore(sc, 5)
    assert slow._worlds.addresses is None and slow._worlds.drive_addresses is None
    assert all(w.drive_addresses is None for w in slow._worlds)
    same(ours, rollout(slow, 150, 3))


def test_a_wrong_rotation_layout_falls_back_to_the_body_calls(monkeypatch):
    """Where the angle offsets do not check out, the positions and velocities still go
    through memory but the drive takes the per-body calls, with the same numbers."""
    sc = load_scenario("phys_diff")
    ours = rollout(PhysicsCore(sc, 3), 60, 8)
    monkeypatch.setattr(chipmunk, "_ANGLE_AT", chipmunk._ANGLE_AT + 8)
    chipmunk.rotation_layout.cache_clear()
    try:
        assert not chipmunk.rotation_layout()
        core = PhysicsCore(sc, 3)
        assert core._worlds.addresses is not None and core._worlds.drive_addresses is None
        same(ours, rollout(core, 60, 8))
    finally:
        monkeypatch.undo()
        chipmunk.rotation_layout.cache_clear()
    assert chipmunk.rotation_layout()


def test_process_core_carries_the_headings():
    sc = load_scenario("phys_diff_obstacles")
    with ProcessCore(sc, 4, 2) as split:
        theirs = rollout(split, 80, 11)
    same(rollout(PhysicsCore(sc, 4), 80, 11), theirs)


def test_vector_env_state_and_load_state_replay_bit_for_bit():
    """A physics checkpoint restarts every game from the restored seed generator (SPEC §6c):
    two loads of one state continue identically, headings included."""
    sc = load_scenario("phys_diff")
    env = VectorEnv(sc, 3)
    env.reset(7)
    rng = np.random.default_rng(2)
    for _ in range(20):
        env.step(rng.uniform(-1, 1, (3, sc.pursuers, 2)))
    state = env.state()
    runs = []
    for _ in range(2):
        obs = env.load_state(state)
        trace = [obs]
        np.testing.assert_array_equal(obs[:, 16:], np.tile([1.0, 0.0], (3, 3)))  # restarted
        actions = np.random.default_rng(3).uniform(-1, 1, (40, 3, sc.pursuers, 2))
        for act in actions:
            step = env.step(act)
            trace += [step.obs, step.reward, env.core.headings()]
        runs.append(trace)
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_rebuilt_world_plays_as_a_world_never_used():
    """Nothing of an episode's turns carries into the next: the pursuers' shapes enter the
    new space already at heading 0 (else the space indexes them where they were turned)."""
    sc = load_scenario("phys_diff", {"evader": "static"})
    seeds = np.array([11, 22, 33], dtype=np.uint64)
    actions = np.random.default_rng(3).uniform(-1, 1, (60, 3, sc.pursuers, 2))
    used, fresh = PhysicsCore(sc, 3), PhysicsCore(sc, 3)
    used.reset(np.arange(3), seeds + np.uint64(1))
    for act in actions:
        used.step(act)
    traces = []
    for core in (used, fresh):
        core.reset(np.arange(3), seeds)
        traces.append([(core.step(a).events, core.positions(), core.headings()) for a in actions])
    for (ev_a, *arrays_a), (ev_b, *arrays_b) in zip(*traces, strict=True):
        assert ev_a == ev_b
        for a, b in zip(arrays_a, arrays_b, strict=True):
            np.testing.assert_array_equal(a, b)


def test_resets_start_every_pursuer_at_heading_zero_at_rest():
    sc = load_scenario("phys_diff")
    core = PhysicsCore(sc, 2)
    core.reset(np.arange(2), np.arange(2, dtype=np.uint64))
    for _ in range(10):
        core.step(np.tile([1.0, 1.0], (2, 3, 1)))
    core.reset(np.array([1]), np.array([5], dtype=np.uint64))
    np.testing.assert_array_equal(core.headings()[1], np.tile([1.0, 0.0], (3, 1)))
    world = core._worlds[1]
    for body, rail, pin in zip(world.bodies[:3], world.rails.bodies, world.rails.pins, strict=True):
        assert body.angle == 0.0 and body.angular_velocity == 0.0 and body.torque == 0.0
        assert body.velocity == (0.0, 0.0) and rail.position == body.position
        assert isinstance(pin, pymunk.PinJoint) and pin.max_bias == 0.0 and pin.b is body
        assert pin.anchor_a == (0.0, ACROSS) and pin.max_force == float("inf")
    assert np.isfinite(world.bodies[0].moment) and world.bodies[3].moment == float("inf")


def test_pursuit_turns_towards_the_evader_then_drives_and_catches_it():
    sc = load_scenario("phys_diff", {"evader": "static"})
    ahead = steer(sc, np.array([[1.0, 0.0]]), np.array([[1.0, 0.0]]))
    behind = steer(sc, np.array([[-1.0, 0.0]]), np.array([[0.0, 1.0]]))
    np.testing.assert_allclose(ahead, [[1.0, 0.0]])  # facing it: full speed, no turn
    np.testing.assert_allclose(behind, [[0.0, 1.0]])  # 90° off: turn left, no drive
    with pytest.raises(ValueError, match="headings"):
        pursuit_actions(sc, np.zeros((4, 2)))
    env = VectorEnv(sc, 4)
    obs = env.reset(0)
    policy, rng, lengths = pursuit_policy(sc), np.random.default_rng(0), []
    for _ in range(200):
        step = env.step(policy(obs, rng))
        obs = step.obs
        lengths += step.episodes.length.tolist() if len(step.episodes) else []
    assert len(lengths) >= 20 and np.mean(lengths) < 40  # 100 steps = 10 s
