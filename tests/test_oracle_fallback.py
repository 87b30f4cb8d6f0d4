"""Where the dense oracle cannot hold the arena, the symmetric one answers: the same figures,
cached, through the oracle command, the optimum and the oracle policy."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from a2cm_phys.analysis.evaluation import optimum, play, reference_of
from a2cm_phys.analysis.policies import OraclePolicy
from a2cm_phys.commands.oracle import main as oracle_main
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.core import default_start
from a2cm_phys.solve import GridModel, TooLargeError, UnsupportedError, solve_dp
from a2cm_phys.solve import cache as cache_module
from a2cm_phys.solve.cache import load_or_solve, load_or_solve_optimum
from a2cm_phys.solve.symmetric import SymmetricResult


def refuse_dense(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make the dense solver refuse every arena, as it does 7x7 and larger."""

    def refuse(scenario, *args, **kwargs):
        raise TooLargeError(f"{scenario.size}x{scenario.size}: too large (test)")

    monkeypatch.setattr(cache_module, "load_or_solve", refuse)


@pytest.fixture
def dense_refuses(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """The dense solver refuses every arena; the default cache is the test's own."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    refuse_dense(monkeypatch)


def _small(name: str = "grid", **changes: object):
    return dataclasses.replace(load_scenario(name), size=4, **changes)


def test_the_symmetric_fallback_agrees_with_the_dense_solution_and_is_cached(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sc = _small("grid_collision")
    dense = load_or_solve(sc, tmp_path / "dense")
    start = dense.start_positions()
    refuse_dense(monkeypatch)
    sol = load_or_solve_optimum(sc, tmp_path)
    assert isinstance(sol, SymmetricResult)
    assert sol.optimal_return(start) == pytest.approx(dense.optimal_return(start), abs=1e-9)
    steps = sol.expected_capture_steps(start)
    assert steps == pytest.approx(dense.expected_capture_steps(start), abs=1e-9)
    assert sol.distribution().mean_length() == pytest.approx(steps, abs=1e-6)
    cached = list(tmp_path.glob("*-symmetric.npz"))
    assert len(cached) == 1
    again = load_or_solve_optimum(sc, tmp_path)  # read back, not solved again
    assert np.array_equal(again.value, sol.value) and np.array_equal(again.policy, sol.policy)
    cached[0].write_bytes(b"not a zip")  # a damaged cache is solved again, not trusted
    assert load_or_solve_optimum(sc, tmp_path).start_steps == pytest.approx(steps, abs=1e-9)


def test_an_evader_the_symmetries_do_not_keep_gets_the_dense_refusal(dense_refuses) -> None:
    with pytest.raises(TooLargeError, match="too large"):
        load_or_solve_optimum(_small(evader="flee"))


def test_the_oracle_command_reports_a_symmetric_solve(
    dense_refuses, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--scenario", "grid", "--set", "size=4", "--cache-dir", str(tmp_path)]
    assert oracle_main([*argv, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "solve (symmetric):" in out and "up to symmetry" in out
    steps = float(out.split("expected steps to capture:")[1].split()[0])
    assert steps == pytest.approx(optimum_steps(_small()), abs=1e-6)


def optimum_steps(sc) -> float:
    """The dense solver's figure from the start, solved without the cache."""
    model = GridModel(sc)
    value = solve_dp(model).value
    start = default_start(sc.size, sc.pursuers).astype(np.int64)
    return float(-value[model.encode(start[:, 0] + sc.size * start[:, 1])])


def test_the_optimum_and_the_oracle_policy_use_the_fallback(dense_refuses) -> None:
    sc = _small()
    figures = optimum(sc)
    assert figures is not None
    assert figures["capture_steps"] == pytest.approx(optimum_steps(sc), abs=1e-6)
    policy = OraclePolicy(sc)
    assert isinstance(policy.solution, SymmetricResult)
    # played through the env, the symmetric policy's actions (mapped back into each
    # state's own frame) capture in the optimum's time, within 4 standard errors
    lengths = play(sc, lambda obs, rng: policy.act(obs), 4000, 16, seed=0).lengths
    bound = 4 * lengths.std() / np.sqrt(len(lengths))
    assert abs(lengths.mean() - figures["capture_steps"]) < bound


def test_physics_is_still_refused_with_its_reason() -> None:
    with pytest.raises(UnsupportedError, match="grid mode only"):
        load_or_solve_optimum(load_scenario("phys"))


def test_the_default_reference_is_pursuit_where_no_oracle_solves_the_arena() -> None:
    big = load_scenario("grid", {"pursuers": 6})  # 25^7 joint states: both solvers refuse
    ref = reference_of(big, episodes=64)
    assert ref is not None and ref.policy == "pursuit" and ref.played is not None
    assert ref.unavailable is None and len(ref.played.lengths) == 64
    asked = reference_of(big, "oracle", episodes=64)  # asked for by name: why not, instead
    assert asked is not None and asked.played is None and "too large" in asked.unavailable
