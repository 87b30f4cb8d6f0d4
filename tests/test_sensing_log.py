"""Sensing masks in the run log (issue 33): a sensing run logs every state's masks, which
``replay --verify`` re-simulates; pictures and Foxglove scenes draw the ranges and
sightings; logs of scenarios without sensing are what they were, message for message."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from test_record import decode_scene

from a2cm_phys.analysis.pictures import episode_picture, sensing_overlay
from a2cm_phys.commands.replay import main as replay_main
from a2cm_phys.commands.train import main as train_main
from a2cm_phys.config import load_scenario
from a2cm_phys.config.scenario import Sensing
from a2cm_phys.envs.render import HEIGHT_RATIO, render_rgb
from a2cm_phys.envs.sensing import sensed
from a2cm_phys.record import read_run
from a2cm_phys.record.masks import packed, unpacked
from a2cm_phys.record.runlog import Trajectory
from a2cm_phys.record.schemas import TRAJECTORY_TOPIC, schemas_for
from a2cm_phys.record.verify import verify, verify_trajectory

ROOT = Path(__file__).resolve().parents[1]
ARGS = {
    "grid_pomdp": ["--updates", "20", "--scene-every", "5"],
    "phys_cont_pomdp": ["--updates", "3", "--num-envs", "2", "--batch-size", "64"],
}


@pytest.fixture(scope="module", params=sorted(ARGS))
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    if request.param.startswith("phys"):
        pytest.importorskip("pymunk")
    path = tmp_path_factory.mktemp("sensing_log") / request.param
    args = ["--scenario", request.param, "--seed", "3", "--run-dir", str(path)]
    assert train_main([*args, *ARGS[request.param], "--scene-every", "1", "--no-progress"]) == 0
    return path


def test_a_sensing_run_logs_the_masks_of_its_logged_positions(run: Path) -> None:
    log = read_run(run)
    sc = log.scenario
    trajs = list(log.trajectories())
    assert trajs
    for traj in trajs:
        assert traj.sensed is not None
        assert traj.sensed.shape == (traj.length + 1, sc.pursuers + 1, sc.pursuers + 1)
        assert np.array_equal(traj.sensed, sensed(sc, traj.positions))
    # somewhere a pursuer knows the evader, somewhere it does not: the masks carry information
    known = np.concatenate([t.sensed[:, : sc.pursuers, -1] for t in trajs])
    assert known.any() and not known.all()
    with open(log.parts[0], "rb") as fh:
        summary = make_reader(fh).get_summary()
    stored = {s.name: json.loads(s.data) for s in summary.schemas.values() if s.name[:4] == "a2cm"}
    assert stored["a2cm_phys.TrajectoryBlock"] == schemas_for(sc)[TRAJECTORY_TOPIC]
    assert "sensed" in stored["a2cm_phys.TrajectoryBlock"]["required"]


def test_the_masks_are_packed_one_integer_per_agent() -> None:
    masks = np.array([[[1, 0, 1], [0, 1, 1], [0, 0, 1]]], dtype=bool)
    assert packed(masks).tolist() == [[5, 6, 4]]
    assert np.array_equal(unpacked(packed(masks)), masks)


def test_verify_passes_and_a_tampered_mask_is_named(
    run: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert replay_main([str(run), "--verify"]) == 0
    assert "all match" in capsys.readouterr().out
    log = read_run(run)
    traj = next(t for t in log.trajectories() if t.length >= 2)
    k = traj.length // 2 + 1
    traj.sensed = traj.sensed.copy()
    traj.sensed[k, 0, -1] ^= True
    problem = verify_trajectory(log.scenario, traj)
    assert problem is not None and problem.startswith(f"sensing masks differ at step {k}:")
    assert verify(log, [traj]) == 1
    assert f"DIVERGED episode {traj.episode} " in capsys.readouterr().out


def test_a_log_without_masks_still_verifies(run: Path) -> None:
    """Logs written before the masks were logged have no ``sensed`` field."""
    log = read_run(run)
    doc = json.loads(log._blocks[0])
    del doc["sensed"]
    trajs = Trajectory.from_block(doc)
    assert all(t.sensed is None for t in trajs)
    assert all(verify_trajectory(log.scenario, t) is None for t in trajs[:5])


def _scenes(path: Path) -> list:
    out = []
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            if channel.topic.startswith("/scene/"):
                out.append(decode_scene(schema, channel, message.data))
    return out


def test_the_scenes_draw_the_ranges_and_the_sightings(run: Path) -> None:
    log = read_run(run)
    scenes = _scenes(log.parts[0])
    assert scenes
    grid = log.scenario.mode == "grid"
    lines = 0
    for scene in scenes:
        ent = {e.id: e for e in scene.entities}
        ranges = ent["sensing"].cubes if grid else ent["sensing"].cylinders
        assert len(ranges) == log.scenario.pursuers
        lines += len(ent["sensing"].lines) - (0 if grid else log.scenario.pursuers)
    assert lines > 0  # some frame shows a pursuer that knows the evader


def test_scenes_without_sensing_have_no_sensing_entity(tmp_path: Path) -> None:
    path = tmp_path / "grid"
    args = ["--scenario", "grid", "--updates", "5", "--run-dir", str(path), "--scene-every", "3"]
    assert train_main([*args, "--no-progress"]) == 0
    scenes = _scenes(path / "episodes.mcap")
    assert scenes and all("sensing" not in {e.id for e in s.entities} for s in scenes)
    assert all(t.sensed is None for t in read_run(path).trajectories())


def _pixel(sc, frame: np.ndarray, x: float, y: float) -> np.ndarray:
    """The frame's pixel at arena point ``(x, y)`` m (render_rgb's layout)."""
    dpi, span = frame.shape[1] / 4, sc.size + 0.3
    col = (0.2 + (x + 0.15) / span * 3.6) * dpi
    row = (4 * HEIGHT_RATIO - 0.95 - (y + 0.15) / span * 3.6) * dpi
    return frame[int(row), int(col)].astype(int)


def test_a_grid_picture_draws_each_range_where_its_cells_are() -> None:
    sc = load_scenario("grid_pomdp")
    positions = np.array([[1, 1], [4, 4], [4, 0], [2, 2]])  # pursuer 0 senses the evader
    masks = sensed(sc, positions[None])[0]
    plain = render_rgb(sc, positions)
    drawn = sensing_overlay(sc, plain, positions, masks)
    assert drawn.shape == plain.shape
    tinted = _pixel(sc, drawn, 0.5, 0.3)  # cell (0, 0): in pursuer 0's range, empty
    assert not np.array_equal(tinted, _pixel(sc, plain, 0.5, 0.3))
    assert tinted[0] > tinted[2]  # reddish: pursuer 0's colour
    for cell in ((3.5, 2.5), (2.5, 4.5)):  # out of every range: untouched
        assert np.array_equal(_pixel(sc, drawn, *cell), _pixel(sc, plain, *cell))
    # the sighting: a line from pursuer 0 to the evader, through (1.85, 1.85)
    assert not np.array_equal(_pixel(sc, drawn, 2.0, 2.0), _pixel(sc, plain, 2.0, 2.0))


def test_a_grid_pomdp_episode_picture_differs_from_one_without_sensing(run: Path) -> None:
    log = read_run(run)
    if log.scenario.mode != "grid":
        pytest.skip("one picture test is enough")
    traj = next(log.trajectories())
    blind = dataclasses.replace(log.scenario, sensing=Sensing())
    with_ranges = episode_picture(log.scenario, traj, 3, pixels=200, progress=False)
    without = episode_picture(blind, traj, 3, pixels=200, progress=False)
    assert len(with_ranges.frames) == len(without.frames)
    for a, b in zip(with_ranges.frames, without.frames, strict=True):
        assert a.shape == b.shape and not np.array_equal(a, b)


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    """Every message of a log; the updates without their wall-clock ``steps_per_s``."""
    out = []
    with open(path, "rb") as fh:
        for _, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            data = message.data
            if channel.topic in ("/train/update", "/plot/update"):
                doc = json.loads(data)
                doc.pop("steps_per_s", None)
                data = json.dumps(doc).encode()
            out.append((channel.topic, message.log_time, data))
    return out


def _schemas(path: Path) -> dict[str, bytes]:
    with open(path, "rb") as fh:
        return {s.name: s.data for s in make_reader(fh).get_summary().schemas.values()}


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv",
    [
        ["--scenario", "grid_collision", "--updates", "30", "--scene-every", "5"],
        [
            *("--scenario", "phys_cont", "--updates", "3", "--num-envs", "2"),
            *("--batch-size", "64", "--lr", "0.007"),  # pinned: defaults may change
        ],
    ],
)
def test_logs_without_sensing_are_those_of_the_committed_package(
    argv: list[str], tmp_path: Path
) -> None:
    """The same run with the package at git HEAD and with this one: the same messages, the
    same schemas (every message byte for byte; the updates' steps/s are wall clock)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs the git checkout")
    if "phys_cont" in argv:
        pytest.importorskip("pymunk")
    head = tmp_path / "head"
    head.mkdir()
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "HEAD", "a2cm_phys"], capture_output=True, check=True
    )
    subprocess.run(["tar", "-x", "-C", str(head)], input=archive.stdout, check=True)
    logs = []
    for name, package in (("head", head), ("here", ROOT)):
        cmd = [sys.executable, "-m", "a2cm_phys.train", *argv, "--seed", "3", "--run-dir", "run"]
        cwd = tmp_path / f"cwd_{name}"
        cwd.mkdir()
        env = {**os.environ, "PYTHONPATH": str(package), "OMP_NUM_THREADS": "1"}
        subprocess.run([*cmd, "--no-progress"], cwd=cwd, env=env, check=True, capture_output=True)
        logs.append(cwd / "run" / "episodes.mcap")
    assert _schemas(logs[0]) == _schemas(logs[1])
    assert _messages(logs[0]) == _messages(logs[1])
