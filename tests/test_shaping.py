"""Progress shaping on the distance and the evader's cell area (algos/shaping.py, algos/voronoi.py)
against hand-computed values and an independent geometry library."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from a2cm_phys.algos import Learner, make_model
from a2cm_phys.algos.shaping import ProgressShaping
from a2cm_phys.algos.voronoi import cell_area
from a2cm_phys.config import ConfigError, Train, load_scenario, load_train, resolve_train


def _obs(scenario, pursuers, evader):
    """A physics observation (SPEC §5) of positions in metres, at rest."""
    xy = np.array([*pursuers, evader], dtype=np.float64) / scenario.size
    return np.concatenate([xy.ravel(), np.zeros(xy.size)]).astype(np.float32)


def test_potential_is_mean_distance_in_steps():
    sc = load_scenario("phys_cont")  # size 5, max_speed 1, dt 0.1: a step is 0.1 m
    shaping = ProgressShaping(sc, distance=2.0)
    obs = _obs(sc, [(0.5, 0.5), (4.5, 0.5), (2.5, 4.5)], (2.5, 2.5))
    mean_dist = (np.hypot(2, 2) * 2 + 2.0) / 3
    assert shaping.potential(obs) == pytest.approx(-2.0 * mean_dist / 0.1, rel=1e-6)
    evader_side = ProgressShaping(sc, distance=2.0, sign=-1.0)
    assert evader_side.potential(obs) == pytest.approx(-shaping.potential(obs))


def test_grid_step_is_one_cell():
    sc = load_scenario("grid")  # obs = cell / (size - 1)
    shaping = ProgressShaping(sc, distance=1.0)
    cells = np.array([[0, 0], [4, 0], [0, 4], [0, 3]], dtype=np.float32)
    obs = (cells / (sc.size - 1)).ravel()
    assert shaping.potential(obs) == pytest.approx(-(3 + 5 + 1) / 3, rel=1e-6)


def test_batch_terms_with_a_terminal_and_a_truncation():
    """T = 3 steps of one game: step 0 an ordinary step, step 1 terminal (capture), step 2
    truncated; the state after a step is the next row, or the episode's final observation
    where it ended, or the observation after the batch at the last step."""
    sc = load_scenario("phys_cont")
    shaping = ProgressShaping(sc, distance=1.0)
    ev = (2.5, 2.5)
    p = [(0.5, 0.5), (4.5, 0.5), (0.5, 4.5)]

    def at(dx):  # every pursuer dx metres along x from its start
        return _obs(sc, [(x + dx, y) for x, y in p], ev)

    obs = np.stack([at(0.0), at(0.1), at(0.0)])[:, None]
    final = np.stack([at(0.7), at(0.2), at(0.3)])[:, None]  # read where the episode ended
    batch = {
        "obs": obs,
        "final_obs": final,
        "next_obs": at(0.5)[None],
        "terminated": np.array([[False], [True], [False]]),
        "truncated": np.array([[False], [False], [True]]),
    }
    phi = shaping.potential
    expected = [
        phi(at(0.1)) - phi(at(0.0)),  # the next row (final_obs ignored)
        phi(at(0.2)) - phi(at(0.1)),  # terminal: the final observation
        phi(at(0.3)) - phi(at(0.0)),  # truncated: the final observation
    ]
    np.testing.assert_allclose(shaping(batch)[:, 0], expected, rtol=1e-9)
    # by hand for step 0: every pursuer moves 0.1 m along +x; the distances of pursuers 0
    # and 2 to the evader change from √8 to √(1.9² + 2²), pursuer 1's to √(2.1² + 2²)
    d0 = np.sqrt(8.0)
    d1 = (2 * np.hypot(1.9, 2.0) + np.hypot(2.1, 2.0)) / 3
    assert expected[0] == pytest.approx((d0 - d1) / 0.1, rel=1e-5)
    batch["truncated"][2] = False  # now the batch ends mid-episode: next_obs follows
    assert shaping(batch)[2, 0] == pytest.approx(phi(at(0.5)) - phi(at(0.0)))


def test_an_episode_sums_to_its_progress():
    """Over an episode the terms sum to Φ(final) − Φ(start), whatever the path."""
    sc = load_scenario("phys_cont")
    shaping = ProgressShaping(sc, distance=1.0)
    rng = np.random.default_rng(0)
    obs = rng.uniform(0.1, 0.9, size=(6, 1, sc.obs_dim)).astype(np.float32)
    final = np.zeros_like(obs)
    final[5] = rng.uniform(0.1, 0.9, size=(1, sc.obs_dim))
    batch = {
        "obs": obs,
        "final_obs": final,
        "next_obs": np.zeros((1, sc.obs_dim), dtype=np.float32),
        "terminated": np.array([[False]] * 5 + [[True]]),
        "truncated": np.zeros((6, 1), dtype=bool),
    }
    progress = shaping.potential(final[5, 0]) - shaping.potential(obs[0, 0])
    assert shaping(batch).sum() == pytest.approx(progress, rel=1e-9)


def test_cell_area_by_hand():
    """Box [0, 5]²; the evader at the centre."""
    e = np.array([2.5, 2.5])
    # one pursuer 2 m to the left: the bisector x = 1.5 leaves 3.5 × 5
    assert cell_area(e, np.array([[0.5, 2.5]]), 0.0, 5.0) == pytest.approx(17.5)
    # left, below and above: [1.5, 5] × [1.5, 3.5]
    three = np.array([[0.5, 2.5], [2.5, 0.5], [2.5, 4.5]])
    assert cell_area(e, three, 0.0, 5.0) == pytest.approx(7.0)
    # a pursuer far outside the box cuts nothing
    assert cell_area(e, np.array([[100.0, 100.0]]), 0.0, 5.0) == pytest.approx(25.0)
    # batched, and over leading dims
    both = cell_area(np.stack([e, e])[None], np.stack([three, three[:1].repeat(3, 0)])[None], 0, 5)
    assert both.shape == (1, 2) and both[0, 1] == pytest.approx(17.5)


def test_cell_area_matches_scipy_halfspace_intersection():
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    rng = np.random.default_rng(0)
    e = rng.uniform(0.3, 4.7, size=(300, 2))
    p = rng.uniform(0.3, 4.7, size=(300, 3, 2))
    got = cell_area(e, p, 0.0, 5.0)
    for r in range(300):
        # a·x + b ≤ 0: the box's four sides, then |x − e| ≤ |x − p_i| for each pursuer
        spaces = [[-1, 0, 0], [1, 0, -5], [0, -1, 0], [0, 1, -5]]
        for q in p[r]:
            spaces.append([*(q - e[r]), -(q @ q - e[r] @ e[r]) / 2])
        cell = HalfspaceIntersection(np.array(spaces, dtype=float), e[r])
        assert got[r] == pytest.approx(ConvexHull(cell.intersections).volume, rel=1e-9)


def test_area_potential_in_steps():
    sc = load_scenario("phys_cont")  # side 5 m, a step is 0.1 m
    shaping = ProgressShaping(sc, distance=0.0, area=2.0)
    obs = _obs(sc, [(0.5, 2.5), (2.5, 0.5), (2.5, 4.5)], (2.5, 2.5))
    assert shaping.potential(obs) == pytest.approx(-2.0 * 7.0 / (5 * 0.1))
    both = ProgressShaping(sc, distance=1.0, area=2.0, sign=-1.0)
    assert both.potential(obs) == pytest.approx(2.0 * 7.0 / 0.5 + 2.0 / 0.1)
    grid = load_scenario("grid")  # cells are unit squares: the box is [-0.5, 4.5]²
    cells = np.array([[0, 2], [2, 0], [2, 4], [2, 2]], dtype=np.float32) / (grid.size - 1)
    # bisectors x = 1, y = 1, y = 3: [1, 4.5] × [1, 3]
    area = ProgressShaping(grid, distance=0.0, area=1.0).potential(cells.ravel())
    assert area == pytest.approx(-3.5 * 2.0 / 5)


def test_advancing_on_a_fleeing_evader_pays_only_by_area():
    """One pursuer chases an evader that runs straight away as fast: the distance term sees
    no progress, the cell-area term sees the bisector advance by a step."""
    sc = load_scenario("phys_cont", {"pursuers": 1})  # side 5 m, a step is 0.1 m
    before = _obs(sc, [(0.5, 2.5)], (2.5, 2.5))
    after = _obs(sc, [(0.6, 2.5)], (2.6, 2.5))
    dist = ProgressShaping(sc, distance=1.0)
    area = ProgressShaping(sc, distance=0.0, area=1.0)
    assert dist.potential(after) - dist.potential(before) == pytest.approx(0.0, abs=1e-5)
    # the bisector moves from x = 1.5 to 1.6: the cell loses 0.1 × 5 m², 1 in step units
    assert area.potential(after) - area.potential(before) == pytest.approx(1.0, rel=1e-5)


def test_one_potential_call_equals_row_by_row():
    """The batch's potentials come from one call over stacked rows: each row's value is
    the same as on its own, bit for bit (what keeps older runs' shaping unchanged)."""
    sc = load_scenario("phys_cont")
    rng = np.random.default_rng(3)
    obs = rng.uniform(0.1, 0.9, size=(8, 4, sc.obs_dim)).astype(np.float32)
    final = rng.uniform(0.1, 0.9, size=(8, 4, sc.obs_dim)).astype(np.float32)
    nxt = rng.uniform(0.1, 0.9, size=(4, sc.obs_dim)).astype(np.float32)
    term = rng.random((8, 4)) < 0.2
    trunc = ~term & (rng.random((8, 4)) < 0.1)
    batch = {"obs": obs, "final_obs": final, "next_obs": nxt, "terminated": term,
             "truncated": trunc}  # fmt: skip
    for shaping in (ProgressShaping(sc, 1.0), ProgressShaping(sc, 0.5, 2.0)):
        after = np.concatenate([obs[1:], nxt[None]])
        after = np.where((term | trunc)[..., None], final, after)
        slow = np.array(
            [[shaping.potential(after[t, b]) - shaping.potential(obs[t, b]) for b in range(4)]
             for t in range(8)]
        )  # fmt: skip
        np.testing.assert_array_equal(shaping(batch), slow)


def test_learner_adds_shaping_to_the_time_component_only():
    sc = load_scenario("phys_cont")
    cfg = resolve_train(sc, Train(num_envs=2, batch_size=4, distance_shaping=1.0))
    model = make_model(cfg, sc)
    learner = Learner(model, cfg, shaping=lambda b: np.full((2, 2), 5.0))
    parts = np.zeros((2, 2, 2))
    parts[..., 1] = -3.0
    batch = {"reward_parts": parts, "rewards": parts.sum(-1), "collisions": np.zeros((2, 2))}
    seen = learner._rewards(batch)
    np.testing.assert_array_equal(seen[..., 0], 5.0)
    np.testing.assert_array_equal(seen[..., 1], -3.0)
    assert np.all(batch["reward_parts"][..., 0] == 0.0)  # the batch stays raw


def test_bad_coefficient_names_the_key():
    for key in ("distance_shaping", "area_shaping"):
        for bad in (-1.0, float("inf"), float("nan")):
            with pytest.raises(ConfigError, match=key):
                load_train({**dataclasses.asdict(Train()), key: bad}, "test")


def test_default_shaping_is_resolved_per_control_type(tmp_path):
    from a2cm_phys.training.trainer import Trainer

    assert Train().distance_shaping is None and Train().area_shaping is None
    assert Train().max_grad_norm is None
    cont = resolve_train(load_scenario("phys_cont"), Train())
    assert (cont.distance_shaping, cont.mean_bound_coef, cont.log_std_init) == (1.0, 0.1, 0.5)
    assert (cont.area_shaping, cont.max_grad_norm) == (2.0, 0.5)
    grid = resolve_train(load_scenario("grid"), Train())
    assert (grid.distance_shaping, grid.mean_bound_coef, grid.log_std_init) == (0.0, 0.0, 0.0)
    assert (grid.area_shaping, grid.max_grad_norm) == (0.0, 0.0)
    explicit = Train(distance_shaping=0.25, area_shaping=0.0, max_grad_norm=0.0)
    assert resolve_train(load_scenario("grid"), explicit).distance_shaping == 0.25
    mine = resolve_train(load_scenario("phys_cont"), explicit)
    assert (mine.area_shaping, mine.max_grad_norm) == (0.0, 0.0)
    # the weights are per unit of the step cost: the paper's collision rewards cost 1,000
    collision = resolve_train(load_scenario("phys_cont_collision"), Train())
    assert (collision.distance_shaping, collision.area_shaping) == (1000.0, 2000.0)
    free = load_scenario("phys_cont", {"rewards": {"step": 0.0, "capture": 5.0}})
    assert resolve_train(free, Train()).distance_shaping == 1.0  # a free step: unit 1
    grid = load_scenario("grid")
    trainer = Trainer(grid, resolve_train(grid, Train(updates=1)), tmp_path, record=False)
    assert trainer.cfg.distance_shaping == 0.0 and trainer.learner.shaping is None
    trainer.close()
    cont = load_scenario("phys_cont")
    trainer = Trainer(cont, resolve_train(cont, Train(updates=1)), tmp_path, record=False)
    shaping = trainer.learner.shaping
    assert shaping.scale == pytest.approx(5 / 0.1) and shaping.area_scale == pytest.approx(4.0)
    trainer.close()


def test_run_config_records_the_shaping_the_learner_saw(tmp_path):
    import json

    from a2cm_phys.commands import train

    code = train.main(
        [
            "--scenario",
            "phys_cont",
            "--updates",
            "2",
            "--run-dir",
            str(tmp_path / "r"),
            "--no-record",
            "--no-progress",
            "--set",
            "max_steps=20",
        ]
    )
    assert code == 0
    config = json.loads((tmp_path / "r" / "config.json").read_text())
    assert config["train"]["distance_shaping"] == 1.0
    assert config["train"]["area_shaping"] == 2.0
    assert config["train"]["max_grad_norm"] == 0.5
    assert config["train"]["mean_bound_coef"] == 0.1


def test_runs_written_before_the_options_read_as_without_them():
    from a2cm_phys.config import stored_train

    old = {k: v for k, v in dataclasses.asdict(Train()).items()}
    for key in ("distance_shaping", "area_shaping", "mean_bound_coef", "pool_every",
                "entropy_schedule"):  # fmt: skip
        del old[key]
    old["log_std_init"] = 0.0  # stored explicitly by then
    old["max_grad_norm"] = 0.0  # likewise (a plain number before it could be unset)
    old["entropy_coef"] = 1e-4  # every stored run has its value
    old["updates"] = 5000  # likewise
    old["batch_size"] = 128  # likewise
    old["num_envs"], old["lr"] = 16, 7e-3  # plain defaults then, stored as such
    filled = stored_train(old)
    assert filled["distance_shaping"] == 0.0 and filled["mean_bound_coef"] == 0.0
    assert filled["area_shaping"] == 0.0
    assert filled["pool_every"] == Train().pool_every
    assert filled["entropy_schedule"] == "constant"  # every run before it had a constant one
    before = Train(
        entropy_coef=1e-4, entropy_schedule="constant", num_envs=16, batch_size=128, lr=7e-3,
        updates=5000,
    )  # fmt: skip
    assert load_train(filled, "old run") == resolve_train(load_scenario("grid"), before)
