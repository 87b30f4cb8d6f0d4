"""Start distributions (issue 45): ``start = "fixed" | "random"`` and the exact optimum over
the random start.

Random starts are checked for validity by fuzzing (grid and physics), for determinism per
seed, for exact uniformity (a chi-square test over the enumerated set on a small arena, and
the sampler's support equal to the enumeration), and the oracle's expectation over starts
against a brute force that shares nothing with it: every tuple of cells, filtered by the
rule as the issue states it, averaged through ``expected_capture_steps``.
"""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from test_record import make_log

from a2cm_phys.commands.replay import main as replay
from a2cm_phys.config import ConfigError, Scenario, Start, load_scenario
from a2cm_phys.envs.core import default_start
from a2cm_phys.envs.grid import GridCore
from a2cm_phys.envs.physics import PhysicsCore
from a2cm_phys.envs.starts import (
    count_grid_starts,
    episode_starts,
    grid_start_chunks,
    random_starts,
)
from a2cm_phys.record import read_run
from a2cm_phys.solve import GridModel, solve_dp
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.symmetric import solve_symmetric
from a2cm_phys.solve.tables import start_law


def random_grid(**overrides) -> Scenario:
    """``grid_random`` with overrides; ``a__b`` stands for the dotted key ``a.b``."""
    return load_scenario("grid_random", {k.replace("__", "."): v for k, v in overrides.items()})


def brute_force_starts(sc: Scenario) -> list[tuple[tuple[int, int], ...]]:
    """Every valid start by the rule as stated, from every tuple of cells: all agents on
    distinct cells, every pursuer at Manhattan distance >= ``min_evader_distance``."""
    cells = [(x, y) for y in range(sc.size) for x in range(sc.size)]
    out = []
    for combo in itertools.product(cells, repeat=sc.pursuers + 1):
        *pursuers, evader = combo
        if len(set(combo)) < len(combo):
            continue
        d = [abs(p[0] - evader[0]) + abs(p[1] - evader[1]) for p in pursuers]
        if min(d) >= sc.start.min_evader_distance:
            out.append(combo)
    return out


# --------------------------------------------------------------------------- validity


@pytest.mark.parametrize("name", ["grid_random", "grid10_random", "grid_flee_random"])
def test_grid_starts_are_valid(name: str) -> None:
    sc = load_scenario(name)
    xy = random_starts(sc, np.arange(20_000, dtype=np.uint64))
    assert xy.dtype == np.int64 and xy.shape == (20_000, sc.pursuers + 1, 2)
    assert xy.min() >= 0 and xy.max() < sc.size
    flat = xy[..., 0] + sc.size * xy[..., 1]
    assert all(len(set(row)) == sc.pursuers + 1 for row in flat.tolist())
    manhattan = np.abs(xy[:, :-1] - xy[:, -1:]).sum(-1)
    assert manhattan.min() >= sc.start.min_evader_distance >= 2  # never on or next to it


@pytest.mark.parametrize("name", ["phys_cont_random", "phys_cont10_random"])
def test_physics_starts_overlap_nothing_and_clear_the_walls(name: str) -> None:
    sc = load_scenario(name)
    ph, n = sc.physics, sc.pursuers
    xy = random_starts(sc, np.arange(5_000, dtype=np.uint64))
    half = ph.box_side / 2
    assert np.all(xy[:, :n] >= half) and np.all(xy[:, :n] <= sc.size - half)
    assert np.all(xy[:, n] >= ph.evader_radius) and np.all(xy[:, n] <= sc.size - ph.evader_radius)
    for i, j in itertools.combinations(range(n), 2):  # axis-aligned boxes: apart on an axis
        assert np.all(np.abs(xy[:, i] - xy[:, j]).max(-1) >= ph.box_side)
    dist = np.linalg.norm(xy[:, :n] - xy[:, n:], axis=-1)
    assert dist.min() >= sc.start.min_evader_distance
    assert dist.min() >= ph.evader_radius + ph.box_side / np.sqrt(2)  # box corner off the disc
    core = PhysicsCore(sc, num_envs=64)
    core.reset(np.arange(64), np.arange(64, dtype=np.uint64))
    np.testing.assert_allclose(core.positions(), xy[:64], rtol=0, atol=1e-12)


def test_pursuers_keep_the_distance_asked_and_the_default_is_todays() -> None:
    base = load_scenario("phys_diff_obstacles", {"start.min_pursuer_distance": 0.0})
    seeds = np.arange(3_000, dtype=np.uint64)
    plain = random_starts(base, seeds)
    np.testing.assert_array_equal(plain, random_starts(load_scenario("phys_cont_random", {
        "obstacles": [dataclasses.asdict(o) for o in base.obstacles], "physics.drive":
        "differential"}), seeds))  # fmt: skip
    n = base.pursuers
    pairs = list(itertools.combinations(range(n), 2))
    close = min(np.linalg.norm(plain[:, i] - plain[:, j], axis=-1).min() for i, j in pairs)
    assert close < 0.85  # without the key, pursuers start too close to turn in place
    sc = load_scenario("phys_diff_obstacles", {"start.min_pursuer_distance": 1.2})
    xy = random_starts(sc, seeds)
    for i, j in pairs:
        assert np.linalg.norm(xy[:, i] - xy[:, j], axis=-1).min() >= 1.2
    kept = np.all([np.linalg.norm(plain[:, i] - plain[:, j], axis=-1) >= 1.2 for i, j in pairs], 0)
    assert 0.2 < kept.mean() < 0.9  # the rule bites, and starts that kept it are unchanged
    np.testing.assert_array_equal(xy[kept], plain[kept])
    dist = np.linalg.norm(xy[:, :n] - xy[:, n:], axis=-1)
    assert dist.min() >= sc.start.min_evader_distance
    with pytest.raises(ConfigError, match=r"or start\.min_pursuer_distance \(4\)"):
        random_starts(load_scenario("phys_diff_obstacles", {"start.min_pursuer_distance": 4.0}),
                      seeds[:4])  # fmt: skip
    with pytest.raises(ConfigError, match=r"start\.min_pursuer_distance"):
        load_scenario("phys_diff_obstacles", {"start.min_pursuer_distance": -0.5})


def test_a_start_is_a_function_of_its_seed_alone() -> None:
    for name in ("grid_random", "phys_cont_random"):
        sc = load_scenario(name)
        seeds = np.array([7, 3, 2**63 + 5, 7, 0], dtype=np.uint64)
        batch = random_starts(sc, seeds)
        one_by_one = np.concatenate([random_starts(sc, s) for s in seeds])
        np.testing.assert_array_equal(batch, one_by_one)
        np.testing.assert_array_equal(batch[0], batch[3])
        assert not np.array_equal(batch[0], batch[1])
        reversed_ = random_starts(sc, seeds[::-1])[::-1]
        np.testing.assert_array_equal(batch, reversed_)


def test_the_cores_start_where_the_sampler_says() -> None:
    sc = load_scenario("grid_collision_random")
    core = GridCore(sc, num_envs=8)
    seeds = np.arange(100, 108, dtype=np.uint64)
    core.reset(np.arange(8), seeds)
    np.testing.assert_array_equal(core.positions(), random_starts(sc, seeds))
    core.reset(np.array([2]), np.array([100], dtype=np.uint64))  # the same seed, the same start
    np.testing.assert_array_equal(core.positions()[2], core.positions()[0])
    explicit = {"pursuer_0": [4, 4], "pursuer_1": [0, 4], "pursuer_2": [4, 0], "evader": [0, 0]}
    core.reset(np.array([1]), np.array([5], dtype=np.uint64), [explicit])
    assert core.positions()[1].tolist() == [[4, 4], [0, 4], [4, 0], [0, 0]]


def test_the_fixed_start_is_todays() -> None:
    for name in ("grid", "grid_collision", "grid10"):
        sc = load_scenario(name)
        assert not sc.start.random
        core = GridCore(sc, num_envs=3)
        core.reset(np.arange(3), np.array([1, 2, 3], dtype=np.uint64))
        start = default_start(sc.size, sc.pursuers)
        assert np.all(core.positions() == start)
        n = sc.size - 1
        assert start.tolist() == [[0, 0], [n, 0], [0, n], [sc.size // 2] * 2]
    sc = load_scenario("phys_cont")
    np.testing.assert_array_equal(episode_starts(sc, [1, 2])[0], default_start(5, 3) + 0.5)


@pytest.mark.parametrize("name", ["grid_random", "phys_cont_random"])
def test_random_starts_are_logged_and_re_simulated(name: str, tmp_path: Path) -> None:
    pytest.importorskip("pymunk")
    steps = 60 if name.startswith("grid") else 400
    make_log(tmp_path / "episodes.mcap", scenario=name, envs=3, steps=steps, seed=4)
    log = read_run(tmp_path)
    trajs = list(log.trajectories())
    assert len(trajs) >= 3
    sc = load_scenario(name)
    for traj in trajs:  # the logged start is the sampler's for the logged seed
        start = random_starts(sc, np.array([traj.seed], dtype=np.uint64))[0]
        np.testing.assert_allclose(traj.positions[0], start, rtol=0, atol=1e-6)
    assert len({traj.positions[0].tobytes() for traj in trajs}) == len(trajs)
    assert replay([str(tmp_path), "--verify"]) == 0


# --------------------------------------------------------------------------- uniformity


def test_the_sampler_draws_exactly_the_enumerated_starts_uniformly() -> None:
    sc = random_grid(size=3, pursuers=2)
    every = brute_force_starts(sc)
    assert count_grid_starts(sc) == len(every)
    enumerated = np.concatenate(list(grid_start_chunks(sc)))
    assert sorted(map(tuple, enumerated.reshape(len(enumerated), -1).tolist())) == sorted(
        tuple(v for cell in s for v in cell) for s in every
    )
    draws = 200 * len(every)
    xy = random_starts(sc, np.arange(draws, dtype=np.uint64)).reshape(draws, -1)
    key = {tuple(v for cell in s for v in cell): k for k, s in enumerate(every)}
    counts = np.bincount([key[tuple(row)] for row in xy.tolist()], minlength=len(every))
    assert counts.min() > 0  # the support is the whole enumeration, and nothing else
    assert stats.chisquare(counts).pvalue > 1e-4


def test_uniform_over_sets_is_uniform_over_tuples() -> None:
    sc = random_grid(size=4, pursuers=2, start__min_evader_distance=3)
    idx, p = start_law(sc)
    sets, q = start_law(sc, ordered=False)
    assert len(idx) == 2 * len(sets) and p.sum() == pytest.approx(1) == q.sum()


# --------------------------------------------------------------------------- the optimum


@pytest.mark.parametrize(
    "case",
    [
        {"size": 3, "pursuers": 1},
        {"size": 3, "pursuers": 2},
        {"size": 4, "pursuers": 2},
        {"size": 4, "pursuers": 2, "start__min_evader_distance": 3},
        {"size": 4, "pursuers": 2, "evader": "flee"},
        {"size": 3, "pursuers": 2, "collisions__mode": "penalize", "rewards__collision": -5.0},
    ],
    ids=lambda c: ",".join(f"{k}={v}" for k, v in c.items()),
)
def test_the_optimum_over_starts_is_the_brute_force_average(case: dict, tmp_path) -> None:
    sc = random_grid(**case)
    sol = load_or_solve(sc, cache_dir=tmp_path)
    every = np.array(brute_force_starts(sc), dtype=np.int64)  # (K, N + 1, 2)
    steps = sol.expected_capture_steps(every)
    assert sol.start_steps == pytest.approx(steps.mean(), rel=1e-12)
    assert sol.start_value == pytest.approx(sol.optimal_return(every).mean(), rel=1e-12)
    law = sol.distribution()  # the episode's end over the start law, at the horizon
    ended = law.capture + law.collision
    assert ended @ np.arange(1, len(ended) + 1) == pytest.approx(sol.start_steps, rel=1e-9)
    fixed = load_or_solve(dataclasses.replace(sc, start=Start()), tmp_path)
    assert fixed.start_steps == pytest.approx(
        float(fixed.expected_capture_steps(fixed.start_positions())), rel=1e-15
    )


@pytest.mark.parametrize("case", [{"size": 4, "pursuers": 2}, {"size": 4, "pursuers": 3}])
def test_the_symmetric_solver_averages_the_same_starts(case: dict) -> None:
    sc = random_grid(**case)
    dense = solve_dp(GridModel(sc), tol=1e-13)
    sym = solve_symmetric(sc, tol=1e-13)
    idx, p = start_law(sc)
    assert sym.start_value == pytest.approx(float(p @ dense.value[idx]), abs=1e-9)
    every = np.array(brute_force_starts(sc), dtype=np.int64)
    assert sym.start_steps == pytest.approx(sym.expected_capture_steps(every).mean(), abs=1e-9)
    ended, left = sym.end_distribution()
    assert left < 1e-9
    assert ended @ np.arange(1, len(ended) + 1) == pytest.approx(sym.start_steps, abs=1e-6)


# --------------------------------------------------------------------------- the keys


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"start": "anywhere"}, r"start\.kind"),
        ({"start.kind": "random", "start.min_evader_distance": -1}, r"start\.min_evader_distance"),
        ({"start.kind": "random", "start.near": 1}, r"start\.near"),
        ({"start.min_pursuer_distance": 1.0}, r"start\.min_pursuer_distance.*mode = 'physics'"),
    ],
)
def test_bad_start_keys_name_the_key(overrides: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load_scenario("grid", overrides)


@pytest.mark.parametrize("size", [2, 3, 4, 5])
def test_the_config_refuses_exactly_the_grid_starts_that_do_not_exist(size: int) -> None:
    for pursuers, distance in itertools.product(range(1, 4), [0, 1, 1.5, 2, 3, 4, 5, 6, 7, 8]):
        try:
            sc = load_scenario("grid", {"size": size, "pursuers": pursuers})
        except ConfigError:
            continue  # more pursuers than border cells
        sc = dataclasses.replace(sc, start=Start("random", distance))
        exists = count_grid_starts(sc) > 0
        try:
            sc.validate()
        except ValueError as err:
            assert not exists and "no valid random start" in str(err)
        else:
            assert exists


def test_a_physics_start_too_rare_to_draw_names_the_key_to_lower() -> None:
    sc = load_scenario("phys_cont_random", {"start.min_evader_distance": 6.0})  # one corner
    with pytest.raises(ConfigError, match=r"start\.min_evader_distance"):
        load_scenario("phys_cont_random", {"start.min_evader_distance": 6.3})
    with pytest.raises(ConfigError, match=r"lower start\.min_evader_distance \(6\)"):
        random_starts(sc, np.arange(4, dtype=np.uint64))


def test_overrides_reach_a_start_the_file_wrote_short(tmp_path) -> None:
    """A dotted override reaches ``start = "random"``, and ``start = "random"`` as an
    override keeps the file's other start keys."""
    short = tmp_path / "short.toml"
    short.write_text('start = "random"\n')
    sc = load_scenario(short, {"start.min_evader_distance": 3})
    assert (sc.start.kind, sc.start.min_evader_distance) == ("random", 3.0)
    table = tmp_path / "table.toml"
    table.write_text("[start]\nmin_evader_distance = 3\n")
    sc = load_scenario(table, {"start": "random"})
    assert (sc.start.kind, sc.start.min_evader_distance) == ("random", 3.0)
