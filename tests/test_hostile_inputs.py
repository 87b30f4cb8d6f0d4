"""Hostile inputs (issue 29, items 7 and 9): every mistake is one ``error:`` line naming the
file, key or value at fault (commands), or an exception of the right type naming the
argument (Python API); never a traceback from deep inside numpy or torch, never a hang."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError, ResetNeeded

from a2cm_phys import make_env
from a2cm_phys.algos import make_model
from a2cm_phys.analysis.policies import check_layout
from a2cm_phys.config import (
    MAX_WEIGHTS,
    PRESETS,
    ConfigError,
    check_network_size,
    load_scenario,
    load_train,
    network_weights,
    resolve_train,
    scenario_names,
)
from a2cm_phys.envs.gym import PursuitEnv
from a2cm_phys.envs.vector import VectorEnv


def _one_error_line(capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """The command's stderr, checked to be one ``error:`` line holding every needle."""
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err
    return err


def _main(command: str):
    return importlib.import_module(f"a2cm_phys.{command}").main


@pytest.fixture(scope="module")
def grid_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A three-update run on ``grid`` (3 pursuers, 4 moves, xy inputs) to evaluate."""
    path = tmp_path_factory.mktemp("grid-run") / "run"
    argv = ["--scenario", "grid", "--set", "train.updates=3", "--run-dir", str(path)]
    assert _main("train")([*argv, "--no-progress", "--no-record"]) == 0
    return path


# --------------------------------------------------------------------------- item 7: commands


@pytest.mark.parametrize(
    ("command", "args"),
    [
        ("train", ["--no-progress", "--logdir", "logs"]),
        ("evaluate", ["--policy", "random", "--episodes", "5"]),
        ("oracle", ["--no-cache"]),
    ],
)
def test_a_scenario_file_that_is_not_utf8_is_one_error_line_naming_it(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    command: str,
    args: list[str],
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b'size = 5\nname = "caf\xe9"\n')  # Latin-1, not UTF-8
    monkeypatch.chdir(tmp_path)
    assert _main(command)(["--scenario", str(bad), *args]) == 2
    _one_error_line(capsys, f"{bad}: not UTF-8 text", "0xe9")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]  # nothing written


@pytest.mark.parametrize(
    ("args", "key"),
    [
        (["--scenario", "phys"], "mode = 'grid', but the scenario 'phys' has mode = 'physics'"),
        (["--scenario", "phys_cont"], "mode = 'grid'"),
        (["--scenario", "grid", "--set", "pursuers=4"], "pursuers = 3, but"),
        (["--scenario", "grid", "--set", "pursuers=2"], "pursuers = 3, but"),
    ],
)
def test_evaluating_a_run_on_a_scenario_of_another_layout_names_the_run_and_key(
    grid_run: Path, capsys: pytest.CaptureFixture[str], args: list[str], key: str
) -> None:
    assert _main("evaluate")([str(grid_run), *args, "--episodes", "5"]) == 2
    _one_error_line(capsys, f"run {grid_run} was trained with {key}")
    argv = ["--pursuers", str(grid_run), *args, "--episodes", "5", "--cross-play"]
    assert _main("evaluate")(argv) == 2
    _one_error_line(capsys, f"run {grid_run} was trained with {key}")


def test_a_run_plays_where_its_layout_fits_and_nowhere_else(
    grid_run: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Other arenas (xy inputs are fractions of the arena), evaders and rewards, and more
    moves than the run's (it plays a subset), are the run's layout: accepted as before."""
    for extra in (["--set", "size=6", "--set", "evader=flee"], ["--set", "actions=5"]):
        argv = [str(grid_run), "--scenario", "grid", *extra, "--episodes", "8", "--no-progress"]
        assert _main("evaluate")([*argv, "--reference", "none", "--json"]) == 0
    assert capsys.readouterr().err == ""
    argv = [str(grid_run), "--scenario", "grid", "--set", "size=6", "--set", "pursuers=4"]
    assert _main("evaluate")([*argv, "--episodes", "8"]) == 2
    _one_error_line(capsys, "pursuers = 3, but the scenario 'grid' has pursuers = 4")


def test_the_layout_check_covers_control_moves_and_one_hot_arenas() -> None:
    phys, cont = load_scenario("phys"), load_scenario("phys_cont")
    with pytest.raises(ConfigError, match=r"run R was trained with control = 'discrete'"):
        check_layout(phys, cont, "R")
    with pytest.raises(ConfigError, match=r"run R was trained with actions = 5.* has actions = 4"):
        check_layout(load_scenario("grid", {"actions": 5}), load_scenario("grid"), "R")
    grid, bigger = load_scenario("grid"), load_scenario("grid", {"size": 6})
    check_layout(grid, bigger, "R")  # xy inputs: any arena
    onehot = make_model(resolve_train(grid, load_train({"encoding": "onehot"})), grid)
    with pytest.raises(ConfigError, match=r"run R was trained with size = 5.* has size = 6"):
        check_layout(grid, bigger, "R", onehot)
    check_layout(grid, grid, "R", onehot)


def test_networks_too_large_to_allocate_are_refused_before_anything_is_built(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    argv = ["--scenario", "grid", "--set", "train.hidden=16384", "--set", "train.layers=64"]
    assert _main("train")([*argv, "--no-progress", "--logdir", "logs"]) == 2
    _one_error_line(capsys, "keys 'hidden', 'layers'", f"{MAX_WEIGHTS:,}")
    assert not any(tmp_path.iterdir())
    grid = load_scenario("grid")
    with pytest.raises(ConfigError, match=r"keys 'hidden', 'layers'"):
        resolve_train(grid, load_train({"hidden": 4096, "layers": 8}))
    resolve_train(grid, load_train({"hidden": 16_384}))  # one wide layer: 0.9 million
    for name in scenario_names():  # every shipped scenario and preset is small enough
        sc = load_scenario(name)
        for values in ({}, *PRESETS.values()):
            check_network_size(sc, load_train(values))


@pytest.mark.parametrize("scenario", ["grid", "grid_vs", "phys", "phys_cont_vs"])
@pytest.mark.parametrize(
    "train",
    [{}, {"algo": "a2c", "layers": 3, "hidden": 16}, {"encoding": "onehot", "layers": 2}],
)
def test_the_weight_count_is_the_built_networks(scenario: str, train: dict) -> None:
    from a2cm_phys.training.teams import make_teams

    sc = load_scenario(scenario)
    if train.get("encoding") == "onehot" and sc.mode != "grid":
        with pytest.raises(ConfigError, match="key 'encoding'"):  # refused when resolved
            resolve_train(sc, load_train({**train, "updates": 1}))
        return
    cfg = resolve_train(sc, load_train({**train, "updates": 1}))
    pursuers, evader = make_teams(sc, cfg)
    built = sum(p.numel() for team in (pursuers, evader) if team for p in team.model.parameters())
    assert network_weights(sc, cfg) == built


def test_substeps_have_an_upper_bound(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ConfigError, match=r"key 'physics\.substeps': must be at most 10,000"):
        load_scenario("phys", {"physics.substeps": 1_000_000_000})
    assert load_scenario("phys", {"physics.substeps": 10_000}).physics.substeps == 10_000
    monkeypatch.chdir(tmp_path)
    argv = ["--scenario", "phys", "--set", "physics.substeps=1000000000", "--no-progress"]
    assert _main("train")([*argv, "--logdir", "logs"]) == 2
    _one_error_line(capsys, "'physics.substeps': must be at most 10,000")
    assert not any(tmp_path.iterdir())


# --------------------------------------------------------------------------- item 9: the API


def test_render_and_state_before_reset_are_refused() -> None:
    env = make_env("grid")
    for call in (env.render, env.state, lambda: env.step({a: 0 for a in env.possible_agents})):
        with pytest.raises(RuntimeError, match=r"before reset\(\): call reset\(\) first"):
            call()
    env.reset(seed=0)
    assert isinstance(env.render(), str)
    gym_env = PursuitEnv("grid", render_mode="ansi")
    with pytest.raises(ResetNeeded, match=r"render\(\) called before reset"):
        gym_env.render()
    with pytest.raises(ResetNeeded, match=r"step\(\) called before reset"):
        gym_env.step(np.zeros(3, dtype=np.int64))


def test_a_closed_env_refuses_to_step_or_reset() -> None:
    env = make_env("grid")
    env.reset(seed=0)
    env.close()
    env.close()  # closing twice is fine
    with pytest.raises(RuntimeError, match=r"step\(\) called after close\(\)"):
        env.step({a: 0 for a in env.possible_agents})
    with pytest.raises(RuntimeError, match=r"reset\(\) called after close\(\)"):
        env.reset()
    gym_env = PursuitEnv("grid")
    gym_env.reset(seed=0)
    gym_env.close()
    with pytest.raises(ClosedEnvironmentError, match=r"step\(\) called after close\(\)"):
        gym_env.step(np.zeros(3, dtype=np.int64))
    vec = VectorEnv(load_scenario("grid"), 2)
    vec.reset(0)
    vec.close()
    with pytest.raises(RuntimeError, match=r"VectorEnv\.step\(\) called after close\(\)"):
        vec.step(np.zeros((2, 3), dtype=np.int64))


@pytest.mark.parametrize("scenario", [123, None, 4.5, ["grid"]])
def test_a_scenario_of_the_wrong_type_names_the_argument(scenario: object) -> None:
    expected = r"scenario: expected a scenario name .*, a path to a TOML file or a Scenario"
    with pytest.raises(TypeError, match=expected):
        make_env(scenario)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=expected):
        PursuitEnv(scenario)  # type: ignore[arg-type]


@pytest.mark.parametrize("options", ["x", ["positions"], 3])
def test_reset_options_that_are_not_a_dict_name_options(options: object) -> None:
    with pytest.raises(TypeError, match=r"reset: options must be a dict"):
        make_env("grid").reset(options=options)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"reset: options must be a dict"):
        PursuitEnv("grid").reset(options=options)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("scenario", "actions", "message"),
    [
        ("grid", np.full((4, 3), np.nan), r"integer moves in \[0, 4\) .*float64 holding NaN"),
        ("grid", np.zeros((4, 3)), r"integer moves in \[0, 4\) of shape \(B = 4, 3\)"),
        ("grid", np.zeros((4, 3), dtype=bool), "got dtype bool"),
        ("grid", np.zeros((4, 2), dtype=np.int64), r"shape \(B = 4, 3\) .*got shape \(4, 2\)"),
        ("grid", np.zeros((3, 3), dtype=np.int64), r"shape \(B = 4, 3\) .*got shape \(3, 3\)"),
        ("grid", np.zeros(12, dtype=np.int64), r"shape \(B = 4, 3\) .*got shape \(12,\)"),
        ("phys_cont", np.zeros((3, 3, 2)), r"shape \(B = 4, 3, 2\) .*got shape \(3, 3, 2\)"),
        ("phys_cont", np.zeros((4, 3)), r"shape \(B = 4, 3, 2\)"),
    ],
)
def test_vector_env_refuses_bad_actions_naming_the_expected_shape(
    scenario: str, actions: np.ndarray, message: str
) -> None:
    env = VectorEnv(load_scenario(scenario), 4)
    env.reset(0)
    with pytest.raises(ValueError, match=message):
        env.step(actions)
    env.close()


@pytest.mark.parametrize("scenario", ["grid_collision", "phys_cont"])
def test_the_action_check_changes_no_game_and_refuses_a_short_batch(scenario: str) -> None:
    sc = load_scenario(scenario, {"max_steps": 30})

    def play(validate: bool) -> list[np.ndarray]:
        env, rng = VectorEnv(sc, 4), np.random.default_rng(5)
        trace = [env.reset(11)]
        for _ in range(60):
            if sc.continuous:
                actions = rng.uniform(-1.0, 1.0, (4, sc.pursuers, 2))
            else:
                actions = rng.integers(0, sc.actions, (4, sc.pursuers))
            step = env.step(actions, validate=validate)
            trace += [step.obs, step.reward, step.positions]
        env.close()
        return trace

    for a, b in zip(play(True), play(False), strict=True):
        np.testing.assert_array_equal(a, b)
    env = VectorEnv(sc, 4)
    env.reset(11)
    short = np.zeros((3, *env.action_shape), dtype=np.float64 if sc.continuous else np.int64)
    with pytest.raises(ValueError, match=r"expected actions of shape \(B = 4, 3"):
        env.step(short)
    env.close()


def test_numpy_scalars_pass_where_python_numbers_do() -> None:
    values = {"max_steps": np.int64(50), "size": np.uint8(6), "rewards.step": np.float32(-2)}
    env = make_env("grid", **values)
    assert env.scenario == make_env("grid", max_steps=50, size=6, **{"rewards.step": -2.0}).scenario
    assert type(env.scenario.max_steps) is int and type(env.scenario.rewards.step) is float
    cfg = load_train({"hidden": np.int32(64), "lr": np.float64(0.01), "value_norm": np.bool_(0)})
    assert (cfg.hidden, cfg.lr, cfg.value_norm) == (64, 0.01, False)
    assert (type(cfg.hidden), type(cfg.lr), type(cfg.value_norm)) == (int, float, bool)
    # refused as the Python values they hold are: floats and bools are not integers
    for value in (np.float64(50.0), np.float32(50.5), np.bool_(True), True):
        with pytest.raises(ConfigError, match=r"key 'max_steps': must be an integer"):
            make_env("grid", max_steps=value)
    with pytest.raises(ConfigError, match=r"key 'rewards.step': must be a number"):
        make_env("grid", **{"rewards.step": np.bool_(False)})


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"max_steps": np.int64(0)}, r"key 'max_steps': must be >= 1, got 0"),
        ({"size": np.int16(2000)}, r"key 'size': must be at most 1,000"),
        ({"rewards.step": np.float32("nan")}, r"key 'rewards.step': must be a finite number"),
    ],
)
def test_numpy_scalars_meet_the_same_bounds_as_python_ones(overrides: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        make_env("grid", **overrides)
