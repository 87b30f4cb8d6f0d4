"""Obstacles on a grid (issue 46): cells an obstacle blocks are walls. A move into one stays
put and is a wall bump; no start puts an agent there; the evaders keep out; the exact
oracle (dense and symmetric) solves such arenas, checked against a brute force written
here from the rules as stated, sharing nothing with the solvers or ``GridRules``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from a2cm_phys.analysis.policies import OraclePolicy
from a2cm_phys.config import ConfigError, Scenario, build, load_scenario, to_dict
from a2cm_phys.envs.evaders.scripted import Evader
from a2cm_phys.envs.grid import GridCore, GridRules
from a2cm_phys.envs.starts import count_grid_starts, grid_start_chunks, random_starts
from a2cm_phys.solve.belief import EvaderFilter
from a2cm_phys.solve.cache import cache_key, load_or_solve, value_cache_key
from a2cm_phys.solve.symmetric import solve_symmetric, symmetry_of

MOVES = [(0, 1), (0, -1), (-1, 0), (1, 0)]
"""The four moves (SPEC §1): up (+y), down, left, right."""


def box(x: int, y: int, width: float = 1.0, height: float = 1.0) -> dict:
    """An ``[[obstacles]]`` box covering cells ``x … x + width − 1`` by ``y … y + height − 1``."""
    return {"x": x + width / 2, "y": y + height / 2, "width": width, "height": height}


def arena(base: str = "grid_random", cells=(), **overrides) -> Scenario:
    """Scenario ``base`` with 1x1 boxes on ``cells``; ``a__b`` stands for the key ``a.b``."""
    changes = {k.replace("__", "."): v for k, v in overrides.items()}
    return load_scenario(base, {**changes, "obstacles": [box(*c) for c in cells]})


# --------------------------------------------------------------------------- brute force


class BruteForce:
    """The game from the rules as stated: a move off the arena or into a blocked cell stays
    put; capture when a pursuer ends on the evader's cell or they swap cells; the random
    evader picks each move with probability 1/4, the fleeing one uniformly among the moves
    that leave it farthest (Manhattan) from the nearest pursuer's cell at the step's start.
    States are tuples of free cells, pursuers first, no pursuer on the evader."""

    def __init__(self, size: int, pursuers: int, blocked: set, evader: str) -> None:
        self.size, self.blocked = size, blocked
        free = [(x, y) for y in range(size) for x in range(size) if (x, y) not in blocked]
        states = [s for s in itertools.product(free, repeat=pursuers + 1) if s[-1] not in s[:-1]]
        self.index = {s: i for i, s in enumerate(states)}
        joint = list(itertools.product(range(4), repeat=pursuers))
        self.next = np.full((len(states), len(joint), 4), len(states))  # last: captured
        self.prob = np.zeros((len(states), 4))
        for i, (*ps, e) in enumerate(states):
            ends = [self.step(e, m) for m in MOVES]
            if evader == "random":
                self.prob[i] = 0.25
            else:
                far = [min(abs(c[0] - p[0]) + abs(c[1] - p[1]) for p in ps) for c in ends]
                best = [k for k in range(4) if far[k] == max(far)]
                self.prob[i, best] = 1.0 / len(best)
            for j, acts in enumerate(joint):
                new = [self.step(p, MOVES[a]) for p, a in zip(ps, acts, strict=True)]
                for b, e2 in enumerate(ends):
                    if not any(
                        q == e2 or (q == e and p == e2) for p, q in zip(ps, new, strict=True)
                    ):
                        self.next[i, j, b] = self.index[(*new, e2)]

    def step(self, cell: tuple, move: tuple) -> tuple:
        """Where a move from ``cell`` ends."""
        x, y = cell[0] + move[0], cell[1] + move[1]
        inside = 0 <= x < self.size and 0 <= y < self.size
        return (x, y) if inside and (x, y) not in self.blocked else cell

    def values(self, sweeps: int = 100_000, tol: float = 1e-13) -> np.ndarray:
        """Value iteration of the least expected steps to capture, from 0: at most
        ``sweeps`` sweeps, until no value moves by ``tol``."""
        v = np.zeros(len(self.index) + 1)
        for _ in range(sweeps):
            new = (1.0 + (self.prob[:, None, :] * v[self.next]).sum(-1)).min(axis=1)
            change = np.max(np.abs(new - v[:-1]))
            v[:-1] = new
            if change < tol:
                break
        return v[:-1]

    def starts(self, min_distance: float = 2) -> list[tuple]:
        """Every random start: distinct free cells, each pursuer that far from the evader."""
        return [
            s
            for s in self.index
            if len(set(s)) == len(s)
            and all(abs(p[0] - s[-1][0]) + abs(p[1] - s[-1][1]) >= min_distance for p in s[:-1])
        ]


def positions(states) -> np.ndarray:
    return np.array([list(s) for s in states], dtype=np.int64)


CASES = [
    (3, 1, [(1, 1)], "random"),
    (3, 2, [(1, 1)], "random"),
    (3, 2, [(1, 1)], "flee"),
    (4, 1, [(1, 1)], "random"),
    (4, 2, [(1, 2), (2, 1)], "random"),
    (4, 2, [(1, 1), (2, 2)], "flee"),
]


@pytest.mark.parametrize(("size", "pursuers", "cells", "evader"), CASES)
def test_the_oracle_is_the_brute_force_optimum(size, pursuers, cells, evader, tmp_path) -> None:
    sc = arena(size=size, pursuers=pursuers, evader=evader, cells=cells)
    brute = BruteForce(size, pursuers, set(cells), evader)
    want = brute.values()
    sol = load_or_solve(sc, tmp_path)
    every = positions(brute.index)
    np.testing.assert_allclose(sol.expected_capture_steps(every), want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(-sol.optimal_return(every), want, rtol=0, atol=1e-9)
    starts = brute.starts()
    assert count_grid_starts(sc) == len(starts)
    assert sol.start_steps == pytest.approx(want[[brute.index[s] for s in starts]].mean(), abs=1e-9)
    open_arena = load_or_solve(arena(size=size, pursuers=pursuers, evader=evader), tmp_path)
    assert abs(open_arena.start_steps - sol.start_steps) > 1e-3  # the obstacles matter


def test_a_fleeing_evader_on_a_ring_is_never_caught_by_one_pursuer(tmp_path) -> None:
    """3x3 with the centre blocked: a ring of 8 cells, where the fleeing evader always
    steps away; the oracle finds no state that can force capture, nor does the brute force
    (every sweep adds exactly one step everywhere)."""
    sc = arena(size=3, pursuers=1, evader="flee", cells=[(1, 1)])
    brute = BruteForce(3, 1, {(1, 1)}, "flee")
    v = brute.values(sweeps=200)
    np.testing.assert_array_equal(v, np.full(len(v), 200.0))
    sol = load_or_solve(sc, tmp_path)
    assert np.all(np.isinf(sol.optimal_return(positions(brute.index))))
    assert sol.meta["losing_states"] == len(brute.index)  # the valid states, all of them


@pytest.mark.parametrize(
    ("cells", "maps"),
    [([(1, 1), (2, 2)], 4), ([(1, 0)], 1), ([(1, 1), (2, 1), (1, 2), (2, 2)], 8)],
)
@pytest.mark.parametrize("evader", ["random", "static"])
def test_the_symmetric_solver_keeps_the_maps_that_keep_the_obstacles(cells, maps, evader):
    sc = arena(size=4, pursuers=2, evader=evader, cells=cells)
    sym = symmetry_of(sc)
    assert sym.maps == maps
    blocked = sc.blocked_cells()
    assert all(np.array_equal(blocked[m], blocked) for m in sym.cell_maps)
    dense = load_or_solve(sc, use_cache=False)
    solved = solve_symmetric(sc, tol=1e-13)
    every = np.concatenate(list(grid_start_chunks(sc)))
    states = dense.index(every)
    np.testing.assert_allclose(
        solved.value[solved.index.ids[states]], dense.value[states], atol=1e-9
    )
    assert solved.start_steps == pytest.approx(dense.start_steps, abs=1e-9)
    assert not np.any(blocked[solved.index.cells])  # no canonical state on a blocked cell


@pytest.mark.parametrize("evader", ["random", "flee"])
def test_the_oracle_played_in_the_core_from_random_starts_takes_its_expected_time(evader):
    """Episodes of the grid core (its starts, evader and rules) under the oracle's policy
    last, on average, the oracle's expectation over the start law."""
    sc = arena(size=4, pursuers=2, evader=evader, cells=[(1, 1), (2, 2)])
    policy = OraclePolicy(sc, solution=load_or_solve(sc, use_cache=False))
    episodes = 20_000
    core = GridCore(sc, episodes)
    core.reset(np.arange(episodes), np.arange(episodes, dtype=np.uint64) + np.uint64(99))
    length, running = np.zeros(episodes), np.ones(episodes, dtype=bool)
    for _ in range(200):
        out = core.step(policy.act(core.observe()))
        assert not sc.blocked_cells()[core.cells[:, running]].any()
        length[running] += 1
        running &= ~out.terminated
        if not running.any():
            break
    assert not running.any()
    law = policy.solution.distribution()  # over the start law
    mean = policy.solution.start_steps
    sd = np.sqrt(law.capture @ (np.arange(1, len(law.capture) + 1) - mean) ** 2)
    assert abs(length.mean() - mean) < 4 * sd / np.sqrt(episodes)


def test_the_scenario_file_is_solved_over_its_random_starts(tmp_path) -> None:
    sc = load_scenario("grid_obstacles")
    assert {(int(c % 5), int(c // 5)) for c in np.flatnonzero(sc.blocked_cells())} == {
        (1, 2),
        (3, 2),
    }
    assert sc.start.random and sc.evader == "random" and sc.pursuers == 3
    sym = solve_symmetric(sc)  # the symmetric solver is quick here and exact as the dense one
    assert sym.index.symmetry.maps == 4
    assert sym.start_steps == pytest.approx(2.674425213914432, abs=1e-9)


# --------------------------------------------------------------------------- the rules


def test_a_move_into_a_blocked_cell_stays_put_and_is_one_wall_bump() -> None:
    sc = arena("grid", cells=[(1, 2)], evader="static", rewards__wall=-0.5)
    core = GridCore(sc, 1)
    place = {"pursuer_0": (0, 2), "pursuer_1": (1, 1), "pursuer_2": (4, 4), "evader": (3, 3)}
    core.reset(np.array([0]), np.array([0], dtype=np.uint64), [place])
    # pursuer_0 right into (1, 2), pursuer_1 up into (1, 2), pursuer_2 up off the arena
    out = core.step(np.array([[3, 0, 0]]))
    np.testing.assert_array_equal(core.positions()[0], [(0, 2), (1, 1), (4, 4), (3, 3)])
    assert out.wall_contacts[0] == 3
    assert out.reward[0] == pytest.approx(-1.0 - 3 * 0.5)
    out = core.step(np.array([[1, 1, 2]]))  # away: no bump
    np.testing.assert_array_equal(core.positions()[0], [(0, 1), (1, 0), (3, 4), (3, 3)])
    assert out.wall_contacts[0] == 0


def test_explicit_positions_on_a_blocked_cell_are_refused() -> None:
    core = GridCore(arena("grid", cells=[(1, 2)]), 1)
    place = {"pursuer_0": (1, 2), "pursuer_1": (1, 1), "pursuer_2": (4, 4), "evader": (3, 3)}
    with pytest.raises(ValueError, match=r"pursuer_0 on \(1, 2\)"):
        core.reset(np.array([0]), np.array([0], dtype=np.uint64), [place])


@pytest.mark.parametrize("size", [2, 3, 5, 7])
def test_without_obstacles_the_tables_are_the_clipped_moves(size) -> None:
    rules = GridRules(load_scenario("grid", {"size": size, "pursuers": 1}))
    for cell, action in itertools.product(range(size * size), range(5)):
        x, y = cell % size, cell // size
        dx, dy = (*MOVES, (0, 0))[action]
        tx, ty = min(max(x + dx, 0), size - 1), min(max(y + dy, 0), size - 1)
        assert rules.move[cell * 5 + action] == tx + size * ty
        assert rules.blocked[cell * 5 + action] == int((tx, ty) != (x + dx, y + dy))
    assert rules.move.dtype == np.int32 and rules.blocked.dtype == np.int32
    assert not rules.blocked_cell.any()


def test_obstacles_change_only_the_moves_into_blocked_cells() -> None:
    cells = [(1, 2), (3, 2)]
    rules, open_rules = GridRules(arena("grid", cells=cells)), GridRules(load_scenario("grid"))
    into = open_rules.move  # where each move goes without obstacles
    source = np.arange(len(into)) // 5
    blocked = rules.blocked_cell
    hit = blocked[into] & ~blocked[source]  # from a free cell into a blocked one
    np.testing.assert_array_equal(rules.move[hit], source[hit])
    np.testing.assert_array_equal(rules.blocked[hit], 1)
    np.testing.assert_array_equal(rules.move[~hit], open_rules.move[~hit])
    np.testing.assert_array_equal(rules.blocked[~hit], open_rules.blocked[~hit])
    assert hit.sum() == 2 * 4  # from the four neighbours of each, (2, 2) beside both


@pytest.mark.parametrize("evader", ["random", "flee"])
def test_the_evaders_never_enter_a_blocked_cell(evader) -> None:
    sc = arena(cells=[(1, 2), (3, 2)], evader=evader)
    games = 256
    core = GridCore(sc, games)
    core.reset(np.arange(games), np.arange(games, dtype=np.uint64))
    rng = np.random.default_rng(5)
    blocked, moved = sc.blocked_cells(), 0
    for _ in range(60):
        before = core.cells.copy()
        out = core.step(rng.integers(0, 4, (games, sc.pursuers)))
        assert not blocked[core.cells].any()
        moved += int(np.sum(core.cells[-1] != before[-1]))
        done = np.flatnonzero(out.terminated | out.truncated)
        core.reset(done, rng.integers(0, 2**63, len(done)).astype(np.uint64))
    assert moved > 1000


def test_a_physics_evader_ignores_the_grid_table() -> None:
    """In physics the obstacles' shapes stop the evader: its flee rule is unchanged."""
    walls = [box(1, 2), box(3, 2)]
    sc = load_scenario("phys_flee", {"obstacles": walls})
    assert Evader(sc, 4, 0.3, 4.7).blocked is None
    assert Evader(arena("grid_flee", cells=[(1, 2)]), 4, 0, 4).blocked is not None


# --------------------------------------------------------------------------- starts


def test_random_starts_never_put_an_agent_on_a_blocked_cell() -> None:
    sc = load_scenario("grid_obstacles")
    xy = random_starts(sc, np.arange(20_000, dtype=np.uint64))
    blocked = sc.blocked_cells()
    assert not blocked[xy[..., 0] + sc.size * xy[..., 1]].any()
    cells = xy[..., 0] + sc.size * xy[..., 1]
    assert np.all(np.sort(cells, axis=1)[:, 1:] != np.sort(cells, axis=1)[:, :-1])  # distinct
    assert np.all(np.abs(xy[:, :-1] - xy[:, -1:]).sum(-1) >= 2)
    # every free cell is drawn: for the evader and for each pursuer
    for agent in range(sc.pursuers + 1):
        assert set(np.unique(cells[:, agent])) == set(np.flatnonzero(~blocked))


def test_the_sampler_draws_exactly_the_enumerated_starts_uniformly() -> None:
    sc = arena(size=3, pursuers=1, cells=[(1, 1)])
    brute = BruteForce(3, 1, {(1, 1)}, "random")
    want = {tuple(map(tuple, s)) for s in brute.starts()}
    every = np.concatenate(list(grid_start_chunks(sc)))
    assert {tuple(map(tuple, s)) for s in every} == want and len(every) == len(want)
    drawn = random_starts(sc, np.arange(40_000, dtype=np.uint64))
    seen, counts = np.unique(drawn.reshape(len(drawn), -1), axis=0, return_counts=True)
    assert {tuple(map(tuple, s.reshape(-1, 2))) for s in seen} == want
    expected = len(drawn) / len(want)
    assert ((counts - expected) ** 2 / expected).sum() < 2 * len(want)  # chi-square, loose


def test_the_start_room_counts_only_free_cells() -> None:
    # 3x3 with (0, 2) and (2, 2) blocked: no two free cells are 4 apart, three are 3 apart
    cells = [(0, 2), (2, 2)]
    arena(size=3, pursuers=1, cells=cells, start__min_evader_distance=3)
    with pytest.raises(ConfigError, match=r"start\.min_evader_distance"):
        arena(size=3, pursuers=1, cells=cells, start__min_evader_distance=4)
    arena(size=3, pursuers=1, start__min_evader_distance=4)  # fine without the obstacles


def test_the_belief_starts_on_free_cells_only() -> None:
    sc = arena("grid_pomdp_random", cells=[(1, 2), (3, 2)])
    belief = EvaderFilter(sc).initial(np.array([[0, 24, 4]]))
    blocked = sc.blocked_cells()
    assert np.all(belief[0, blocked] == 0) and belief[0].sum() == pytest.approx(1.0)
    assert np.count_nonzero(belief[0]) == (~blocked).sum() - 3 - 6  # minus pursuers and near


# --------------------------------------------------------------------------- config, cache


def test_an_obstacle_scenario_round_trips_through_the_config() -> None:
    sc = load_scenario("grid_obstacles")
    data = to_dict(sc)
    assert [o["x"] for o in data["obstacles"]] == [1.5, 3.5]
    again = build(Scenario, data, "again")
    assert again == sc
    np.testing.assert_array_equal(again.blocked_cells(), sc.blocked_cells())
    assert cache_key(again) == cache_key(sc)


def test_cache_keys_are_those_of_before_without_obstacles_and_the_cells_with() -> None:
    assert cache_key(load_scenario("grid")) == "069f2364b340e65b"
    assert value_cache_key(load_scenario("grid")) == "4a53da9dc4bc3d72"
    assert cache_key(load_scenario("grid_flee_random")) == "6acc700a2d5e93b9"
    two = arena("grid", cells=[(1, 3), (2, 3)])
    wide = load_scenario("grid", {"obstacles": [box(1, 3, width=2.0)]})  # the same two cells
    assert cache_key(two) == cache_key(wide) and value_cache_key(two) == value_cache_key(wide)
    others = {cache_key(load_scenario("grid")), cache_key(arena("grid", cells=[(1, 3)]))}
    assert cache_key(two) not in others
    assert value_cache_key(two) != value_cache_key(load_scenario("grid"))
