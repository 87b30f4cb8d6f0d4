"""Sweeps under faults: a run another process writes is reported busy and left alone (two
sweeps of one --logdir never run one run twice), SIGTERM stops a sweep resumably with 143,
the summary files are written whole or not at all and name only what was written, and a
--logdir that is empty or a link to nothing is refused."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from a2cm_phys.base.exitcodes import EXIT_NO_SPACE
from a2cm_phys.commands import sweep
from a2cm_phys.study.rundirs import run_state
from a2cm_phys.training.rundir import run_lock

TINY = {"updates": 4, "num_envs": 4, "batch_size": 16}
LONG = {**TINY, "updates": 20_000}  # a run that is still going when the test stops it


def _args(logdir: Path, *extra: str, train: dict[str, int] = TINY) -> list[str]:
    args = ["--scenarios", "grid", "--algos", "a2cm", "--seeds", "0", "--sequential",
            "--logdir", str(logdir), "--no-record"]  # fmt: skip
    return [*args, *(f"--set=train.{k}={v}" for k, v in train.items()), *extra]


def _runs(logdir: Path) -> dict[str, dict]:
    return {r["run"]: r for r in json.loads((logdir / "sweep_summary.json").read_text())["runs"]}


def _start(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "a2cm_phys.sweep", *args]
    return subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(path: Path, proc: subprocess.Popen[str], seconds: float = 120) -> None:
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.1)


def _stopped(proc: subprocess.Popen[str], signum: int) -> str:
    """Send ``signum``; the stderr of the process once it has ended."""
    proc.send_signal(signum)
    return proc.communicate(timeout=120)[1]


def test_a_run_another_process_writes_is_reported_busy_and_left_alone(tmp_path, capsys):
    logdir = tmp_path / "sweep"
    held = logdir / "grid-a2cm-s0"
    held.mkdir(parents=True)
    with run_lock(held):  # as a train --run-dir or another sweep holds it
        assert sweep.main(_args(logdir, "--seeds", "0-1")) == 0
    out = "".join(capsys.readouterr())
    assert f"grid-a2cm-s0: busy ({held}: another process (pid {os.getpid()})" in out
    assert "grid-a2cm-s1: ran" in out
    assert [p.name for p in held.iterdir()] == [".lock"]  # no config, checkpoint, summary
    runs = _runs(logdir)
    assert runs["grid-a2cm-s0"]["outcome"] == "busy" and runs["grid-a2cm-s0"]["summary"] is None
    assert f"pid {os.getpid()}" in runs["grid-a2cm-s0"]["busy"]
    assert runs["grid-a2cm-s1"]["outcome"] == "ran"
    assert "| grid | a2cm | 1 |" in out  # the table holds the run that ran, not the busy one
    assert sweep.main(_args(logdir, "--seeds", "0-1")) == 0  # once free, it runs
    assert {k: r["outcome"] for k, r in _runs(logdir).items()} == {
        "grid-a2cm-s0": "ran",
        "grid-a2cm-s1": "skipped",
    }


def test_a_second_sweep_leaves_the_first_ones_run_alone_and_sigterm_stops_the_first(
    tmp_path, capsys
):
    logdir = tmp_path / "sweep"
    args = _args(logdir, train=LONG)
    first = _start(args, tmp_path)
    run_dir = logdir / "grid-a2cm-s0"
    try:
        _wait_for(run_dir / "checkpoint.pt", first)  # the first sweep trains this run
        config = (run_dir / "config.json").read_bytes()
        assert sweep.main(args) == 0
        out = "".join(capsys.readouterr())
        assert f"grid-a2cm-s0: busy ({run_dir}: another process (pid {first.pid})" in out
        assert _runs(logdir)["grid-a2cm-s0"]["outcome"] == "busy"
        assert (run_dir / "config.json").read_bytes() == config
        assert not (run_dir / "summary.json").exists()
    finally:
        err = _stopped(first, signal.SIGTERM)
    assert first.returncode == 128 + signal.SIGTERM, err
    assert "interrupted (SIGTERM)" in err and "run the same command to resume" in err
    assert json.loads((run_dir / "summary.json").read_text())["status"] == "interrupted"
    assert run_state(run_dir) == "partial"  # the same command resumes it


@pytest.mark.slow
def test_sigterm_stops_a_sweep_on_ray_resumably_with_143(tmp_path):
    pytest.importorskip("ray")
    logdir = tmp_path / "sweep"
    args = [a for a in _args(logdir, train=LONG) if a != "--sequential"]
    proc = _start(args, tmp_path)
    run_dir = logdir / "grid-a2cm-s0"
    try:
        _wait_for(run_dir / "checkpoint.pt", proc)
    finally:
        err = _stopped(proc, signal.SIGTERM)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "interrupted (SIGTERM)" in err and "run the same command to resume" in err
    assert "Traceback" not in err and "SIGTERM received" not in err  # no Ray stack dump
    assert json.loads((run_dir / "summary.json").read_text())["status"] == "interrupted"
    assert run_state(run_dir) == "partial"


def test_a_sweep_whose_runs_all_fail_says_so_and_names_only_what_it_wrote(tmp_path, capsys):
    logdir = tmp_path / "sweep"
    logdir.mkdir()
    (logdir / "sweep_summary.csv").write_text("an older sweep's table\n")
    args = _args(logdir, "--seeds", "0-1", "--set", "train.reward_scale=1e300")
    assert sweep.main(args) == 1
    out, err = capsys.readouterr()
    assert "every run failed (2 of 2)" in err
    assert f"summary: {logdir / 'sweep_summary.json'}\n" in out and ".csv" not in out
    assert not (logdir / "sweep_summary.csv").exists()  # it described another sweep
    assert [r["outcome"] for r in _runs(logdir).values()] == ["failed", "failed"]


def test_a_summary_that_cannot_be_written_leaves_the_last_one_whole(tmp_path, capsys):
    resource = pytest.importorskip("resource")
    logdir = tmp_path / "sweep"
    assert sweep.main(_args(logdir)) == 0
    before = {p: p.read_bytes() for p in logdir.glob("sweep_summary.*")}
    assert len(before) == 2
    capsys.readouterr()  # in memory: the file-size limit below must not hit the capture
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    xfsz = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG past the limit, not a kill
    resource.setrlimit(resource.RLIMIT_FSIZE, (100, hard))  # as a full disk would
    try:
        status = sweep.main(_args(logdir))  # the run is done: only the summary is written
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, xfsz)
    err = capsys.readouterr().err
    assert status == EXIT_NO_SPACE and "sweep_summary" in err
    assert {p: p.read_bytes() for p in before} == before
    assert not list(logdir.glob(".*.tmp"))


@pytest.mark.parametrize(
    ("logdir", "message"),
    [("", "empty"), ("link", "which does not exist"), ("link/sub", "which does not exist")],
)
def test_a_logdir_empty_or_through_a_link_to_nothing_is_refused(
    tmp_path, monkeypatch, capsys, logdir, message
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "link").symlink_to(tmp_path / "nowhere")
    assert sweep.main([*_args(tmp_path), "--logdir", logdir]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --logdir") and message in err and err.count("\n") == 1
    assert [p.name for p in tmp_path.iterdir()] == ["link"]  # nothing written, here or there
