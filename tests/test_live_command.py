"""``train --live`` as a user types it (issue 32): the run serves Foxglove while it trains,
a real WebSocket client receives scenes and learning-curve points that decode, Ctrl-C
still leaves a resumable run, and a busy port is one line, exit 2, with nothing written."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from test_live import watch

pytest.importorskip("websockets")


def train(run_dir: Path, *extra: str) -> subprocess.Popen[str]:
    """A long main-job run serving its live view on a free port."""
    argv = ["--scenario", "grid_collision", "--updates", "100000", "--run-dir", str(run_dir)]
    return subprocess.Popen(
        [sys.executable, "-m", "a2cm_phys.train", *argv, "--no-progress", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )


def test_a_client_watches_a_training_run_live(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    proc = train(run_dir, "--live", "0")
    try:
        url = ""
        while not url:
            line = proc.stderr.readline()
            assert line, "train ended before serving"
            found = re.search(r"live view: (ws://\S+)", line)
            url = found.group(1) if found else ""
        topics = ["/scene", "/plot/episodes", "/plot/update"]
        got = watch(url, topics, 30, lambda g: all(len(g.messages.get(t, [])) >= 3 for t in topics))
        proc.send_signal(signal.SIGINT)
        assert proc.wait(60) == 130
    finally:
        proc.kill()
    assert all(len(got.messages.get(t, [])) >= 3 for t in topics)
    scene = got.decode_scene(got.messages["/scene"][0][1])
    assert {"pursuer_0", "evader"} <= {e.id for e in scene.entities}
    point = got.json("/plot/episodes")[0][1]
    assert {"episode", "return", "captured"} <= set(point)
    assert (run_dir / "checkpoint.pt").is_file()  # interrupted, resumable as ever


def test_a_busy_port_is_one_line_and_writes_nothing(tmp_path: Path) -> None:
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        proc = train(tmp_path / "run", "--live", str(port))
        _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 2
    assert err.count("\n") == 1 and f"127.0.0.1:{port}" in err and err.startswith("error:")
    assert not (tmp_path / "run").exists()
