"""Nothing is lost when a run is killed, resumed, interrupted twice or loses a worker, and a
bad run directory is refused (issue 15)."""

from __future__ import annotations

import json
import os
import shutil
import signal
from pathlib import Path

import pytest

from a2cm_phys.analysis.run_series import load_logged_run
from a2cm_phys.commands.replay import main as replay_main
from a2cm_phys.commands.train import EXIT_INTERRUPTED, EXIT_WORKER_DIED, main
from a2cm_phys.record import read_run
from a2cm_phys.record.writer import EpisodeRecorder
from a2cm_phys.training import checkpoint
from a2cm_phys.training.trainer import Trainer

GRID = ["--scenario", "grid", "--num-envs", "4", "--batch-size", "32", "--seed", "3",
        "--no-progress"]  # fmt: skip


def _episodes(run_dir: Path) -> int:
    return json.loads((run_dir / "summary.json").read_text())["episodes"]


def _ids(run_dir: Path) -> list[int]:
    return [int(i) for i in read_run(run_dir).episodes["episode"]]


def test_resume_from_update_0_keeps_the_first_log(tmp_path, monkeypatch):
    original = Trainer._one_update

    def interrupted_in_first_rollout(self, on_step):
        def step_then_stop(*args):
            on_step(*args)
            if self.env.core.t.max() >= 7:  # some episodes of update 0 are logged
                raise KeyboardInterrupt

        original(self, step_then_stop)

    run_dir = tmp_path / "run"
    monkeypatch.setattr(Trainer, "_one_update", interrupted_in_first_rollout)
    assert main([*GRID, "--updates", "6", "--run-dir", str(run_dir)]) == EXIT_INTERRUPTED
    assert checkpoint.load(run_dir)["update"] == 0
    first = (run_dir / "episodes.mcap").read_bytes()
    monkeypatch.setattr(Trainer, "_one_update", original)
    assert main(["--resume", str(run_dir), "--no-progress"]) == 0
    assert (run_dir / "episodes.mcap").read_bytes() == first  # not overwritten
    assert _ids(run_dir) == list(range(_episodes(run_dir)))


def test_a_log_ahead_of_its_checkpoint_counts_each_episode_once(tmp_path, capsys):
    """Killed after the log got ahead of the last checkpoint, then resumed: plot and replay
    see every episode once, and as many as an uninterrupted run has."""
    whole, run_dir = tmp_path / "whole", tmp_path / "run"
    constant = ["--set", "train.lr_schedule=constant", "--set", "train.entropy_schedule=constant"]
    assert main([*GRID, *constant, "--updates", "8", "--run-dir", str(whole)]) == 0
    assert main([*GRID, *constant, "--updates", "5", "--run-dir", str(run_dir)]) == 0
    saved = tmp_path / "at5.pt"
    shutil.copy(run_dir / "checkpoint.pt", saved)
    assert main(["--resume", str(run_dir), "--updates", "8", "--no-progress"]) == 0
    shutil.copy(saved, run_dir / "checkpoint.pt")  # as if killed before the last save
    assert main(["--resume", str(run_dir), "--updates", "8", "--no-progress"]) == 0
    assert len(list(run_dir.glob("episodes*.mcap"))) == 3
    n = _episodes(whole)
    assert _episodes(run_dir) == n
    assert _ids(run_dir) == list(range(n))
    assert len(load_logged_run(run_dir).columns["length"]) == n
    capsys.readouterr()
    assert replay_main([str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert f"{n} episodes" in out and "episodes-001-from-000005" in out


def test_a_second_interrupt_never_cuts_the_log(tmp_path, monkeypatch, capsys):
    """Two Ctrl-C during a log write, then two more while the log is being closed: exit
    130, no traceback, a cleanly closed log holding every finished episode once."""
    record_step, close = EpisodeRecorder.record_step, EpisodeRecorder.close
    calls = []

    def record_step_interrupted(self, *args):
        calls.append(1)
        if len(calls) == 50:
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
        record_step(self, *args)

    def close_interrupted(self):
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        close(self)

    monkeypatch.setattr(EpisodeRecorder, "record_step", record_step_interrupted)
    monkeypatch.setattr(EpisodeRecorder, "close", close_interrupted)
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "100", "--run-dir", str(run_dir)]) == EXIT_INTERRUPTED
    assert "please wait" in capsys.readouterr().err
    log = read_run(run_dir)
    assert log.clean
    ids = [int(i) for i in log.episodes["episode"]]
    assert ids == list(range(len(ids))) and len(ids) > 0


def test_a_dead_worker_saves_progress_names_it_and_says_how_to_resume(
    tmp_path, monkeypatch, capsys
):
    from a2cm_phys.envs.workers import ProcessCore

    step, calls = ProcessCore.step, []

    def step_then_die(self, *args):
        calls.append(1)
        if len(calls) == 4 * 6 + 2:  # inside update 7 (4 steps per game and update)
            os.kill(self._procs[0].pid, signal.SIGKILL)  # worker 1 (slice 0 is ours)
        return step(self, *args)

    monkeypatch.setattr(ProcessCore, "step", step_then_die)
    run_dir = tmp_path / "run"
    argv = ["--scenario", "phys", "--num-envs", "4", "--workers", "2", "--batch-size", "16",
            "--updates", "20", "--run-dir", str(run_dir), "--no-progress"]  # fmt: skip
    assert main(argv) == EXIT_WORKER_DIED
    err = capsys.readouterr().err
    assert "physics worker 1" in err and f"--resume {run_dir}" in err
    assert "Traceback" not in err
    assert checkpoint.load(run_dir)["update"] == 6
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "worker_died" and summary["updates"] == 6
    assert read_run(run_dir).clean


@pytest.mark.parametrize("leftover", ["episodes.mcap", "summary.json", "config.json"])
def test_run_dir_with_a_runs_files_but_no_checkpoint_is_refused(tmp_path, capsys, leftover):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / leftover).write_text("precious")
    assert main([*GRID, "--updates", "1", "--run-dir", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert leftover in err and err.count("\n") == 1
    assert [p.name for p in run_dir.iterdir()] == [leftover]
    assert (run_dir / leftover).read_text() == "precious"


@pytest.mark.parametrize("name", ['"../../x"', '"../x"', '"/tmp/a2cm-escape"', '"a/b"'])
def test_a_scenario_name_cannot_leave_the_logdir(tmp_path, capsys, name):
    logdir = tmp_path / "a" / "b" / "logs"
    argv = [*GRID, "--updates", "1", "--set", f"name={name}", "--logdir", str(logdir)]
    assert main(argv) == 2
    assert "'name'" in capsys.readouterr().err
    assert not any(p.is_file() for p in tmp_path.rglob("*"))
    assert not list(Path("/tmp").glob("a2cm-escape*"))


def test_resume_with_a_damaged_config_json_rebuilds_it(tmp_path):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "2", "--run-dir", str(run_dir), "--no-record"]) == 0
    (run_dir / "config.json").write_text("{damaged")
    assert main(["--resume", str(run_dir), "--updates", "3", "--no-progress"]) == 0
    config = json.loads((run_dir / "config.json").read_text())
    assert config["train"]["updates"] == 3 and config["scenario"]["name"] == "grid"


def test_a_run_that_cannot_start_leaves_no_run_directory(tmp_path, monkeypatch, capsys):
    def no_memory(*args, **kwargs):
        raise MemoryError("no memory for the games")

    monkeypatch.setattr("a2cm_phys.training.trainer.VectorEnv", no_memory)
    assert main([*GRID, "--updates", "1", "--logdir", str(tmp_path / "logs")]) == 2
    err = capsys.readouterr().err
    assert "out of memory" in err and err.count("\n") == 1
    assert not any((tmp_path / "logs").iterdir())


def test_a_preset_gives_defaults_and_explicit_options_win(tmp_path):
    run_dir = tmp_path / "run"
    argv = ["--scenario", "grid", "--preset", "paper", "--updates", "1", "--lr", "0.01",
            "--run-dir", str(run_dir), "--no-record", "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    train = json.loads((run_dir / "config.json").read_text())["train"]
    assert train["num_envs"] == 1 and train["batch_size"] == 128  # the preset
    assert train["updates"] == 1 and train["lr"] == 0.01  # explicit options
