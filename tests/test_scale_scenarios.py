"""The 10x10 scenarios of issue 35 (``grid10``, ``phys_cont10``) and larger teams.

What the tests over every scenario (``tests/test_api.py`` etc.) do not check: that the
scenarios are their 5x5 originals with only the arena and the step cap changed, and that
the default start places every team the scale benchmark plays (up to 6 pursuers, arenas up
to 15) on distinct cells, the corners first.
"""

from __future__ import annotations

import numpy as np
import pytest

from a2cm_phys.config import load_scenario, to_dict
from a2cm_phys.envs.vector import VectorEnv

SCALED = {"grid10": "grid", "phys_cont10": "phys_cont"}


@pytest.mark.parametrize(("name", "original"), SCALED.items())
def test_scaled_scenarios_differ_from_their_originals_only_in_size_and_cap(name, original):
    big, small = to_dict(load_scenario(name)), to_dict(load_scenario(original))
    assert (big["size"], big["pursuers"], big["max_steps"]) == (10, 3, 4000)
    changed = {key for key in big if big[key] != small[key]}
    assert changed == {"name", "size", "max_steps"}


@pytest.mark.parametrize("name", SCALED)
def test_the_scaled_arenas_start_in_the_corners_with_the_evader_in_the_centre(name):
    env = VectorEnv(load_scenario(name), 2)
    try:
        env.reset(3)
        start = env.core.positions()
    finally:
        env.close()
    offset = 0.5 if name.startswith("phys") else 0.0  # physics bodies sit at cell centres
    expected = np.array([(0, 0), (9, 0), (0, 9), (5, 5)]) + offset
    np.testing.assert_array_equal(start[0], expected)
    np.testing.assert_array_equal(start[1], expected)


@pytest.mark.parametrize("mode", ["grid", "phys", "phys_cont"])
@pytest.mark.parametrize("size", [5, 8, 10, 15])
@pytest.mark.parametrize("pursuers", [4, 6])
def test_large_teams_start_on_distinct_cells_and_can_step(mode, size, pursuers):
    sc = load_scenario(mode, {"size": size, "pursuers": pursuers})
    env = VectorEnv(sc, 2)
    try:
        env.reset(0)
        cells = np.floor(env.core.positions()[0]).astype(int)
        shape = (2, *env.action_shape)
        actions = np.zeros(shape, dtype=np.float32 if sc.continuous else np.int64)
        step = env.step(actions)
    finally:
        env.close()
    assert len({tuple(c) for c in cells}) == pursuers + 1  # the evader's cell too
    top = size - 1
    assert {tuple(c) for c in cells[:4]} == {(0, 0), (top, 0), (0, top), (top, top)}
    assert tuple(cells[-1]) == (size // 2, size // 2)
    assert step.obs.shape == (2, env.obs_dim)
    assert np.all(np.isfinite(step.obs))
