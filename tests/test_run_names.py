"""A run's name, ``config.json`` and label carry its preset (issue 31): runs of the paper's
method and of ours are told apart; sweeps find their runs by configuration, not by name."""

from __future__ import annotations

import json
import re

from a2cm_phys.commands import sweep
from a2cm_phys.commands.train import main as train_main
from a2cm_phys.config import Train, load_scenario, load_train, preset, resolve_train, to_dict
from a2cm_phys.training.rundir import CONFIG_NAME, run_name, write_config
from a2cm_phys.training.runs import run_identity, run_label, run_preset

TINY = {"updates": 2, "num_envs": 2, "batch_size": 8}
STAMP = r"\d{8}-\d{6}"


def _train(logdir, *extra):
    argv = ["--scenario", "grid_collision", "--logdir", str(logdir), "--no-record",
            "--no-progress", *extra]  # fmt: skip
    argv += [f"--set=train.{k}={v}" for k, v in TINY.items()]
    assert train_main(argv) == 0
    (run,) = [p for p in logdir.iterdir() if p.is_dir()]
    return run


def test_a_presets_run_has_the_preset_in_its_name_config_and_label(tmp_path):
    run = _train(tmp_path / "paper", "--preset", "paper")
    assert re.fullmatch(rf"grid_collision-a2cm-paper-s0-{STAMP}", run.name), run.name
    config = json.loads((run / CONFIG_NAME).read_text())
    assert config["preset"] == "paper"
    assert run_label(run) == "A2CM (paper)" and run_preset(run) == "paper"
    assert run_label(run / "checkpoint.pt") == "A2CM (paper)"  # a file in the run: its folder
    assert run_identity(run).scenario == "grid_collision"

    # a resumed session keeps it
    argv = ["--resume", str(run), "--updates", "3", "--no-record", "--no-progress"]
    assert train_main(argv) == 0
    config = json.loads((run / CONFIG_NAME).read_text())
    assert config["preset"] == "paper" and len(config["resumed"]) == 1


def test_without_a_preset_the_name_is_unchanged(tmp_path):
    run = _train(tmp_path / "ours", "--algo", "a2c", "--seed", "3")
    assert re.fullmatch(rf"grid_collision-a2c-s3-{STAMP}", run.name), run.name
    assert json.loads((run / CONFIG_NAME).read_text())["preset"] is None
    assert run_label(run) == "A2C" and run_preset(run) is None


def test_a_run_written_before_the_preset_was_recorded_counts_as_the_preset_it_holds(tmp_path):
    scenario = load_scenario("grid_collision")
    for name, values, label in (("paper", preset("paper"), "A2CM (paper)"),
                                ("ours", {}, "A2CM")):  # fmt: skip
        run = tmp_path / name
        run.mkdir()
        write_config(run, scenario, resolve_train(scenario, load_train(values)), "train")
        config = json.loads((run / CONFIG_NAME).read_text())
        del config["preset"]  # as written before issue 31
        (run / CONFIG_NAME).write_text(json.dumps(config))
        assert run_label(run) == label
    # a preset with one of its values changed is no longer that preset
    run = tmp_path / "changed"
    run.mkdir()
    cfg = resolve_train(scenario, load_train({**preset("paper"), "lr": 1e-3}))
    (run / CONFIG_NAME).write_text(
        json.dumps({"scenario": to_dict(scenario), "train": to_dict(cfg)})
    )
    assert run_preset(run) is None


def test_run_name():
    assert run_name("grid", "a2cm", 0) == "grid-a2cm-s0"
    assert run_name("grid", "a2cm", 0, "paper") == "grid-a2cm-paper-s0"
    assert Train().algo == "a2cm"


def _sweep(logdir, *extra, updates=("--updates", "2")):
    args = ["--scenarios", "grid", "--algos", "a2cm", "--seeds", "0", "--sequential",
            "--logdir", str(logdir), "--no-record", *updates, *extra]  # fmt: skip
    args += [f"--set=train.{k}={v}" for k, v in TINY.items() if k != "updates"]
    return sweep.main(args)


def test_a_sweep_finds_its_runs_by_configuration_whatever_their_name(tmp_path, capsys):
    logdir = tmp_path / "sweep"
    assert _sweep(logdir, "--preset", "paper") == 0
    assert "grid-a2cm-paper-s0: ran" in capsys.readouterr().out
    run = logdir / "grid-a2cm-paper-s0"
    config = json.loads((run / CONFIG_NAME).read_text())
    assert config["preset"] == "paper" and config["train"]["updates"] == 2
    assert "--preset paper" in config["command"]
    summary = json.loads((run / "summary.json").read_text())

    # the same sweep again trains nothing
    assert _sweep(logdir, "--preset", "paper") == 0
    assert "grid-a2cm-paper-s0: skipped" in capsys.readouterr().out

    # a run named the old way (no preset in the name, none in config.json) is still found
    old = logdir / "grid-a2cm-s0"
    run.rename(old)
    config.pop("preset")
    (old / CONFIG_NAME).write_text(json.dumps(config))
    assert _sweep(logdir, "--preset", "paper") == 0
    out = capsys.readouterr().out
    assert "grid-a2cm-s0: skipped" in out and "ran" not in out
    assert not run.exists()
    assert json.loads((old / "summary.json").read_text()) == summary

    # our defaults are another configuration: its run's name is taken by the paper's run
    assert _sweep(logdir) == 2
    assert "holds a run of another configuration" in capsys.readouterr().err


def test_sweep_updates_is_trains_option(tmp_path, capsys):
    assert _sweep(tmp_path / "a", updates=("--set", "train.updates=2")) == 0
    capsys.readouterr()
    assert _sweep(tmp_path / "a") == 0  # --updates 2: the same run, skipped
    assert "grid-a2cm-s0: skipped" in capsys.readouterr().out
    assert _sweep(tmp_path / "a", "--set", "train.updates=7") == 0  # the flag wins
    assert "grid-a2cm-s0: skipped" in capsys.readouterr().out
    config = json.loads((tmp_path / "a" / "grid-a2cm-s0" / CONFIG_NAME).read_text())
    assert config["train"]["updates"] == 2 and config["preset"] is None
