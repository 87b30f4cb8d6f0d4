"""The run log with continuous commands and a learned evader: float actions logged bit for
bit, both teams' rewards, ``replay --verify`` exact, scenes at the control rate, trails in
replay pictures, old-format logs still read and verified."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_record import check_messages, main_verify, make_log, stamp_ns
from test_replay import rewrite

from a2cm_phys.analysis.episodes import episode_text
from a2cm_phys.analysis.pictures import episode_picture, frame_title
from a2cm_phys.commands.replay import main
from a2cm_phys.config import Scenario
from a2cm_phys.record import LogError, read_run
from a2cm_phys.record.jsontext import json_float_rows
from a2cm_phys.record.schemas import (
    FORMAT,
    SCENE_TOPIC_PREFIX,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    UPDATE_TOPIC,
)

pytest.importorskip("pymunk")

SHORT = {"max_steps": 40}
"""Episodes short enough for a test to finish several of them."""
DT_NS = 100_000_000
"""The continuous scenarios' control period, 0.1 s, in nanoseconds."""


def bits(values: np.ndarray) -> np.ndarray:
    """The float64 bit patterns of ``values`` (so ``-0.0 != 0.0`` and NaN == NaN)."""
    return np.asarray(values, dtype=np.float64).view(np.int64)


@pytest.fixture(scope="module")
def cont_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    path = tmp_path_factory.mktemp("cont") / "episodes.mcap"
    return path, make_log(path, "phys_cont", envs=2, steps=130, overrides=SHORT, scene_every=2)


def test_continuous_commands_round_trip_bit_for_bit(cont_log: tuple[Path, dict]) -> None:
    path, expected = cont_log
    log = read_run(path)
    finished = expected["finished"]
    n = expected["scenario"].pursuers
    assert log.metadata["format"] == FORMAT and log.metadata["step_seconds"] == 0.1
    assert log.n_episodes == len(finished) >= 4
    zeros = 0
    for j, (e, data) in enumerate(finished):
        traj = log.trajectory(j)
        assert traj.continuous and traj.actions.shape == (e.length, n + 1, 2)
        np.testing.assert_array_equal(bits(traj.actions), bits(np.array(data["act"])))
        pursuers = traj.actions[:, :n].astype(np.float32)  # what the policy gave, float32
        np.testing.assert_array_equal(pursuers.view(np.int32), np.array(data["act"])[:, :n]
                                      .astype(np.float32).view(np.int32))  # fmt: skip
        zeros += int(np.sum(bits(traj.actions) == bits(-0.0)))
        np.testing.assert_array_equal(traj.positions, np.array(data["pos"]))
        np.testing.assert_array_equal(traj.velocities, np.array(data["vel"]))
        assert traj.dt == 0.1 and traj.evader_reward is None
        assert log.episodes["t1"][j] - log.episodes["t0"][j] == pytest.approx(0.1 * e.length)
    assert zeros > 0  # -0.0 was logged with its sign
    assert "evader_return" not in log.episodes


def test_continuous_log_verifies_exactly(cont_log: tuple[Path, dict]) -> None:
    assert main_verify(read_run(cont_log[0])) == 0


def _turn_pursuer_0(doc: dict) -> None:
    """Pursuer 0's first command in the block, pointed the other way along x (it starts
    0.2 m from the walls, further than one control period takes it)."""
    row = doc["actions"][0]
    row[0], row[1] = (1.0, 0.0) if row[0] < 0 else (-1.0, 0.0)


def _nudge_evader(doc: dict) -> None:
    """The scripted evader's first command, one float64 ulp off: only an exact log passes."""
    row = doc["actions"][0]
    row[-1] = float(np.nextafter(row[-1], 2.0))


@pytest.mark.parametrize(
    "edit, what", [(_turn_pursuer_0, "positions"), (_nudge_evader, "evader action")]
)
def test_verify_catches_a_tampered_command(
    cont_log: tuple[Path, dict],
    tmp_path: Path,
    edit: object,
    what: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bad = tmp_path / "tampered.mcap"
    rewrite(cont_log[0], bad, edit)
    assert main([str(bad), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "DIVERGED episode 0 " in out and f"{what} differ at step 1" in out
    assert "1 DIVERGED" in out


def test_scenes_and_clock_run_at_the_control_rate(cont_log: tuple[Path, dict]) -> None:
    path, expected = cont_log
    seen = check_messages(path)  # every scene decodes with the Foxglove SDK's own schema
    scenes = [m for t, ms in seen.items() if t.startswith(SCENE_TOPIC_PREFIX) for m in ms]
    drawn = [e for j, (e, _) in enumerate(expected["finished"]) if j % 2 == 0]
    assert len(scenes) == sum(e.length + 1 for e in drawn)
    for log_time, scene in scenes:
        assert stamp_ns(scene.entities[0]) == log_time
        assert log_time % DT_NS == 0  # a control step, not a whole second
    e = expected["finished"][0][0]  # drawn first in its game: its frames come first there
    frames = [t for t, _ in seen[f"{SCENE_TOPIC_PREFIX}{e.env}"][: e.length + 1]]
    assert set(np.diff(frames).tolist()) == {DT_NS}  # the states of an episode, 0.1 s apart
    updates = seen[UPDATE_TOPIC]
    for k, (log_time, doc) in enumerate(updates):
        assert log_time == (k + 1) * 8 * DT_NS and doc["env_steps"] == (k + 1) * 8 * 2
    for _, doc in seen[TRAJECTORY_TOPIC]:
        assert doc["dt"] == 0.1
        want = np.concatenate([np.arange(n + 1) * 0.1 for n in doc["length"]])
        assert doc["time"] == want.tolist()  # each state's time since its episode's start


def test_exported_scenes_run_at_the_control_rate(cont_log: tuple[Path, dict], tmp_path: Path):
    from mcap.reader import make_reader

    out = tmp_path / "scenes.mcap"
    assert main([str(cont_log[0]), "--export-foxglove", str(out), "--episode", "0"]) == 0
    with open(out, "rb") as fh:
        times = [m.log_time for _, _, m in make_reader(fh).iter_messages()]
    assert len(times) == read_run(cont_log[0]).trajectory(0).length + 1
    assert set(np.diff(times).tolist()) == {DT_NS}


def drift(sc: Scenario, rng: np.random.Generator, envs: int) -> tuple[np.ndarray, None]:
    """Commands towards the top right, with some noise: paths long enough to see."""
    noise = rng.uniform(-0.3, 0.3, size=(envs, sc.pursuers, 2))
    return (np.array([0.8, 0.5]) + noise).astype(np.float32), None


def test_gif_frames_draw_the_paths_as_trails(tmp_path: Path) -> None:
    from a2cm_phys.envs.render import render_rgb

    make_log(tmp_path / "episodes.mcap", "phys_cont", envs=1, steps=45, overrides=SHORT,
             policy=drift)  # fmt: skip
    log = read_run(tmp_path)
    traj = log.trajectory(0)
    assert traj.length == 40  # no capture: the pursuers drift towards the top-right corner
    picture = episode_picture(log.scenario, traj, max_frames=5)
    assert picture.steps == [0, 10, 20, 30, 40]
    trail_pixels = []  # pixels that differ from the same picture drawn without trails
    for k, frame, caption in zip(picture.steps, picture.frames, picture.captions, strict=True):
        title = frame_title(log.scenario, traj, k, stride=10)
        bare = render_rgb(log.scenario, traj.positions[k], traj.velocities[k], title,
                          trail=traj.positions[:0], caption=caption)  # fmt: skip
        trail_pixels.append(int((frame != bare).any(-1).sum()))
    assert trail_pixels[0] == 0 and trail_pixels[-1] > 300
    assert trail_pixels == sorted(set(trail_pixels))  # the trails grow with the path
    out = tmp_path / "ep.gif"
    args = [str(tmp_path), "--episode", "0", "--render", "gif", "--out", str(out)]
    assert main([*args, "--max-frames", "7"]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 7


def test_episode_text_shows_commands(cont_log: tuple[Path, dict]) -> None:
    log = read_run(cont_log[0])
    text = episode_text(log.scenario, log.trajectory(0))
    assert "actions 0:(" in text and " E:(" in text and "s), return" in text


# --------------------------------------------------------------------------- learned evader


@pytest.fixture(scope="module", params=["grid_vs", "phys_vs", "phys_cont_vs"])
def vs_log(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    name = request.param
    path = tmp_path_factory.mktemp(name) / "episodes.mcap"
    grid = name == "grid_vs"
    expected = make_log(path, name, envs=3, steps=150 if grid else 90,
                        overrides=None if grid else SHORT, scene_every=3)  # fmt: skip
    return path, expected


def test_both_teams_are_logged(vs_log: tuple[Path, dict]) -> None:
    path, expected = vs_log
    log = read_run(path)
    finished = expected["finished"]
    n = expected["scenario"].pursuers
    assert log.n_episodes == len(finished) >= 3
    for j, (e, data) in enumerate(finished):
        traj = log.trajectory(j)
        assert log.episodes["evader_return"][j] == e.evader_ret
        assert log.episodes["return"][j] == e.ret
        np.testing.assert_array_equal(traj.evader_reward, data["erew"])
        np.testing.assert_array_equal(bits(traj.actions), bits(np.array(data["act"])))
        assert traj.actions.shape[1] == n + 1  # the evader's actions are the last agent's
    check_messages(path)


def test_learned_evader_logs_verify(vs_log: tuple[Path, dict]) -> None:
    assert main_verify(read_run(vs_log[0])) == 0


def _change_evader_action(doc: dict) -> None:
    """The learned evader's first action, changed (it starts in the middle, far from walls)."""
    row = doc["actions"][0]
    if isinstance(row[-1], int):
        row[-1] = (row[-1] + 1) % 4
    else:
        row[-2], row[-1] = (1.0, 0.0) if row[-2] < 0 else (-1.0, 0.0)


def _change_evader_return(doc: dict) -> None:
    doc["evader_return"][0] += 1


@pytest.mark.parametrize(
    "edit, topic, what",
    [
        (_change_evader_action, TRAJECTORY_TOPIC, "positions differ at step 1"),
        (_change_evader_return, SUMMARY_TOPIC, "summary evader_return is"),
    ],
)
def test_verify_catches_a_tampered_evader(
    vs_log: tuple[Path, dict],
    tmp_path: Path,
    edit: object,
    topic: str,
    what: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bad = tmp_path / "tampered.mcap"
    rewrite(vs_log[0], bad, edit, topic=topic)
    assert main([str(bad), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "DIVERGED episode 0 " in out and what in out and "1 DIVERGED" in out


def test_a_format_1_log_still_reads_and_verifies(vs_log: tuple[Path, dict], tmp_path: Path):
    """Format 1 logged the evader's actions but not its rewards; the clock was 1 s a step
    (so it only ever held discrete runs: the physics case here is a stand-in)."""
    old = tmp_path / "old.mcap"

    def as_format_1(meta: dict) -> None:
        meta["format"] = json.dumps("a2cm_phys.episodes/1")

    rewrite(vs_log[0], old, lambda doc: doc.pop("evader_reward"), every=True,
            metadata=as_format_1)  # fmt: skip
    rewrite(old, tmp_path / "episodes.mcap", lambda doc: doc.pop("evader_return"),
            topic=SUMMARY_TOPIC, every=True)  # fmt: skip
    log = read_run(tmp_path / "episodes.mcap")
    assert log.metadata["format"] == "a2cm_phys.episodes/1"
    assert "evader_return" not in log.episodes and log.trajectory(0).evader_reward is None
    assert main_verify(log) == 0


def test_a_newer_format_is_refused(grid_path: Path, tmp_path: Path) -> None:
    newer = tmp_path / "newer.mcap"

    def as_format_99(meta: dict) -> None:
        meta["format"] = json.dumps("a2cm_phys.episodes/99")

    rewrite(grid_path, newer, lambda doc: None, metadata=as_format_99)
    with pytest.raises(LogError, match="newer than this a2cm_phys reads"):
        read_run(newer)


@pytest.fixture
def grid_path(tmp_path: Path) -> Path:
    make_log(tmp_path / "g.mcap", steps=40)
    return tmp_path / "g.mcap"


def test_float_rows_are_exact_json() -> None:
    values = np.array(
        [[-0.0, 5e-324, float(np.float32(0.1)), 1 / 3], [np.nan, np.inf, -1e300, 2.0]]
    )
    back = np.array(json.loads(json_float_rows(values)), dtype=np.float64)
    np.testing.assert_array_equal(bits(back[0]), bits(values[0]))
    assert np.isnan(back[1, :2]).all() and back[1, 2:].tolist() == [-1e300, 2.0]
    assert json_float_rows(values[:1]) == b"[[-0.0,5e-324,0.10000000149011612,0.3333333333333333]]"
