"""``replay --serve`` and ``--export-foxglove`` without ``--episode`` (issue 32): a finished
log streams to a real Foxglove WebSocket client, and an export asks for nothing unbounded:
without ``--episode`` both take the last logged episodes and say so."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from test_live import watch
from test_record import make_log

from a2cm_phys.commands.replay import SAMPLE, main
from a2cm_phys.record import read_run

pytest.importorskip("websockets")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay_foxglove")
    make_log(path / "episodes.mcap", steps=200)
    return path


def test_an_export_without_episodes_takes_the_last_logged_and_says_so(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "scenes.mcap"
    assert main([str(run_dir), "--export-foxglove", str(out)]) == 0
    captured = capsys.readouterr()
    logged = read_run(run_dir).logged_episodes
    assert len(logged) > SAMPLE  # the fixture logs more than the sample
    assert f"taking the last {SAMPLE} logged" in captured.err
    assert f"wrote {SAMPLE} episodes" in captured.out
    with out.open("rb") as fh:
        schemas = {s.name for s in make_reader(fh).get_summary().schemas.values()}
    assert schemas == {"foxglove.SceneUpdate"}


def test_serve_streams_an_episode_to_a_client(run_dir: Path) -> None:
    episode = str(read_run(run_dir).logged_episodes[0])
    argv = [str(run_dir), "--serve", "0", "--episode", episode, "--speed", "20"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "a2cm_phys.replay", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = re.search(r"serving on (ws://\S+)", proc.stdout.readline()).group(1)
        got = watch(url, ["/scene"], 20, lambda g: len(g.messages.get("/scene", [])) >= 2)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "served 1 episodes" in out
    scene = got.decode_scene(got.messages["/scene"][0][1])
    assert {"pursuer_0", "evader"} <= {e.id for e in scene.entities}


def test_serving_an_episode_the_log_lacks_is_one_line(
    run_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(run_dir), "--serve", "0", "--episode", "999999"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
