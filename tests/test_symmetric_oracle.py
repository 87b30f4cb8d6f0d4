"""The symmetric oracle (issue 35): the grid game's symmetry group and canonical states
(``solve/symmetry.py``) and the solver over them (``solve/symmetric.py``), checked against
the dense value iteration (``GridModel`` + ``solve_dp``) and the grid rules themselves."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from a2cm_phys.config import Scenario, load_scenario
from a2cm_phys.envs.grid import GridRules
from a2cm_phys.solve import GridModel, TooLargeError, UnsupportedError, solve_dp
from a2cm_phys.solve.policy_chain import capture_distribution, evaluate_policy, policy_chain
from a2cm_phys.solve.symmetric import SymmetricResult, check_symmetric, solve_symmetric
from a2cm_phys.solve.symmetry import Symmetry
from a2cm_phys.solve.tables import start_state

DENSE_5X5 = 2.9393043518066406
"""``-solve_dp(GridModel(grid)).value`` at the start of the 5x5 ``grid`` scenario (8 s,
17 sweeps; the figure the README reports as 2.9393 steps)."""

TOL = 1e-13


def grid(**overrides) -> Scenario:
    """The ``grid`` scenario with overrides; ``a__b`` stands for the dotted key ``a.b``."""
    return load_scenario("grid", {k.replace("__", "."): v for k, v in overrides.items()})


def positions(sc: Scenario, cells: np.ndarray) -> np.ndarray:
    """Positions ``(K, N + 1, 2)`` of cells ``(N + 1, K)``."""
    return np.stack([cells % sc.size, cells // sc.size], -1).transpose(1, 0, 2)


# --------------------------------------------------------------------------- the group


@pytest.mark.parametrize("size", [2, 3, 4, 5])
def test_the_eight_maps_carry_moves_and_walls_to_moves_and_walls(size: int) -> None:
    sym = Symmetry(size, 2)
    rules = GridRules(grid(size=size, actions=5))
    move = rules.move.reshape(-1, 5)
    blocked = rules.blocked.reshape(-1, 5)
    maps = {tuple(m) for m in sym.cell_maps}
    assert len(maps) == 8 and tuple(range(size * size)) in maps
    for g in range(8):
        cm, am = sym.cell_maps[g], sym.action_maps[g]
        assert sorted(cm) == list(range(size * size)) and am[4] == 4
        np.testing.assert_array_equal(move[cm[:, None], am[None, :]], cm[move])
        np.testing.assert_array_equal(blocked[cm[:, None], am[None, :]], blocked)
        np.testing.assert_array_equal(sym.action_maps[g][sym.action_inverse[g]], np.arange(5))
        for h in range(8):  # closed under composition: a group
            assert tuple(cm[sym.cell_maps[h]]) in maps


def test_every_image_of_a_state_has_its_canonical_id() -> None:
    sym = Symmetry(4, 3)
    index = sym.index()
    assert sym.order == 48
    rng = np.random.default_rng(0)
    cells = sym.decode(rng.integers(0, sym.n_states, 2000))
    ids = index.ids[sym.encode(cells)]
    generic = np.array([[0], [1], [6], [11]])  # a state no symmetry fixes
    images = set()
    for g, perm in itertools.product(range(8), itertools.permutations(range(3))):
        image = sym.cell_maps[g][cells[[*perm, 3]]]
        np.testing.assert_array_equal(index.ids[sym.encode(image)], ids)
        images.add(int(sym.encode(sym.cell_maps[g][generic[[*perm, 3]]])[0]))
    assert len(images) == sym.order  # the 8 x 3! elements act as distinct maps
    valid = np.all(cells[:3] != cells[3], axis=0)
    assert np.all(ids[~valid] == index.n) and np.all(ids[valid] < index.n)
    # each canonical state is its own canonical key, and the ids number them in order
    np.testing.assert_array_equal(index.ids[index.keys], np.arange(index.n))
    np.testing.assert_array_equal(sym.canonical_key(index.cells.astype(np.int64)), index.keys)


def test_canonical_states_are_the_orbits() -> None:
    sym = Symmetry(3, 2)
    orbits = set()
    for p0, p1, e in itertools.product(range(9), repeat=3):
        if e in (p0, p1):
            continue
        image = {
            (*sorted((sym.cell_maps[g][p0], sym.cell_maps[g][p1])), sym.cell_maps[g][e])
            for g in range(8)
        }
        orbits.add(frozenset(image))
    assert sym.index().n == len(orbits)


def test_actions_map_back_to_the_state_frame() -> None:
    sym = Symmetry(5, 3)
    rng = np.random.default_rng(1)
    cells = sym.decode(rng.integers(0, sym.n_states, 500))
    canonical = rng.integers(0, 4, (500, 3))
    own = sym.own_actions(cells, canonical)
    g, rank = sym.frames(cells)
    for k in range(500):  # pursuer i's mapped move is the canonical move of its rank
        for i in range(3):
            assert sym.action_maps[g[k], own[k, i]] == canonical[k, rank[i, k]]


# --------------------------------------------------------------------------- the optimum


CASES = [
    {"size": 3, "pursuers": 1},
    {"size": 4, "pursuers": 1},
    {"size": 3, "pursuers": 2},
    {"size": 4, "pursuers": 2},
    {"size": 3, "pursuers": 3},
    {"size": 4, "pursuers": 3},
    {"size": 3, "pursuers": 2, "collisions__mode": "penalize", "rewards__collision": -5.0},
    {"size": 4, "pursuers": 2, "collisions__mode": "penalize", "rewards__collision": -5.0},
    {"size": 3, "pursuers": 3, "collisions__mode": "penalize", "rewards__collision": -5.0},
    {"size": 4, "pursuers": 3, "collisions__mode": "penalize", "rewards__collision": -5.0},
    {"size": 3, "pursuers": 3, "collisions__mode": "terminate", "rewards__collision": -5.0},
    {"size": 4, "pursuers": 2, "actions": 5, "rewards__wall": -0.5, "rewards__capture": 2.0},
    {"size": 4, "pursuers": 2, "evader": "static"},
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: ",".join(f"{k}={v}" for k, v in c.items()))
def test_every_state_value_equals_the_dense_optimum(case: dict) -> None:
    sc = grid(**case)
    model = GridModel(sc)
    dense = solve_dp(model, tol=TOL)
    sym = solve_symmetric(sc, tol=TOL)
    valid = model.valid()
    mine = np.append(sym.value, 0.0)[sym.index.ids]
    np.testing.assert_allclose(mine[valid], dense.value[valid], rtol=0, atol=1e-9)
    assert sym.start_value == pytest.approx(dense.value[start_state(sc)], abs=1e-9)


@pytest.mark.parametrize("case", [CASES[5], CASES[7], CASES[10], CASES[11]], ids=str)
def test_the_greedy_policy_mapped_back_is_optimal_under_the_rules(case: dict) -> None:
    """Every state's own-frame actions, replayed through ``GridRules.apply``
    (``policy_chain``), earn the dense optimum, take the expected steps reported, and end
    the episode from the start at the steps :meth:`end_distribution` says."""
    sc = grid(**case)
    model = GridModel(sc)
    dense = solve_dp(model, tol=TOL)
    sym = solve_symmetric(sc, tol=TOL)
    valid = model.valid()
    cells = model.decode(np.arange(model.n_states))
    xy = positions(sc, cells)
    own = sym.actions(xy)
    joint = np.ravel_multi_index(tuple(own.T), (sc.actions,) * sc.pursuers)
    chain = policy_chain(model, joint)
    earned = evaluate_policy(chain, chain.reward, tol=1e-14)
    np.testing.assert_allclose(earned[valid], dense.value[valid], rtol=0, atol=1e-9)
    steps = evaluate_policy(chain, np.ones(model.n_states), tol=1e-14)
    np.testing.assert_allclose(sym.expected_capture_steps(xy)[valid], steps[valid], atol=1e-8)
    assert np.all(sym.expected_capture_steps(xy)[~valid] == 0)
    law = capture_distribution(chain, start_state(sc), sc.max_steps)
    ended, left = sym.end_distribution()
    exact = (law.capture + law.collision)[: len(ended)]
    np.testing.assert_allclose(ended, exact, rtol=0, atol=1e-12)
    assert left < 1e-12 and ended @ np.arange(1, len(ended) + 1) == pytest.approx(
        sym.start_steps, abs=1e-9
    )


def test_5x5_grid_is_the_dense_optimum() -> None:
    sym = solve_symmetric(grid())
    assert sym.index.n < 390_625 / 40
    assert sym.start_steps == pytest.approx(DENSE_5X5, abs=1e-9)
    assert sym.start_value == pytest.approx(-DENSE_5X5, abs=1e-9)
    assert sym.expected_capture_steps(sym.start_positions()) == sym.start_steps
    again = SymmetricResult.from_arrays(sym.scenario, sym.to_arrays())
    np.testing.assert_array_equal(
        again.actions(sym.start_positions()), sym.actions(sym.start_positions())
    )
    assert again.start_steps == sym.start_steps and again.greedy_sweeps == sym.greedy_sweeps
    with pytest.raises(ValueError, match="canonical states"):
        SymmetricResult.from_arrays(grid(size=4), sym.to_arrays())


@pytest.mark.slow
def test_5x5_grid_agrees_with_the_dense_solver_everywhere() -> None:
    sc = grid()
    model = GridModel(sc)
    dense = solve_dp(model)
    sym = solve_symmetric(sc)
    assert -dense.value[start_state(sc)] == pytest.approx(DENSE_5X5, abs=1e-12)
    valid = model.valid()
    mine = np.append(sym.value, 0.0)[sym.index.ids]
    np.testing.assert_allclose(mine[valid], dense.value[valid], rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- limits


def test_too_large_names_the_arena_and_the_budget() -> None:
    with pytest.raises(TooLargeError, match=r"12x12 arena with 4 pursuers.*GiB \(budget 8\.0"):
        check_symmetric(grid(size=12, pursuers=4))
    with pytest.raises(TooLargeError, match=r"4x4 arena with 2 pursuers.*budget 0\.0 GiB"):
        solve_symmetric(grid(size=4, pursuers=2), memory_budget=1000)
    assert check_symmetric(grid(size=10)) < 2 * 2**30  # 10x10, 3 pursuers: in reach


def test_unsupported_games_name_the_key() -> None:
    with pytest.raises(UnsupportedError, match="evader='flee'"):
        check_symmetric(grid(evader="flee"))
    with pytest.raises(UnsupportedError, match="mode"):
        check_symmetric(load_scenario("phys"))
