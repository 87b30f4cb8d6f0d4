"""The ``search`` team (a2cm_phys.analysis.search): lawnmower paths that stay in their strips
and cover them, commands at the next waypoint, the chase after a sighting and its end,
memory per game, no reading of the global state, and short evaluations."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.search import search_policy, strip_bounds, sweep_waypoints
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.sensing import agent_slice, team_observation
from a2cm_phys.envs.vector import VectorEnv

ARENAS = [(5, 3), (10, 3), (8, 2), (20, 4), (4, 1), (6, 5)]  # (size, pursuers)


def pomdp(size=5, pursuers=3, **overrides):
    return load_scenario("phys_cont_pomdp", {"size": size, "pursuers": pursuers, **overrides})


def team(scenario, positions, blind=False):
    """Team vectors ``(B, team_dim)`` for positions ``(B, N + 1, 2)`` (metres, at rest), as
    the env builds them; ``blind``: as if no pursuer sensed the evader."""
    positions = np.asarray(positions, dtype=np.float64)
    b = len(positions)
    state = np.concatenate(
        [positions.reshape(b, -1) / scenario.size, np.zeros((b, positions[0].size))], axis=1
    ).astype(np.float32)
    obs = team_observation(scenario, state, positions)
    if blind:
        n = scenario.pursuers
        evader = 4 + (n - 1) * 5
        for i in range(n):
            start = agent_slice(scenario, i).start + evader
            obs[:, start : start + 5] = 0.0
    return obs


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def segment_distance(points, a, b):
    """Distances ``(P,)`` of ``points`` ``(P, 2)`` to the segment ``a``–``b``."""
    ab = b - a
    t = np.clip(((points - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def strip_points(scenario, low, high, step=0.05):
    xs = np.arange(low, high + 1e-9, step)
    ys = np.arange(0.0, scenario.size + 1e-9, step)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


@pytest.mark.parametrize(("size", "pursuers"), ARENAS)
def test_each_path_stays_in_its_strip_inside_the_walls_and_covers_it(size, pursuers):
    scenario = pomdp(size, pursuers)
    paths, strips = sweep_waypoints(scenario), strip_bounds(scenario)
    assert paths.shape[0] == strips.shape[0] == pursuers
    assert np.isclose(strips[0, 0], 0) and np.isclose(strips[-1, 1], size)
    inset = scenario.physics.box_side / 2
    # the pursuer turns within one step of a waypoint: the path covers with a step to spare
    reach = scenario.sensing.radius - scenario.physics.max_speed * scenario.physics.dt
    for path, (low, high) in zip(paths, strips, strict=True):
        assert np.all(path[:, 0] >= low - 1e-9) and np.all(path[:, 0] <= high + 1e-9)
        assert np.all(path >= inset - 1e-9) and np.all(path <= size - inset + 1e-9)
        points = strip_points(scenario, low, high)
        near = np.min([segment_distance(points, a, b) for a, b in itertools.pairwise(path)], axis=0)
        assert near.max() <= reach + 1e-9, f"strip [{low}, {high}] is not covered"


def test_wide_strips_get_several_lanes_and_narrow_ones_one():
    assert sweep_waypoints(pomdp(5, 3)).shape == (3, 2, 2)  # 1.67 m strips, one lane
    wide = sweep_waypoints(pomdp(20, 2))  # 10 m strips: 4 lanes, ~2.5 m apart
    assert wide.shape == (2, 8, 2)
    lanes = np.unique(wide[0, :, 0])
    assert len(lanes) == 4 and np.all(np.diff(lanes) < 2 * 1.5)


def test_commands_point_at_the_nearer_end_of_each_pursuers_strip():
    scenario = pomdp()
    policy = search_policy(scenario)
    start = [[0.5, 0.5], [4.5, 0.5], [0.5, 4.5], [4.5, 4.5]]  # evader 4 m from everyone
    actions = policy(team(scenario, [start]), np.random.default_rng(0))
    assert actions.shape == (1, 3, 2) and actions.dtype == np.float32
    # strips by x at the start: pursuer_0 (x 0.5) left, pursuer_2 (x 0.5) middle,
    # pursuer_1 (x 4.5) right; each heads for the nearer end of its strip's lane
    want = unit([[5 / 6 - 0.5, 0.3 - 0.5], [25 / 6 - 4.5, 0.3 - 0.5], [2.5 - 0.5, 4.7 - 4.5]])
    np.testing.assert_allclose(actions[0], want, atol=1e-6)


@pytest.mark.parametrize(("size", "pursuers"), [(10, 3), (5, 1), (6, 4)])
def test_a_kinematic_sweep_goes_through_the_path_reverses_and_covers_its_strip(size, pursuers):
    """Pursuers moved exactly by their commands (one step's travel each) go through their
    strip's waypoints in order, then back, each command aimed at the next waypoint."""
    scenario = pomdp(size, pursuers)
    policy, paths = search_policy(scenario), sweep_waypoints(scenario)
    rng = np.random.default_rng(0)
    n, m = pursuers, paths.shape[1]
    pos = np.column_stack([np.linspace(0.5, size - 0.5, n), np.full(n, size / 2)])
    evader = np.array([[size / 2, size / 2]])
    goals: list[list[int]] = [[] for _ in range(n)]
    trail = []
    for _ in range(int(2.2 * m * size / 0.1) + 100):
        cmd = policy(team(scenario, [np.vstack([pos, evader])], blind=True), rng)[0]
        assert np.all(np.abs(np.linalg.norm(cmd, axis=1) - 1) < 1e-5)
        for i in range(n):  # the waypoint of its strip (strip i: starts in x order) aimed at
            cos = (unit(paths[i] - pos[i]) * cmd[i]).sum(1)
            goal = int(np.argmax(cos))
            assert cos[goal] > 1 - 1e-5
            if not goals[i] or goals[i][-1] != goal:
                goals[i].append(goal)
        pos = pos + cmd * scenario.physics.max_speed * scenario.physics.dt
        trail.append(pos.copy())
    trail = np.array(trail)  # (T, N, 2)
    ping_pong = [*range(m), *range(m - 2, -1, -1), *range(1, m)]
    strips = strip_bounds(scenario)
    for i in range(n):
        first = goals[i][0]
        order = ping_pong if first == 0 else [m - 1 - g for g in ping_pong]
        assert goals[i][: len(order)] == order
        arrived = np.argmax(np.linalg.norm(trail[:, i] - paths[i, first], axis=1) <= 0.1)
        xs = trail[arrived:, i, 0]
        assert xs.min() >= strips[i, 0] - 0.1 and xs.max() <= strips[i, 1] + 0.1
        points = strip_points(scenario, *strips[i], step=0.1)
        near = np.full(len(points), np.inf)
        for chunk in np.array_split(trail[arrived:, i], 20):
            d = np.linalg.norm(points[:, None] - chunk[None], axis=-1).min(1)
            near = np.minimum(near, d)
        assert near.max() <= scenario.sensing.radius


def test_after_a_sighting_everyone_heads_at_it_then_resumes_the_sweep_when_it_is_cold():
    scenario = pomdp()
    policy = search_policy(scenario)
    rng = np.random.default_rng(0)
    pursuers = np.array([[0.5, 0.5], [4.5, 0.5], [0.5, 4.5]])
    before = policy(team(scenario, [np.vstack([pursuers, [4.5, 4.5]])]), rng)[0]
    # only pursuer_1 (at 4.5, 0.5) senses the evader at (4.5, 1.8): the team chases it
    sighting = np.array([4.5, 1.8])
    seen = team(scenario, [np.vstack([pursuers, sighting])])
    assert seen[0, agent_slice(scenario, 0)][-5] == 0 and seen[0, agent_slice(scenario, 1)][-5] == 1
    np.testing.assert_allclose(policy(seen, rng)[0], unit(sighting - pursuers), atol=1e-6)
    # out of everyone's sight: still at the last sighting, not at its true position
    gone = team(scenario, [np.vstack([pursuers, [2.5, 2.6]])])
    assert not any(gone[0, agent_slice(scenario, i)][-5] for i in range(3))
    np.testing.assert_allclose(policy(gone, rng)[0], unit(sighting - pursuers), atol=1e-6)
    # in view again, elsewhere: the new sighting
    moved = np.array([1.2, 4.5])
    now = policy(team(scenario, [np.vstack([pursuers, moved])]), rng)[0]
    np.testing.assert_allclose(now, unit(moved - pursuers), atol=1e-6)
    # pursuer_2 comes within reach of the sighting without the evader in view: the trail is
    # cold, the sweep resumes where it was (each heads for the waypoint it was heading for)
    cold = pursuers.copy()
    cold[2] = moved + np.array([0.3, 0.0])
    out = policy(team(scenario, [np.vstack([cold, [4.5, 4.5]])]), rng)[0]
    paths = sweep_waypoints(scenario)
    goals = [paths[0, 0], paths[2, 0], paths[1, 1]]  # as `before` aimed
    np.testing.assert_allclose(out, unit(np.array(goals) - cold), atol=1e-6)
    np.testing.assert_allclose(before, unit(np.array(goals) - pursuers), atol=1e-6)


def test_the_global_state_is_never_read():
    scenario = pomdp()
    env = VectorEnv(scenario, 4)
    obs = env.reset(7)
    honest, fooled = search_policy(scenario), search_policy(scenario)
    rng, noise = np.random.default_rng(0), np.random.default_rng(1)
    sightings = 0
    for _ in range(120):
        scrambled = obs.copy()
        scrambled[:, : scenario.state_dim] = noise.uniform(-3, 3, (4, scenario.state_dim))
        actions = honest(obs, rng)
        np.testing.assert_array_equal(fooled(scrambled, rng), actions)
        sightings += int(honest.sighted.sum())
        step = env.step(actions)
        obs = step.obs
        if step.episodes:
            ended = step.terminated | step.truncated
            honest.episodes_ended(ended)
            fooled.episodes_ended(ended)
    env.close()
    assert sightings > 0  # both modes were exercised


def test_episodes_ended_forgets_that_games_sweep_and_sighting_only():
    scenario = pomdp()
    rng = np.random.default_rng(0)
    pursuers = np.array([[0.5, 0.5], [4.5, 0.5], [0.5, 4.5]])
    far, near = np.vstack([pursuers, [4.5, 4.5]]), np.vstack([pursuers, [4.5, 1.8]])
    policy = search_policy(scenario)
    policy(team(scenario, [far, far]), rng)
    # both games advance pursuer_0 past its first waypoint, then sight the evader
    advanced = far.copy()
    advanced[0] = [5 / 6, 0.32]
    policy(team(scenario, [advanced, advanced]), rng)
    policy(team(scenario, [near, near]), rng)
    policy.episodes_ended(np.array([True, False]))
    blind = np.vstack([[[1.0, 2.0], [4.0, 2.0], [1.0, 3.0]], [[3.0, 4.5]]])
    out = policy(team(scenario, [blind, blind]), rng)
    fresh = search_policy(scenario)(team(scenario, [blind]), rng)
    np.testing.assert_array_equal(out[0], fresh[0])  # game 0: a new sweep from scratch
    np.testing.assert_allclose(out[1], unit([4.5, 1.8] - blind[:3]), atol=1e-6)  # still chasing


def test_scenarios_without_sensing_or_continuous_physics_are_refused_by_name():
    for name in ("phys_cont", "grid_pomdp", "phys"):
        with pytest.raises(ValueError, match=f"'{name}'"):
            search_policy(load_scenario(name))


@pytest.mark.parametrize(("size", "most"), [(5, 100), (10, 400)])
def test_a_short_evaluation_catches_the_evader(size, most):
    """Loose: a random team needs ~140 steps in the 5 m arena and ~590 (a quarter
    truncated) in the 10 m one; search ~24 and ~130."""
    scenario = pomdp(size)
    result = play(scenario, search_policy(scenario), 20, num_envs=10, seed=0)
    assert result.captured.mean() >= 0.8
    assert result.lengths.mean() < most
