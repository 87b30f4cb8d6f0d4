"""Physics worker processes end with the trainer, whatever signal ended it (issue 15)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/task").exists(), reason="reads child processes from /proc (Linux)"
)


def _children(pid: int) -> list[int]:
    kids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids += [int(k) for k in (task / "children").read_text().split()]
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")  # a zombie has ended; only its exit status is left


def _start_trainer(tmp_path: Path) -> tuple[subprocess.Popen[str], list[int]]:
    cmd = [
        sys.executable, "-m", "a2cm_phys.train", "--scenario", "phys", "--num-envs", "4",
        "--workers", "3", "--updates", "100000", "--no-progress", "--logdir", str(tmp_path),
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    assert proc.stderr is not None
    line = proc.stderr.readline()  # printed once the workers are up
    assert line.startswith("run directory:"), line
    workers = _children(proc.pid)
    assert len(workers) == 2 and all(_alive(w) for w in workers)  # the trainer steps a slice
    return proc, workers


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM])
def test_workers_end_with_the_trainer(tmp_path: Path, signum: int) -> None:
    proc, workers = _start_trainer(tmp_path)
    try:
        os.kill(proc.pid, signum)
        proc.wait(timeout=120)
        deadline = time.monotonic() + 60  # a bound on waiting, not a timing requirement
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(w) for w in workers)
    finally:
        proc.kill()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)
