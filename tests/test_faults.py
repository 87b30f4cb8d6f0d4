"""Hostile sequences against a run (issue 29): kills at random instants and at every kind of
write, two writers at once, a full disk at each write site, damaged checkpoints and parts.
After each, the log must hold every episode its checkpoints count, exactly once, and
``replay --verify`` must say so, or name what is wrong."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from faults import TRAIN, invariant_problems, kill_at_write, kill_trial, new_run_args

from a2cm_phys.analysis.run_series import load_logged_run
from a2cm_phys.commands.replay import main as replay_main
from a2cm_phys.commands.train import EXIT_NO_SPACE, main
from a2cm_phys.record import LogError, read_run
from a2cm_phys.record.writer import EpisodeRecorder
from a2cm_phys.training import checkpoint
from a2cm_phys.training.rundir import run_lock

GRID = ["--scenario", "grid_collision", "--num-envs", "4", "--batch-size", "32", "--seed", "1",
        "--no-progress"]  # fmt: skip


def _summary(run_dir: Path) -> dict:
    return json.loads((run_dir / "summary.json").read_text())


def _finished_and_whole(run_dir: Path) -> None:
    """The run ended, its log holds exactly the summary's episodes, and they verify."""
    assert invariant_problems(run_dir, finished=True) == []
    assert read_run(run_dir).n_episodes == _summary(run_dir)["episodes"]


def _temps(run_dir: Path) -> list[str]:
    return sorted(p.name for p in run_dir.glob(".*.tmp"))


# ------------------------------------------------------------------------------ kills


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_random_sigkills_and_resumes_keep_every_episode_exactly_once(tmp_path, seed):
    whole = tmp_path / "whole"
    assert main([*GRID, "--updates", "1500", "--run-dir", str(whole)]) == 0
    trial = kill_trial(tmp_path / "run", seed, kills=3, updates=1500, checkpoint_every=2)
    assert trial.problems == []
    assert len(trial.after_kill) >= 1
    for saved, logged in trial.after_kill:
        assert logged >= saved  # the log never falls behind a checkpoint
    # grid runs resume bit for bit: as many episodes as the run never killed
    assert trial.summary_episodes == trial.log_episodes == _summary(whole)["episodes"]
    # the episodes that straddle a resume keep their whole trajectory (logged every episode)
    assert trial.verified == trial.summary_episodes


@pytest.mark.slow
def test_a_kill_at_any_write_leaves_a_run_that_resumes_with_nothing_lost(tmp_path):
    """SIGKILL (``os._exit``) at write calls spread over a run: mid-flush of the log, between
    a checkpoint's temp file and its rename, between keeping the previous and the new."""
    argv = [*GRID, "--updates", "40", "--checkpoint-every", "2", "--log-every", "1"]
    rng = np.random.default_rng(7)
    targets = sorted(rng.choice(np.arange(3, 120), size=6, replace=False).tolist())
    for target in targets:
        run_dir = tmp_path / f"at-{target}"
        status = kill_at_write(run_dir, target, [*argv, "--run-dir", str(run_dir)])
        assert status == 137, f"the run did not reach write {target}"
        if (run_dir / "checkpoint.pt").exists() or (run_dir / "config.json").exists():
            if any(run_dir.glob("episodes*.mcap")):
                assert invariant_problems(run_dir) == [], target
            resumed = subprocess.run([*TRAIN, "--resume", str(run_dir), "--no-progress"],
                                     capture_output=True, text=True)  # fmt: skip
            assert resumed.returncode == 0, resumed.stderr
            _finished_and_whole(run_dir)
            assert _temps(run_dir) == []


# ------------------------------------------------------------------------------ one writer


def test_a_second_writer_is_refused_naming_the_run_and_the_holder(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "3", "--run-dir", str(run_dir)]) == 0
    capsys.readouterr()
    files = lambda: sorted((p.name, p.stat().st_mtime_ns) for p in run_dir.glob("[!.]*"))  # noqa: E731
    before = files()
    with run_lock(run_dir):
        assert main(["--resume", str(run_dir), "--updates", "6", "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(run_dir) in err and f"pid {os.getpid()}" in err
        assert main([*GRID, "--updates", "3", "--run-dir", str(run_dir)]) == 2
        assert f"pid {os.getpid()}" in capsys.readouterr().err
    assert files() == before  # nothing touched
    assert main(["--resume", str(run_dir), "--updates", "6", "--no-progress"]) == 0


@pytest.mark.slow
def test_two_processes_resuming_one_run_at_once_one_trains(tmp_path):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "2", "--run-dir", str(run_dir)]) == 0
    resume = [*TRAIN, "--resume", str(run_dir), "--updates", "1500", "--no-progress"]
    procs = [subprocess.Popen(resume, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = sorted((p.wait(), p.stderr.read()) for p in procs)
    assert [code for code, _ in results] == [0, 2], results
    assert "another process (pid" in results[1][1]
    _finished_and_whole(run_dir)
    assert len(list(run_dir.glob("episodes*.mcap"))) == 2  # the refused one wrote no part


def test_two_new_runs_on_one_run_dir_one_is_refused(tmp_path):
    run_dir = tmp_path / "run"
    new = [*TRAIN, *GRID, "--updates", "800", "--run-dir", str(run_dir)]
    procs = []
    for seed in ("1", "2"):
        procs.append(subprocess.Popen([*new, "--seed", seed], stderr=subprocess.PIPE, text=True))
    results = sorted((p.wait(), p.stderr.read()) for p in procs)
    assert [code for code, _ in results] == [0, 2], results
    config = json.loads((run_dir / "config.json").read_text())
    assert config["train"]["seed"] == _summary(run_dir)["seed"]
    assert checkpoint.load(run_dir)["train"]["seed"] == _summary(run_dir)["seed"]


# ------------------------------------------------------------------------------ full disk


def _no_space_at_fsync_of(monkeypatch, name: str) -> None:
    """``fsync`` of a file called ``name`` fails as on a full disk (the data never lands)."""
    real = os.fsync

    def fsync(fd):
        if os.readlink(f"/proc/self/fd/{fd}").endswith(name):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)


def _no_space_in_log_after(monkeypatch, writes: int) -> None:
    real, calls = EpisodeRecorder._write, [0]

    def write(self, *args):
        calls[0] += 1
        if calls[0] > writes:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *args)

    monkeypatch.setattr(EpisodeRecorder, "_write", write)


@pytest.mark.parametrize("site", ["log", "checkpoint", "summary"])
def test_a_full_disk_stops_with_its_own_status_and_resumes_with_nothing_lost(
    tmp_path, monkeypatch, capsys, site
):
    run_dir = tmp_path / "run"
    argv = [*GRID, "--updates", "300", "--checkpoint-every", "20", "--run-dir", str(run_dir)]
    if site == "log":
        _no_space_in_log_after(monkeypatch, 150)
        named = "episodes.mcap"
    else:
        named = "summary.json" if site == "summary" else "checkpoint.pt"
        if site == "checkpoint":
            real_save, saves = checkpoint.save, [0]

            def save_then_fill(path, state):  # the first saves succeed, then the disk is full
                saves[0] += 1
                if saves[0] == 4:
                    _no_space_at_fsync_of(monkeypatch, f".{named}.tmp")
                return real_save(path, state)

            monkeypatch.setattr(checkpoint, "save", save_then_fill)
        else:
            _no_space_at_fsync_of(monkeypatch, f".{named}.tmp")
    assert main(argv) == EXIT_NO_SPACE
    err = capsys.readouterr().err
    assert "No space left on device" in err and named in err
    assert f"--resume {run_dir}" in err
    assert _temps(run_dir) == []
    assert invariant_problems(run_dir) == []
    monkeypatch.undo()  # space freed
    assert main(["--resume", str(run_dir), "--no-progress"]) == 0
    _finished_and_whole(run_dir)
    assert replay_main([str(run_dir), "--verify"]) == 0


def test_a_full_disk_while_writing_config_leaves_no_run(tmp_path, monkeypatch, capsys):
    _no_space_at_fsync_of(monkeypatch, ".config.json.tmp")
    assert main([*GRID, "--updates", "3", "--logdir", str(tmp_path / "logs")]) == EXIT_NO_SPACE
    assert "config.json" in capsys.readouterr().err
    assert not any((tmp_path / "logs").iterdir())


def test_a_failed_first_save_leaves_a_run_that_resumes(tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / "run"
    _no_space_at_fsync_of(monkeypatch, ".checkpoint.pt.tmp")
    assert main([*GRID, "--updates", "20", "--run-dir", str(run_dir)]) == EXIT_NO_SPACE
    assert not (run_dir / "checkpoint.pt").exists() and _temps(run_dir) == []
    monkeypatch.undo()
    capsys.readouterr()
    assert main(["--resume", str(run_dir), "--no-progress"]) == 0  # from config.json
    _finished_and_whole(run_dir)


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True).returncode == 0  # fmt: skip


@pytest.mark.slow
def test_a_real_full_disk_then_resumed_elsewhere(tmp_path):
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "600k"):
        pytest.skip("cannot mount a tmpfs here (needs root and mount)")
    try:
        run_dir = disk / "run"
        argv = [*TRAIN, *new_run_args(run_dir, 20000, 25, "grid_collision"), "--no-progress"]
        done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
        assert done.returncode == EXIT_NO_SPACE, done.stderr
        assert "No space left on device" in done.stderr and "--resume" in done.stderr
        assert _temps(run_dir) == []
        assert invariant_problems(run_dir) == []
        moved = tmp_path / "moved"
        shutil.copytree(run_dir, moved)
    finally:
        subprocess.run(["umount", str(disk)], check=False)
    resumed = subprocess.run([*TRAIN, "--resume", str(moved), "--updates", "2000",
                              "--no-progress"], capture_output=True, text=True)  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr
    _finished_and_whole(moved)


# ------------------------------------------------------------------------------ damage


def _flip(path: Path, offset: int, count: int = 64) -> None:
    data = bytearray(path.read_bytes())
    for i in range(offset, offset + count):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def test_a_corrupt_checkpoint_is_an_error_and_resume_falls_back(tmp_path, capsys):
    run_dir = tmp_path / "run"
    argv = [*GRID, "--updates", "30", "--checkpoint-every", "10", "--run-dir", str(run_dir)]
    assert main(argv) == 0
    latest = run_dir / "checkpoint.pt"
    _flip(latest, len(latest.read_bytes()) // 2)
    with pytest.raises(ValueError, match=r"checkpoint\.pt: damaged checkpoint"):
        checkpoint.load(run_dir)
    from a2cm_phys.commands.evaluate import main as evaluate_main

    capsys.readouterr()
    assert evaluate_main([str(run_dir), "--episodes", "5"]) == 2
    assert "checkpoint.pt: damaged" in capsys.readouterr().err
    assert main(["--resume", str(run_dir), "--updates", "40", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "falling back to the previous checkpoint" in err
    assert (run_dir / checkpoint.DAMAGED_NAME).exists()
    _finished_and_whole(run_dir)
    assert checkpoint.load(run_dir)["update"] == 40


@pytest.mark.parametrize(
    "bad",
    [
        [1, 2, 3],
        torch.zeros(3),
        {"format": 1, "update": 3},
        "abc-update",
    ],
    ids=["list", "tensor", "missing-keys", "update-abc"],
)
def test_a_checkpoint_of_the_wrong_structure_is_one_error_line(tmp_path, capsys, bad):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "2", "--run-dir", str(run_dir)]) == 0
    if bad == "abc-update":
        state = checkpoint.load(run_dir)
        bad = {**state, "update": "abc"}
    (run_dir / "checkpoint.prev.pt").unlink()
    torch.save(bad, run_dir / "checkpoint.pt")
    capsys.readouterr()
    assert main(["--resume", str(run_dir), "--updates", "4", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "checkpoint.pt" in err


def test_a_truncated_checkpoint_names_the_file(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "2", "--run-dir", str(run_dir)]) == 0
    (run_dir / "checkpoint.prev.pt").unlink()
    latest = run_dir / "checkpoint.pt"
    latest.write_bytes(latest.read_bytes()[:100])
    capsys.readouterr()
    assert main(["--resume", str(run_dir), "--updates", "4", "--no-progress"]) == 2
    assert "checkpoint.pt" in capsys.readouterr().err


def _two_part_run(tmp_path: Path) -> Path:
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "10", "--run-dir", str(run_dir)]) == 0
    assert main(["--resume", str(run_dir), "--updates", "20", "--no-progress"]) == 0
    return run_dir


@pytest.mark.parametrize("damage", ["empty", "garbage"])
def test_a_damaged_first_part_hides_no_other(tmp_path, capsys, damage):
    run_dir = _two_part_run(tmp_path)
    second = read_run(run_dir / "episodes-001-from-000010.mcap").n_episodes
    (run_dir / "episodes.mcap").write_bytes(b"" if damage == "empty" else b"\x89MCAP0\r\nxx")
    log = read_run(run_dir)
    assert log.n_episodes == second
    assert any("episodes.mcap" in p for p in log.problems)
    capsys.readouterr()
    assert replay_main([str(run_dir)]) == 0
    assert "PROBLEM episodes.mcap" in capsys.readouterr().out
    assert replay_main([str(run_dir), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "INTEGRITY episodes.mcap" in out and "lost" in out
    with pytest.raises(LogError, match="episodes are missing"):  # no silently short figure
        load_logged_run(run_dir)


def test_a_damaged_part_that_lost_nothing_is_plotted_and_named(tmp_path, capsys):
    """Resumed from update 0, the second part holds every episode: the first one's damage
    loses nothing, and every reader says so instead of failing."""
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "6", "--run-dir", str(run_dir)]) == 0
    os.replace(run_dir / "checkpoint.prev.pt", run_dir / "checkpoint.pt")  # the first save
    assert checkpoint.load(run_dir)["update"] == 0
    assert main(["--resume", str(run_dir), "--no-progress"]) == 0
    (run_dir / "episodes.mcap").write_bytes(b"")
    capsys.readouterr()
    assert replay_main([str(run_dir), "--verify"]) == 1  # the damage is reported
    assert "INTEGRITY episodes.mcap: unreadable" in capsys.readouterr().out
    run = load_logged_run(run_dir)
    assert len(run.columns["length"]) == _summary(run_dir)["episodes"]
    assert any("episodes.mcap" in p for p in run.problems)


def test_verify_finds_a_deleted_part_and_lost_episodes(tmp_path, capsys):
    run_dir = _two_part_run(tmp_path)
    assert replay_main([str(run_dir), "--verify"]) == 0
    capsys.readouterr()
    (run_dir / "episodes.mcap").unlink()
    assert replay_main([str(run_dir), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "episodes.mcap: missing" in out and "episode ids missing" in out


def test_verify_re_simulates_no_superseded_part(tmp_path, capsys):
    """A part cut short, resumed from an older checkpoint: what it logged past that
    checkpoint is superseded, and verify neither re-simulates nor counts it."""
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "10", "--run-dir", str(run_dir)]) == 0
    saved = tmp_path / "at10.pt"
    shutil.copy(run_dir / "checkpoint.pt", saved)
    assert main(["--resume", str(run_dir), "--updates", "20", "--no-progress"]) == 0
    shutil.copy(saved, run_dir / "checkpoint.pt")  # as if killed before its first save
    (run_dir / "checkpoint.prev.pt").unlink()
    assert main(["--resume", str(run_dir), "--updates", "20", "--no-progress"]) == 0
    log = read_run(run_dir)
    capsys.readouterr()
    assert replay_main([str(run_dir), "--verify"]) == 0
    out = capsys.readouterr().out
    assert f"verify: {len(log.logged_episodes)} episodes" in out
    assert sum(1 for _ in log.trajectories()) == len(log.logged_episodes)
    assert len(log.logged_episodes) <= log.n_episodes == _summary(run_dir)["episodes"]


# ------------------------------------------------------------------------------ outputs


def test_no_output_replaces_a_runs_own_files(tmp_path, capsys):
    run_dir = _two_part_run(tmp_path)
    files = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}
    for argv in (
        ["--export-foxglove", str(run_dir / "episodes.mcap"), "--episode", "1"],
        ["--export-foxglove", str(run_dir / "episodes-001-from-000010.mcap")],
        ["--render", "gif", "--out", str(run_dir / "checkpoint.pt"), "--episode", "1"],
        ["--render", "png", "--out", str(run_dir / "config.json"), "--episode", "1"],
    ):
        capsys.readouterr()
        assert replay_main([str(run_dir), *argv]) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1
    assert {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()} == files
    capsys.readouterr()
    gif = run_dir / "summary.gif"  # a .gif beside the run is fine
    assert replay_main([str(run_dir), "--render", "gif", "--out", str(gif), "--episode", "1"]) == 0


# ------------------------------------------------------------------------------ outcomes


def test_resuming_a_finished_run_adds_no_part_and_never_goes_back(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "6", "--run-dir", str(run_dir)]) == 0
    parts = sorted(p.name for p in run_dir.glob("episodes*.mcap"))
    capsys.readouterr()
    assert main(["--resume", str(run_dir), "--no-progress"]) == 0
    assert "nothing to train" in capsys.readouterr().err
    assert sorted(p.name for p in run_dir.glob("episodes*.mcap")) == parts
    assert main(["--resume", str(run_dir), "--updates", "3", "--no-progress"]) == 2
    assert "--updates 3: the run is at update 6" in capsys.readouterr().err
    _finished_and_whole(run_dir)


def test_a_run_without_a_log_stays_without_one(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "3", "--run-dir", str(run_dir), "--no-record"]) == 0
    assert main(["--resume", str(run_dir), "--updates", "6", "--no-progress"]) == 0
    assert not any(run_dir.glob("episodes*.mcap"))
    logged = tmp_path / "logged"
    assert main([*GRID, "--updates", "3", "--run-dir", str(logged)]) == 0
    capsys.readouterr()
    argv = ["--resume", str(logged), "--updates", "6", "--no-record", "--no-progress"]
    assert main(argv) == 2
    assert "--no-record" in capsys.readouterr().err


def test_a_summary_that_cannot_be_written_is_refused_before_training(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "3", "--run-dir", str(run_dir)]) == 0
    (run_dir / "summary.json").unlink()
    (run_dir / "summary.json").mkdir()
    capsys.readouterr()
    started = time.monotonic()
    assert main(["--resume", str(run_dir), "--updates", "3000", "--no-progress"]) == 2
    assert "summary.json" in capsys.readouterr().err
    assert time.monotonic() - started < 30 and checkpoint.load(run_dir)["update"] == 3


def test_a_damaged_config_json_on_resume_is_rebuilt(tmp_path):
    run_dir = tmp_path / "run"
    assert main([*GRID, "--updates", "3", "--run-dir", str(run_dir)]) == 0
    (run_dir / "config.json").write_text("[1, 2, 3]")
    assert main(["--resume", str(run_dir), "--updates", "6", "--no-progress"]) == 0
    config = json.loads((run_dir / "config.json").read_text())
    assert config["rebuilt_from_checkpoint"] and config["train"]["updates"] == 6


def test_empty_names_are_refused(tmp_path, capsys):
    assert main([*GRID, "--updates", "1", "--logdir", ""]) == 2
    assert "--logdir: an empty folder name" in capsys.readouterr().err
    assert main([*GRID, "--updates", "1", "--logdir", str(tmp_path), "--preset", ""]) == 2
    assert "unknown preset ''" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_a_logdir_through_a_dangling_link_names_the_link(tmp_path, capsys):
    link = tmp_path / "logs"
    link.symlink_to(tmp_path / "gone")
    assert main([*GRID, "--updates", "1", "--logdir", str(link)]) == 2
    err = capsys.readouterr().err
    assert "does not exist" in err and "gone" in err and "too many" not in err


@pytest.mark.slow
def test_a_killed_physics_writer_frees_its_run_at_once(tmp_path):
    """Physics workers are forked from the writer: they must not keep its run locked."""
    run_dir = tmp_path / "run"
    argv = ["--scenario", "phys", "--num-envs", "4", "--workers", "2", "--updates", "100000",
            "--run-dir", str(run_dir), "--no-progress"]  # fmt: skip
    proc = subprocess.Popen([*TRAIN, *argv], stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (run_dir / "episodes.mcap").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    proc.kill()
    proc.wait()
    with run_lock(run_dir):  # raises RunBusy if a worker still held it
        pass
