"""Shortest paths over the free cells (:mod:`a2cm_phys.envs.paths`): the path lengths are
scipy's shortest paths on the same graph, and the distance around obstacles is never
shorter than the straight one, equals it by the evader, and goes round a wall."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import lil_matrix
from scipy.sparse.csgraph import shortest_path

from a2cm_phys.algos.shaping import ProgressShaping
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.paths import around_obstacles, path_lengths
from a2cm_phys.envs.starts import random_starts


@pytest.mark.parametrize("name", ["grid_obstacles", "phys_diff_obstacles", "phys_diff10_obstacles"])
def test_path_lengths_are_scipys_shortest_paths(name: str) -> None:
    sc = load_scenario(name)
    size, blocked = sc.size, sc.blocked_cells()
    graph = lil_matrix((size * size, size * size))
    for c in range(size * size):  # an edge into every free neighbour, from any cell
        x, y = c % size, c // size
        for dx, dy in ((0, 1), (0, -1), (-1, 0), (1, 0)):
            if 0 <= x + dx < size and 0 <= y + dy < size:
                d = x + dx + size * (y + dy)
                if not blocked[d]:
                    graph[c, d] = 1
    expected = shortest_path(graph.tocsr(), unweighted=True)
    expected = np.where(np.isinf(expected), -1, expected).astype(np.int64)
    np.testing.assert_array_equal(path_lengths(sc), expected)
    into = path_lengths(sc)[:, blocked]  # never entered, but left (from an agent beside one)
    assert blocked.any() and (into[~np.eye(size * size, dtype=bool)[:, blocked]] == -1).all()
    assert (path_lengths(sc)[blocked] >= 0).sum() > blocked.sum()


def test_the_distance_around_obstacles() -> None:
    sc = load_scenario("phys_diff_obstacles")  # boxes on cells (1, 2) and (3, 2)
    xy = random_starts(sc, np.arange(2000, dtype=np.uint64))
    around = around_obstacles(sc, xy)
    straight = np.linalg.norm(xy[:, :-1] - xy[:, -1:], axis=-1)
    assert (around >= straight - 1e-12).all() and (around > straight + 0.5).any()
    # the evader in cell (1, 3), above the left box: from cell (2, 2), up to (2, 3)'s
    # centre and one step; from under the box, out to (0, 1) or (2, 1) and three steps
    game = np.array([[(2.5, 2.4), (1.5, 1.5), (0.5, 0.5), (1.5, 3.5)]])
    d = around_obstacles(sc, game)[0]
    np.testing.assert_allclose(d, [1.1 + 1, 1.0 + 3, 1.0 + 3])
    beside = np.array([[(2.5, 3.4), (1.5, 1.5), (0.5, 0.5), (1.5, 3.5)]])
    assert around_obstacles(sc, beside)[0, 0] == pytest.approx(np.hypot(1.0, 0.1))


def test_shaping_pays_for_progress_around_the_walls() -> None:
    sc = load_scenario("phys_diff_obstacles")
    shaping = ProgressShaping(sc, distance=1.0)
    obs = np.zeros((2, sc.obs_dim), np.float32)
    # pursuer 0 below the left box, the evader above it: beside the box (x = 0.7) is
    # nearer round it than under its middle (x = 1.5), though farther in a straight line
    for row, x0 in ((0, 0.7), (1, 1.5)):
        xy = np.array([(x0, 1.5), (4.5, 0.5), (4.5, 4.5), (1.5, 3.5)]) / sc.size
        obs[row, : xy.size] = xy.ravel()
    phi = shaping.potential(obs)
    assert phi[0] > phi[1]  # nearer round the box at x = 0.7 than under its middle
