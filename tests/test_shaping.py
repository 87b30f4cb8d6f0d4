"""Progress shaping on the distance (algos/shaping.py) against hand-computed values."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from a2cm_phys.algos import Learner, make_model
from a2cm_phys.algos.shaping import DistanceShaping
from a2cm_phys.config import ConfigError, Train, load_scenario, load_train


def _obs(scenario, pursuers, evader):
    """A physics observation (SPEC §5) of positions in metres, at rest."""
    xy = np.array([*pursuers, evader], dtype=np.float64) / scenario.size
    return np.concatenate([xy.ravel(), np.zeros(xy.size)]).astype(np.float32)


def test_potential_is_mean_distance_in_steps():
    sc = load_scenario("phys_cont")  # size 5, max_speed 1, dt 0.1: a step is 0.1 m
    shaping = DistanceShaping(sc, coef=2.0)
    obs = _obs(sc, [(0.5, 0.5), (4.5, 0.5), (2.5, 4.5)], (2.5, 2.5))
    mean_dist = (np.hypot(2, 2) * 2 + 2.0) / 3
    assert shaping.potential(obs) == pytest.approx(-2.0 * mean_dist / 0.1, rel=1e-6)
    evader_side = DistanceShaping(sc, coef=2.0, sign=-1.0)
    assert evader_side.potential(obs) == pytest.approx(-shaping.potential(obs))


def test_grid_step_is_one_cell():
    sc = load_scenario("grid")  # obs = cell / (size - 1)
    shaping = DistanceShaping(sc, coef=1.0)
    cells = np.array([[0, 0], [4, 0], [0, 4], [0, 3]], dtype=np.float32)
    obs = (cells / (sc.size - 1)).ravel()
    assert shaping.potential(obs) == pytest.approx(-(3 + 5 + 1) / 3, rel=1e-6)


def test_batch_terms_with_a_terminal_and_a_truncation():
    """T = 3 steps of one game: step 0 an ordinary step, step 1 terminal (capture), step 2
    truncated; the state after a step is the next row, or the episode's final observation
    where it ended, or the observation after the batch at the last step."""
    sc = load_scenario("phys_cont")
    shaping = DistanceShaping(sc, coef=1.0)
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
    shaping = DistanceShaping(sc, coef=1.0)
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


def test_learner_adds_shaping_to_the_time_component_only():
    sc = load_scenario("phys_cont")
    cfg = Train(num_envs=2, batch_size=4, distance_shaping=1.0)
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
    for bad in (-1.0, float("inf"), float("nan")):
        with pytest.raises(ConfigError, match="distance_shaping"):
            load_train({**dataclasses.asdict(Train()), "distance_shaping": bad}, "test")


def test_default_shaping_is_resolved_per_control_type(tmp_path):
    from a2cm_phys.config import resolve_train
    from a2cm_phys.trainer import Trainer

    assert Train().distance_shaping is None
    cont = resolve_train(load_scenario("phys_cont"), Train())
    assert (cont.distance_shaping, cont.mean_bound_coef, cont.log_std_init) == (1.0, 0.1, -0.5)
    grid = resolve_train(load_scenario("grid"), Train())
    assert (grid.distance_shaping, grid.mean_bound_coef, grid.log_std_init) == (0.0, 0.0, 0.0)
    explicit = Train(distance_shaping=0.25)
    assert resolve_train(load_scenario("grid"), explicit).distance_shaping == 0.25
    trainer = Trainer(load_scenario("grid"), Train(updates=1), tmp_path, record=False)
    assert trainer.cfg.distance_shaping == 0.0 and trainer.learner.shaping is None
    trainer.close()


def test_run_config_records_the_shaping_the_learner_saw(tmp_path):
    import json

    from a2cm_phys import train

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
    assert config["train"]["mean_bound_coef"] == 0.1


def test_runs_written_before_the_options_read_as_without_them():
    from a2cm_phys.config import resolve_train, stored_train

    old = {k: v for k, v in dataclasses.asdict(Train()).items()}
    for key in ("distance_shaping", "mean_bound_coef", "pool_every", "entropy_schedule"):
        del old[key]
    old["log_std_init"] = 0.0  # stored explicitly by then
    old["entropy_coef"] = 1e-4  # every stored run has its value
    old["updates"] = 5000  # likewise
    filled = stored_train(old)
    assert filled["distance_shaping"] == 0.0 and filled["mean_bound_coef"] == 0.0
    assert filled["pool_every"] == Train().pool_every
    assert filled["entropy_schedule"] == "constant"  # every run before it had a constant one
    before = Train(entropy_coef=1e-4, entropy_schedule="constant")
    assert load_train(filled, "old run") == resolve_train(load_scenario("grid"), before)
