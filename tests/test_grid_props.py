"""Property tests of the grid core: agents stay on the board; a batch of B games is
exactly B single games."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from a2cm_phys.config import load_scenario
from a2cm_phys.envs.grid import GridCore

scenarios = st.sampled_from(["grid", "grid_collision", "grid_collision_continue", "grid_flee"])


@st.composite
def games(draw):
    """A scenario, a batch size and a random action sequence for it."""
    name = draw(scenarios)
    size = draw(st.integers(2, 6))
    pursuers = draw(st.integers(1, min(4, 4 * (size - 1), size * size - 1)))
    n_actions = draw(st.sampled_from([4, 5]))
    sc = load_scenario(name, {"size": size, "pursuers": pursuers, "actions": n_actions})
    batch = draw(st.integers(1, 6))
    steps = draw(st.integers(1, 40))
    seed = draw(st.integers(0, 2**32))
    actions = np.random.default_rng(seed).integers(0, n_actions, (steps, batch, pursuers))
    return sc, batch, actions, seed


@settings(max_examples=60, deadline=None)
@given(games())
def test_agents_stay_on_the_board(game):
    sc, batch, actions, seed = game
    core = GridCore(sc, batch)
    core.reset(np.arange(batch), np.arange(batch, dtype=np.uint64) + np.uint64(seed))
    for acts in actions:
        out = core.step(acts)
        pos = core.positions()
        assert ((pos >= 0) & (pos < sc.size)).all()
        done = np.flatnonzero(out.terminated | out.truncated)
        core.reset(done, done.astype(np.uint64))


@settings(max_examples=60, deadline=None)
@given(games())
def test_batched_core_equals_single_games(game):
    sc, batch, actions, seed = game
    seeds = np.random.default_rng(seed).integers(0, 2**63, batch).astype(np.uint64)
    together = GridCore(sc, batch)
    together.reset(np.arange(batch), seeds)
    alone = [GridCore(sc, 1) for _ in range(batch)]
    for i, core in enumerate(alone):
        core.reset(np.array([0]), seeds[i : i + 1])
    live = np.ones(batch, dtype=bool)
    for acts in actions:
        out = together.step(acts)
        for i, core in enumerate(alone):
            if not live[i]:
                continue
            single = core.step(acts[i : i + 1])
            for field in (
                "reward",
                "terminated",
                "truncated",
                "captured",
                "collisions",
                "wall_contacts",
                "evader_action",
            ):
                assert getattr(single, field)[0] == getattr(out, field)[i], field
            np.testing.assert_array_equal(core.positions()[0], together.positions()[i])
            np.testing.assert_array_equal(core.observe()[0], together.observe()[i])
        live &= ~(out.terminated | out.truncated)
        if not live.any():
            break


@settings(max_examples=40, deadline=None)
@given(games())
def test_tabulated_meet_rule_equals_the_direct_rule(game):
    """Large arenas skip the meet table; both paths must give the same step."""
    sc, batch, actions, seed = game
    tabulated = GridCore(sc, batch).rules
    direct = GridCore(sc, batch).rules
    direct.meets = None
    rng = np.random.default_rng(seed)
    for acts in actions:
        cells = rng.integers(0, sc.size**2, (sc.pursuers + 1, batch)).astype(np.int32)
        evader = rng.integers(0, 5, batch)
        a = tabulated.apply(cells.copy(), acts, evader)
        b = direct.apply(cells.copy(), acts, evader)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
