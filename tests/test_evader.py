"""Evader policies: uniform random moves, fleeing the nearest pursuer, standing still."""

from __future__ import annotations

import numpy as np
import pytest

from a2cm_phys.config import load_scenario
from a2cm_phys.envs.evader import Evader, evader_actions, flee_actions, random_actions


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
