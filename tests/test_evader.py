"""Evader policies: uniform random moves, fleeing the nearest pursuer, standing still; and
their continuous forms (wandering, fleeing down a potential, static)."""

from __future__ import annotations

import numpy as np
import pytest

from a2cm_phys.config import load_scenario
from a2cm_phys.envs.evaders.continuous import FLEE_SPEED, RANDOM_SPEED, ContinuousEvader
from a2cm_phys.envs.evaders.scripted import Evader, evader_actions, flee_actions, random_actions


def test_random_evader_is_uniform_and_reproducible():
    seeds = np.arange(20_000, dtype=np.uint64)
    t = np.zeros(20_000, dtype=np.int64)
    acts = random_actions(seeds, t, 4)
    counts = np.bincount(acts, minlength=4)
    # chi-square with 3 dof: 16.27 is the 0.1% critical value
    expected = len(acts) / 4
    assert ((counts - expected) ** 2 / expected).sum() < 16.27
    np.testing.assert_array_equal(acts, random_actions(seeds, t, 4))
    assert not np.array_equal(acts, random_actions(seeds, t + 1, 4))


def test_flee_moves_away_from_the_nearest_pursuer():
    # evader at (2, 2), pursuers at (3, 2), (2, 3), (1, 3). Nearest distance after each move:
    # up (2, 3): 0; down (2, 1): min(2, 2, 3) = 2; left (1, 2): min(2, 2, 1) = 1; right: 0.
    evader = np.array([[2.0, 2.0]])
    pursuers = np.array([[[3.0, 2.0], [2.0, 3.0], [1.0, 3.0]]])
    for t in range(20):
        act = flee_actions(np.array([5], dtype=np.uint64), np.array([t]), evader, pursuers, 4, 0, 4)
        assert act[0] == 1


def test_flee_breaks_ties_uniformly():
    # pursuer straight above at (2, 4), evader at (2, 2): up 1, down 3, left 3, right 3
    evader = np.array([[2.0, 2.0]])
    pursuers = np.array([[[2.0, 4.0]]])
    seeds = np.arange(3000, dtype=np.uint64)
    acts = flee_actions(
        seeds,
        np.zeros(3000, dtype=np.int64),
        np.repeat(evader, 3000, 0),
        np.repeat(pursuers, 3000, 0),
        4,
        0,
        4,
    )
    counts = np.bincount(acts, minlength=4)
    assert counts[0] == 0
    assert all(900 < c < 1100 for c in counts[1:])


def test_static_evader_stays():
    sc = load_scenario("grid", {"evader": "static"})
    acts = evader_actions(
        sc, np.zeros(3, dtype=np.uint64), np.zeros(3, dtype=np.int64), None, None, 0, 4
    )
    np.testing.assert_array_equal(acts, [4, 4, 4])


@pytest.mark.parametrize("policy", ["random", "flee", "static"])
@pytest.mark.parametrize("num_envs, horizon", [(1, None), (5, 3), (5, 1), (64, None)])
def test_moves_computed_ahead_are_the_step_by_step_moves(policy, num_envs, horizon):
    """Games restarting at random times, and a forgotten look-ahead, change nothing."""
    sc = load_scenario("grid", {"evader": policy})
    evader = Evader(sc, num_envs, 0, 4, horizon)
    rng = np.random.default_rng(7)
    seed = rng.integers(0, 2**63, num_envs).astype(np.uint64)
    t = np.zeros(num_envs, dtype=np.int64)
    for step in range(150):
        xy = rng.integers(0, 5, (num_envs, sc.pursuers + 1, 2)).astype(np.float64)
        got = evader.moves(seed, t, xy[:, -1], xy[:, :-1])
        want = evader_actions(sc, seed, t, xy[:, -1], xy[:, :-1], 0, 4)
        np.testing.assert_array_equal(got, want, err_msg=f"step {step}")
        t += 1
        done = np.flatnonzero(rng.random(num_envs) < 0.15)
        seed[done] = rng.integers(0, 2**63, len(done)).astype(np.uint64)
        t[done] = 0
        evader.restart(done, seed[done])
        if step == 70:  # the owner changes its arrays behind the evader's back, and says so
            t += 1000
            evader.forget()


# --------------------------------------------------------------------------- continuous


def continuous(policy, num_envs, horizon=None, **overrides):
    sc = load_scenario("phys_cont", {"evader": policy, **overrides})
    r = sc.physics.evader_radius
    return sc, ContinuousEvader(sc, num_envs, r, sc.size - r, horizon)


def test_random_wander_keeps_its_speed_and_turns_a_bounded_angle():
    sc, evader = continuous("random", 500)
    seeds = np.arange(500, dtype=np.uint64)
    evader.restart(np.arange(500), seeds)
    xy = np.full((500, 2), sc.size / 2)  # in the open: no bounce
    headings = []
    for t in range(30):
        command = evader.moves(seeds, np.full(500, t), xy)
        np.testing.assert_allclose(np.hypot(*command.T), RANDOM_SPEED)
        headings.append(np.arctan2(command[:, 1], command[:, 0]))
    turns = np.angle(np.exp(1j * np.diff(np.stack(headings), axis=0)))
    assert np.abs(turns).max() <= evader.turn + 1e-9
    assert np.abs(turns).max() > 0.9 * evader.turn  # the bound is reached, not just respected
    first = np.mod(headings[0], 2 * np.pi)  # initial headings: uniform over the circle
    assert np.histogram(first, bins=4, range=(0, 2 * np.pi))[0].min() > 90


def test_random_wander_bounces_off_walls():
    sc, evader = continuous("random", 1)
    seed = np.array([3], dtype=np.uint64)
    evader.restart(np.array([0]), seed)
    evader.moves(seed, np.array([0]), np.array([[2.5, 2.5]]))
    evader.heading[:] = (1.0, 0.0)  # heading straight at the right wall, about to touch it
    command = evader.moves(seed, np.array([1]), np.array([[sc.size - 0.31, 2.5]]))
    assert command[0, 0] < 0


@pytest.mark.parametrize("policy", ["random", "flee", "static"])
@pytest.mark.parametrize("num_envs, horizon", [(1, None), (5, 3), (5, 1), (64, None)])
def test_continuous_commands_are_the_same_whatever_the_look_ahead(policy, num_envs, horizon):
    """The commands depend on each game's seed, step and positions only: not on the batch,
    the look-ahead horizon, or games restarting at random times."""
    sc, ahead = continuous(policy, num_envs, horizon)
    _, single = continuous(policy, num_envs, 1)
    rng = np.random.default_rng(9)
    seed = rng.integers(0, 2**63, num_envs).astype(np.uint64)
    t = np.zeros(num_envs, dtype=np.int64)
    for evader in (ahead, single):
        evader.restart(np.arange(num_envs), seed)
    for step in range(120):
        xy = rng.uniform(0.3, sc.size - 0.3, (num_envs, sc.pursuers + 1, 2))
        got = ahead.moves(seed, t, xy[:, -1], xy[:, :-1])
        want = single.moves(seed, t, xy[:, -1], xy[:, :-1])
        np.testing.assert_array_equal(got, want, err_msg=f"step {step}")
        t += 1
        done = np.flatnonzero(rng.random(num_envs) < 0.1)
        seed[done] = rng.integers(0, 2**63, len(done)).astype(np.uint64)
        t[done] = 0
        ahead.restart(done, seed[done])
        single.restart(done, seed[done])


def test_static_continuous_evader_commands_nothing():
    _, evader = continuous("static", 3)
    seeds = np.zeros(3, dtype=np.uint64)
    np.testing.assert_array_equal(evader.moves(seeds, np.zeros(3, dtype=np.int64)), 0.0)


def test_flee_runs_away_from_a_lone_pursuer_at_full_speed():
    sc, evader = continuous("flee", 200)
    rng = np.random.default_rng(0)
    me = np.full((200, 2), sc.size / 2)
    pursuer = me[:, None] + rng.normal(0, 1, (200, 1, 2)) * 0.8  # all around, not too close
    seeds = np.arange(200, dtype=np.uint64)
    command = evader.moves(seeds, np.zeros(200, dtype=np.int64), me, pursuer)
    np.testing.assert_allclose(np.hypot(*command.T), FLEE_SPEED)
    away = me - pursuer[:, 0]
    cos = (command * away).sum(-1) / np.hypot(*away.T) / FLEE_SPEED
    assert cos.min() > 0.8  # within ~37° of straight away (16 headings, walls 2.2 m off)


def test_flee_slides_along_a_wall_instead_of_into_it():
    """Pressed against the bottom wall by a pursuer coming straight down at it, the evader
    runs along the wall (either way), not into it or back at the pursuer."""
    _, evader = continuous("flee", 64)
    me = np.tile([2.5, 0.32], (64, 1))
    pursuer = np.tile([2.5, 1.4], (64, 1, 1))
    seeds = np.arange(64, dtype=np.uint64)
    command = evader.moves(seeds, np.zeros(64, dtype=np.int64), me, pursuer)
    assert (np.abs(command[:, 0]) > 0.9 * FLEE_SPEED).all()
    sides = np.sign(command[:, 0])
    assert (sides > 0).any() and (sides < 0).any()  # a seeded coin, not a fixed side
