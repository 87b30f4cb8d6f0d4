"""Evaluation: unbiased episode counts, bootstrap intervals, the command line."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.policies import random_policy
from a2cm_phys.analysis.stats import bootstrap_ci, describe, mean_and_se, t_interval
from a2cm_phys.commands.evaluate import main
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.training.episode_stats import EpisodeStats
from a2cm_phys.training.trainer import Trainer


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short trained run (a checkpoint to evaluate)."""
    path = tmp_path_factory.mktemp("run")
    cfg = load_train({"num_envs": 16, "updates": 20})
    grid = load_scenario("grid")
    assert Trainer(grid, resolve_train(grid, cfg), path, record=False).run() == "done"
    return path


def test_play_gives_exactly_n_episodes_reproducibly() -> None:
    sc = load_scenario("grid")
    a = play(sc, random_policy(sc), 37, num_envs=8, seed=5)
    b = play(sc, random_policy(sc), 37, num_envs=8, seed=5)
    c = play(sc, random_policy(sc), 37, num_envs=8, seed=6)
    assert len(a.lengths) == 37 and a.captured.all()
    np.testing.assert_array_equal(a.lengths, b.lengths)
    assert not np.array_equal(a.lengths, c.lengths)
    assert (a.returns == -a.lengths).all()  # grid: -1 per step


def test_bootstrap_ci_is_seeded_and_covers_the_mean() -> None:
    x = np.random.default_rng(0).exponential(5.0, size=400)
    lo, hi = bootstrap_ci(x, lambda r: r.mean(axis=-1), seed=1)
    assert (lo, hi) == bootstrap_ci(x, lambda r: r.mean(axis=-1), seed=1)
    mean, se = mean_and_se(x)
    assert lo < mean < hi
    assert hi - lo == pytest.approx(2 * 1.96 * se, rel=0.2)
    assert np.isnan(bootstrap_ci(np.array([]), np.mean)).all()
    stats = describe(np.full(50, 3.0))
    assert {k: tuple(v.values()) for k, v in stats.items()} == {
        "mean": (3.0, 3.0, 3.0),
        "median": (3.0, 3.0, 3.0),
        "p95": (3.0, 3.0, 3.0),
    }


def test_t_interval_matches_students_t() -> None:
    mean, half = t_interval([1.0, 2.0, 4.0])
    assert mean == pytest.approx(7 / 3)
    t975 = 4.302653  # Student t, 2 degrees of freedom, 97.5% (tables: 4.303)
    assert half == pytest.approx(t975 * np.std([1.0, 2.0, 4.0], ddof=1) / np.sqrt(3))
    assert np.isnan(t_interval([5.0])[1]) and t_interval([5.0])[0] == 5.0
    assert t_interval(np.ones(100))[1] == 0.0


def test_episode_stats_round_trip() -> None:
    sc = load_scenario("grid")
    from a2cm_phys.envs.vector import VectorEnv

    env, stats = VectorEnv(sc, 4), EpisodeStats(window=5)
    env.reset(0)
    rng = np.random.default_rng(0)
    for _ in range(100):
        stats.add(env.step(rng.integers(0, 4, size=(4, 3))).episodes)
    again = EpisodeStats.from_state(stats.state())
    assert again.state().keys() == stats.state().keys()
    assert list(again.recent) == list(stats.recent) and len(again.recent) == 5
    assert again.episodes == stats.episodes > 5


def test_cli_prints_statistics_with_confidence_intervals(
    run_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(run_dir), "--episodes", "200", "--greedy"]) == 0
    out = capsys.readouterr().out
    for label in ("capture steps mean", "capture steps median", "capture steps p95"):
        assert label in out
    assert "capture rate" in out and "collisions / episode" in out and "95% CI" in out
    assert main([str(run_dir / "checkpoint.pt"), "--episodes", "200", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["episodes"] == 200 and report["policy"].endswith("(sampled) vs random evader")
    mean = report["capture_steps"]["mean"]
    assert mean["lo"] <= mean["value"] <= mean["hi"]


def test_cli_random_policy_and_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--policy", "random", "--scenario", "grid", "--episodes", "300", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["policy"] == "random vs random evader"
    assert report["capture_rate"]["value"] == 1.0
    assert main(["no/such/run"]) == 2
    assert main(["--policy", "random"]) == 2
    assert "error:" in capsys.readouterr().err


@pytest.mark.skipif(
    importlib.util.find_spec("a2cm_phys.oracle") is None, reason="no oracle module yet"
)
def test_cli_oracle_policy_beats_random(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    small = tmp_path / "small.toml"
    small.write_text("size = 3\npursuers = 2\n[rewards]\nstep = -1.0\n")
    reports = {}
    for policy in ("oracle", "random"):
        args = ["--policy", policy, "--scenario", str(small), "--episodes", "500", "--json"]
        assert main(args) == 0
        reports[policy] = json.loads(capsys.readouterr().out)["capture_steps"]["mean"]
    assert reports["oracle"]["hi"] < reports["random"]["lo"]


def test_the_oracle_is_one_team_whatever_evader_it_meets(tmp_path) -> None:
    """In a cross-play the oracle row is the scenario's optimum (here against the random
    evader) in every column, not each column's best response (which differs)."""
    import dataclasses

    from a2cm_phys.analysis.policies import OraclePolicy, matchup
    from a2cm_phys.solve.tables import joint_observations, valid_states

    sc = load_scenario("grid", {"size": 3, "pursuers": 2, "max_steps": 50})
    obs = joint_observations(sc)[valid_states(sc)]
    rng = np.random.default_rng(0)
    own = OraclePolicy(sc, cache_dir=tmp_path).act(obs)
    for evader in ("random", "flee", "static"):
        np.testing.assert_array_equal(matchup(sc, "oracle", evader).pursuers(obs, rng), own)
    flee = dataclasses.replace(sc, evader="flee")
    assert not np.array_equal(OraclePolicy(flee, cache_dir=tmp_path).act(obs), own)
