"""Fault injection for the run log's invariant (used by ``tests/test_faults.py`` and, with
more trials, by ``benchmarks/fault_trials.py``): train in a child process, kill it with
SIGKILL at a random instant or at a chosen write, resume, and check after every kill that
the log holds every episode the checkpoints count, once (:mod:`a2cm_phys.record.integrity`).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from a2cm_phys.analysis.episodes import integrity_problems
from a2cm_phys.record import read_run
from a2cm_phys.training import checkpoint

TRAIN = [sys.executable, "-m", "a2cm_phys.train"]


def new_run_args(run_dir: Path, updates: int, checkpoint_every: int, scenario: str) -> list[str]:
    """A small, fast training run of ``scenario`` into ``run_dir``."""
    return [
        "--scenario", scenario, "--num-envs", "4", "--batch-size", "32", "--seed", "1",
        "--updates", str(updates), "--run-dir", str(run_dir),
        "--checkpoint-every", str(checkpoint_every),
    ]  # fmt: skip


def invariant_problems(run_dir: Path, finished: bool = False) -> list[str]:
    """What breaks the invariant now (``replay --verify``'s check, without re-simulating);
    a finished run must have its summary, which is then held against the log."""
    if finished and not (run_dir / "summary.json").is_file():
        return [f"{run_dir}: finished without summary.json"]
    return integrity_problems(run_dir, read_run(run_dir))


@dataclass
class Trial:
    """One run killed ``kills`` times and resumed to its end: what each kill left."""

    after_kill: list[tuple[int, int]] = field(default_factory=list)  # (checkpoint, log) episodes
    problems: list[str] = field(default_factory=list)
    summary_episodes: int = 0
    log_episodes: int = 0
    verified: int = 0


def kill_trial(
    run_dir: Path,
    seed: int,
    kills: int,
    *,
    updates: int = 4000,
    checkpoint_every: int = 3,
    scenario: str = "grid_collision",
    window: float = 2.0,
) -> Trial:
    """Start the run, SIGKILL it ``kills`` times, each at an instant drawn uniformly from
    the first ``window`` seconds of its session's training (from the moment its log part
    appears), resume after each kill, then let it finish."""
    rng = np.random.default_rng(seed)
    trial = Trial()
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    for k in range(kills):
        args = (
            new_run_args(run_dir, updates, checkpoint_every, scenario)
            if k == 0
            else ["--resume", str(run_dir), "--checkpoint-every", str(checkpoint_every)]
        )
        parts = len(list(run_dir.glob("episodes*.mcap")))
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        proc = subprocess.Popen([*TRAIN, *args, "--no-progress"], env=env, **quiet)
        deadline = time.monotonic() + 60
        while len(list(run_dir.glob("episodes*.mcap"))) == parts and proc.poll() is None:
            if time.monotonic() > deadline:
                break
            time.sleep(0.01)
        time.sleep(float(rng.uniform(0, window)))
        if proc.poll() is not None:
            break
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        trial.problems += [f"after kill {k}: {p}" for p in _now(run_dir, trial)]
    done = subprocess.run([*TRAIN, "--resume", str(run_dir), "--no-progress"], env=env,
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        trial.problems.append(f"final resume exited {done.returncode}: {done.stderr[-500:]}")
        return trial
    trial.problems += invariant_problems(run_dir, finished=True)
    trial.summary_episodes = json.loads((run_dir / "summary.json").read_text())["episodes"]
    trial.log_episodes = read_run(run_dir).n_episodes
    verify = subprocess.run([sys.executable, "-m", "a2cm_phys.replay", str(run_dir), "--verify"],
                            capture_output=True, text=True)  # fmt: skip
    if verify.returncode != 0:
        trial.problems.append(f"replay --verify exited {verify.returncode}: {verify.stdout[-800:]}")
    for line in verify.stdout.splitlines():
        if line.startswith("verify:"):
            trial.verified = int(line.split()[1])
    return trial


def _now(run_dir: Path, trial: Trial) -> list[str]:
    """The invariant right after a kill; records (checkpoint episodes, log episodes)."""
    if not any(run_dir.glob("episodes*.mcap")):
        return []  # killed before the log began: nothing to lose yet
    counts, _ = checkpoint.saved_counts(run_dir)
    latest = max((c.episodes for c in counts), default=0)
    try:
        n = read_run(run_dir).n_episodes
    except Exception as err:
        return [f"unreadable log: {err}"]
    trial.after_kill.append((latest, n))
    return invariant_problems(run_dir)


KILL_AT_WRITE = r"""
import os, sys
from a2cm_phys.record.writer import EpisodeRecorder
target, calls = int(sys.argv[1]), [0]
def counted(fn):
    def wrapper(*args, **kwargs):
        calls[0] += 1
        if calls[0] == target:
            os._exit(137)  # as SIGKILL: no cleanup, no flush
        return fn(*args, **kwargs)
    return wrapper
os.fsync = counted(os.fsync)
os.replace = counted(os.replace)
os.link = counted(os.link)
EpisodeRecorder._write = counted(EpisodeRecorder._write)
from a2cm_phys.train import main
sys.exit(main(sys.argv[2:]))
"""
"""A child that runs ``train`` and dies at its N-th write, fsync, link or rename."""


def kill_at_write(run_dir: Path, target: int, argv: list[str]) -> int:
    """Run ``train argv`` in a child that dies at its ``target``-th write call; its status."""
    proc = subprocess.run([sys.executable, "-c", KILL_AT_WRITE, str(target), *argv],
                          capture_output=True, text=True)  # fmt: skip
    return proc.returncode
