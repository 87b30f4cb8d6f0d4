"""Scenario files and overrides: loading, validation, clear errors."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest

from a2cm_phys import make_env
from a2cm_phys.config import (
    ConfigError,
    load_scenario,
    load_train,
    parse_assignments,
    scenario_names,
)


def test_named_scenarios_load_and_mean_what_they_say():
    assert {"grid", "grid_collision", "grid_collision_continue", "grid_flee"} <= set(
        scenario_names()
    )
    exp2 = load_scenario("grid_collision")
    assert (exp2.rewards.step, exp2.rewards.collision, exp2.collisions.mode) == (
        -1000.0,
        -150_000_000.0,
        "terminate",
    )
    assert load_scenario("grid_collision_continue").collisions.mode == "penalize"
    assert load_scenario("grid").collisions.mode == "off"
    assert load_scenario("grid_flee").evader == "flee"
    with pytest.raises(dataclasses.FrozenInstanceError):
        exp2.size = 7


def test_a_scenario_can_be_a_path(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text("size = 3\npursuers = 2\n[rewards]\nstep = -2\n")
    sc = load_scenario(path)
    assert (sc.name, sc.size, sc.pursuers, sc.rewards.step) == ("mine", 3, 2, -2.0)


@pytest.mark.parametrize(
    ("overrides", "key", "why"),
    [
        ({"size": 1}, "size", ">= 2"),
        ({"pursuers": 17}, "pursuers", "border"),
        ({"max_steps": 0}, "max_steps", ">= 1"),
        ({"evader": "smart"}, "evader", "one of"),
        ({"collisions.mode": "sometimes"}, "collisions.mode", "one of"),
        ({"rewards.step": "minus one"}, "rewards.step", "number"),
        ({"size": 5.5}, "size", "integer"),
        ({"size": True}, "size", "integer"),
        ({"colour": "red"}, "colour", "unknown key"),
        ({"rewards.bonus": 1}, "rewards.bonus", "unknown key"),
        ({"physics.substeps": 0}, "physics.substeps", ">= 1"),
        ({"actions": 6}, "actions", "4 \\(paper\\) or 5"),
    ],
)
def test_bad_values_name_the_key(overrides, key, why):
    with pytest.raises(ConfigError, match=rf"key '{key}': .*{why}"):
        load_scenario("grid", overrides)


def test_bad_file_names_file_and_key(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("size = 5\n[rewards]\nstpe = -1\n")
    with pytest.raises(ConfigError, match=r"broken\.toml: key 'rewards\.stpe': unknown key"):
        load_scenario(path)
    path.write_text("size = = 5\n")
    with pytest.raises(ConfigError, match=r"broken\.toml: invalid TOML"):
        load_scenario(path)


def test_unknown_scenario_lists_the_named_ones():
    with pytest.raises(ConfigError, match=r"unknown scenario 'gird'.*grid_collision"):
        load_scenario("gird")


def test_overrides_from_code_and_command_line_agree():
    from_cli = load_scenario(
        "grid", parse_assignments(["rewards.step=-2", "evader=flee", "size=6"])
    )
    from_code = make_env("grid", size=6, evader="flee", rewards={"step": -2}).scenario
    assert from_cli == from_code
    assert from_cli.rewards.collision == 0.0  # the rest of the table is kept


def test_set_needs_key_equals_value():
    with pytest.raises(ConfigError, match="key=value"):
        parse_assignments(["size"])


def test_training_options_are_validated():
    with pytest.raises(ConfigError, match="batch_size"):
        load_train({"batch_size": 100, "num_envs": 16})
    with pytest.raises(ConfigError, match="'lr'"):
        load_train({"lr": -1.0})
    assert load_train().lr is None  # resolved by the game: the paper's 7e-3, or 1e-2


def test_cli_config_error_is_one_line_without_traceback():
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "a2cm_phys.train",
            "--scenario",
            "grid",
            "--set",
            "size=1",
            "--updates",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "key 'size'" in proc.stderr


def test_entropy_is_resolved_by_the_game_and_an_explicit_value_wins() -> None:
    from a2cm_phys.config import ENTROPY, preset, resolve_train

    unset = load_train()
    assert unset.entropy_coef is None and unset.entropy_schedule is None
    games = {
        "discrete": ("grid", "grid_collision", "grid_flee", "phys", "phys_collision"),
        "self-play": ("grid_vs", "phys_vs"),
        "continuous": ("phys_cont", "phys_cont_collision", "phys_cont_vs"),
    }
    for game, names in games.items():
        for name in names:
            cfg = resolve_train(load_scenario(name), unset)
            assert (cfg.entropy_coef, cfg.entropy_schedule) == ENTROPY[game], name
    assert ENTROPY["discrete"] == (0.03, "linear") and ENTROPY["self-play"][1] == "constant"
    paper = load_train(preset("paper"))
    assert resolve_train(load_scenario("grid_collision"), paper).entropy_coef == 1e-4
    assert resolve_train(load_scenario("grid_collision"), paper).entropy_schedule == "constant"
    chosen = load_train({"entropy_coef": 0.5, "entropy_schedule": "constant"})
    assert resolve_train(load_scenario("grid"), chosen).entropy_coef == 0.5
    assert resolve_train(load_scenario("grid"), chosen).entropy_schedule == "constant"
    with pytest.raises(ConfigError, match="entropy_coef"):
        load_train({"entropy_coef": -1.0})
    with pytest.raises(ConfigError, match="entropy_schedule"):
        load_train({"entropy_schedule": "cosine"})


def test_updates_are_resolved_by_the_control_type_and_an_explicit_value_wins() -> None:
    from a2cm_phys.config import preset, resolve_train

    unset = load_train()
    assert unset.updates is None
    for name in ("phys", "grid_vs", "grid_flee"):
        assert resolve_train(load_scenario(name), unset).updates == preset("paper")["updates"]
    for name in ("grid", "grid_collision"):  # the paper's 640,000 steps, in batches of 512
        resolved = resolve_train(load_scenario(name), unset)
        assert resolved.updates * resolved.batch_size == 640_000 and resolved.updates == 1250
        # the paper's batch alone gives the paper's 5,000 updates
        paper_batch = resolve_train(load_scenario(name), load_train({"batch_size": 128}))
        assert paper_batch.updates == preset("paper")["updates"]
    for name, steps in (("phys_cont", 2e6), ("phys_cont_flee", 4e6), ("phys_cont_vs", 2e6)):
        resolved = resolve_train(load_scenario(name), unset)
        assert 0 <= steps - resolved.updates * resolved.batch_size < resolved.batch_size
    chosen = load_train({"updates": 7})
    assert resolve_train(load_scenario("phys_cont"), chosen).updates == 7
    with pytest.raises(ConfigError, match="updates"):
        load_train({"updates": 0})


def test_batch_size_is_resolved_by_the_control_type_and_checked_against_num_envs() -> None:
    from a2cm_phys.config import preset, resolve_train

    assert load_train().batch_size is None
    for name in ("phys", "phys_cont_vs", "grid_vs", "grid_flee"):
        resolved = resolve_train(load_scenario(name), load_train())
        assert (resolved.batch_size, resolved.num_envs, resolved.lr) == (128, 16, 7e-3), name
    for name in ("grid", "grid_collision", "grid_pomdp", "grid10"):  # GRID_DEFAULTS
        resolved = resolve_train(load_scenario(name), load_train())
        assert (resolved.batch_size, resolved.num_envs, resolved.lr) == (512, 64, 1e-2), name
        assert resolved.steps_per_env == 8  # as before: 16 games of 128
        assert resolved.updates == 1250  # the paper's 640,000 steps
    for name in ("phys_cont", "phys_cont_collision", "phys_cont_pomdp", "phys_cont10"):
        resolved = resolve_train(load_scenario(name), load_train())  # WIDE_DEFAULTS
        assert (resolved.batch_size, resolved.num_envs, resolved.lr) == (512, 64, 1e-2), name
        assert resolved.steps_per_env == 8 and resolved.updates == 2_000_000 // 512
    # the paper's preset is the paper's anywhere
    paper = resolve_train(load_scenario("grid_collision"), load_train(preset("paper")))
    assert (paper.num_envs, paper.batch_size, paper.updates, paper.lr) == (1, 128, 5000, 7e-3)
    # an explicit batch that the default number of games does not divide: named, with the fix
    with pytest.raises(ConfigError, match=r"'batch_size': 96 .*num_envs=64.*set num_envs"):
        resolve_train(load_scenario("grid"), load_train({"batch_size": 96}))
    resolved = resolve_train(load_scenario("phys_cont_flee"), load_train())
    assert (resolved.batch_size, resolved.steps_per_env, resolved.updates) == (512, 32, 7812)
    # an explicit batch wins, and continuous control's updates keep its step budget
    chosen = resolve_train(load_scenario("phys_cont_flee"), load_train({"batch_size": 64}))
    assert (chosen.batch_size, chosen.updates) == (64, 62_500)
    # 512 is no multiple of 48: the error names the key and the default, before any run
    with pytest.raises(ConfigError, match=r"'batch_size'.*default of 512.*num_envs=48"):
        resolve_train(load_scenario("phys_cont_flee"), load_train({"num_envs": 48}))
    assert resolve_train(load_scenario("phys_cont"), load_train({"num_envs": 32})).updates == 3906
    resolved = resolve_train(load_scenario("phys_cont_vs"), load_train({"num_envs": 32}))
    assert (resolved.batch_size, resolved.updates) == (128, 15_625)


def test_paper_preset_has_no_shaping_and_no_clipping_in_continuous_control() -> None:
    from a2cm_phys.config import preset, resolve_train

    paper = resolve_train(load_scenario("phys_cont"), load_train(preset("paper")))
    assert (paper.distance_shaping, paper.area_shaping, paper.max_grad_norm) == (0, 0, 0)
