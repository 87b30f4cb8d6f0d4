"""Foxglove's own JavaScript libraries against our server and our logs: the live view watched
by ``@foxglove/ws-protocol``'s ``FoxgloveClient`` (which offers only the protocol's older
name, ``foxglove.websocket.v1``), and a main job's log read by ``@mcap/core``'s indexed
reader. The packages are installed with ``npm ci`` into ``tests/js`` (their lock file is
kept there); without node or npm, or without the registry, the tests are skipped saying so."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from test_live import Training

from a2cm_phys.config import load_scenario
from a2cm_phys.training.live import LiveView

JS = Path(__file__).parent / "js"


@pytest.fixture(scope="module")
def node() -> str:
    """The ``node`` executable, with ``tests/js``'s packages installed."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node and npm are needed to run Foxglove's JavaScript client and reader")
    if not (JS / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        done = subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts"],
            cwd=JS,
            capture_output=True,
            text=True,
            timeout=600,
        )
        if done.returncode != 0:
            pytest.skip(f"npm ci in {JS} failed: {done.stderr.strip()[-300:]}")
    return node


def run_js(node: str, script: str, *args: str) -> dict:
    """Run ``tests/js/SCRIPT`` and return the JSON object it prints."""
    done = subprocess.run(
        [node, str(JS / script), *args], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_foxglove_client_watches_the_live_view(node: str) -> None:
    sc = load_scenario("grid_collision")
    with LiveView.open(sc, "127.0.0.1", 0) as live, Training(live):
        got = run_js(node, "watch.mjs", live.url, "20", "4")
    assert got["protocol"] == "foxglove.websocket.v1"
    assert got["serverName"] == "a2cm_phys training"
    assert got["channels"]["/scene"] == {
        "encoding": "protobuf",
        "schemaName": "foxglove.SceneUpdate",
    }
    scenes = got["scenes"]
    assert len(scenes) >= 4
    assert all(
        {"arena", "evader", "trails", "contacts"} | {f"pursuer_{i}" for i in range(3)}
        <= set(s["ids"])
        for s in scenes
    )
    stamps = [s["timestamp"] for s in scenes]
    assert stamps == sorted(stamps)
    assert [s["caption"].split()[2] for s in scenes] == ["step"] * len(scenes)
    updates = got["plots"]["/plot/update"]
    assert updates and all(p["policy_loss"] == 0.5 for p in updates)


def test_indexed_reader_reads_a_main_job_log(node: str, tmp_path: Path) -> None:
    run = tmp_path / "run"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "a2cm_phys.train",
            "--scenario",
            "grid_collision",
            "--updates",
            "30",
            "--run-dir",
            str(run),
            "--no-progress",
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    log = run / "episodes.mcap"
    got = run_js(node, "read_mcap.mjs", str(log))
    with log.open("rb") as fh:
        reader = make_reader(fh)
        counts = Counter(channel.topic for _, channel, _ in reader.iter_messages())
        schemas = {channel.topic: schema.name for schema, channel, _ in reader.iter_messages()}
    assert {t: v["count"] for t, v in got["topics"].items()} == dict(counts)
    assert {t: v["schema"] for t, v in got["topics"].items()} == schemas
    assert got["topics"]["/train/update"]["count"] == 30
    assert got["topics"]["/episodes/trajectories"]["count"] >= 1
