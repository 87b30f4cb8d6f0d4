"""Evader policies: uniform random moves, fleeing the nearest pursuer, standing still."""

from __future__ import annotations

import numpy as np

from a2cm_phys.config import load_scenario
from a2cm_phys.envs.evader import evader_actions, flee_actions, random_actions


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
