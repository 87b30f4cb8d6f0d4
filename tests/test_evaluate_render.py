"""``evaluate … --render gif|png`` (issue 34): an episode the pursuers play, drawn as
``replay`` draws a logged one, for a pretrained team right after installing (no run
directory); the episodes played are the trajectories a log would hold; bad picture options
are one line, exit 2, before anything is played."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from PIL import Image

from a2cm_phys.analysis.evaluation import play
from a2cm_phys.analysis.pictures import GRID_FRAME_SECONDS
from a2cm_phys.analysis.playback import picture_stem, play_episodes
from a2cm_phys.analysis.policies import matchup
from a2cm_phys.commands.evaluate import main
from a2cm_phys.config import load_scenario
from a2cm_phys.envs.factory import make_core
from a2cm_phys.record.verify import verify_trajectory

QUICK = ["--reference", "none", "--no-progress"]


def gif_frames(path: Path) -> tuple[int, list[int], tuple[int, int]]:
    """A GIF's frame count, each frame's milliseconds and its size."""
    with Image.open(path) as im:
        durations = []
        for i in range(im.n_frames):
            im.seek(i)
            durations.append(im.info["duration"])
        return im.n_frames, durations, im.size


def test_a_pretrained_team_is_drawn_with_one_frame_a_state_and_its_capture_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    argv = ["--pursuers", "pretrained:grid_collision", "--greedy", "--episodes", "16"]
    assert main([*argv, *QUICK, "--render", "gif"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("grid_collision: pretrained:grid_collision (greedy)")  # the report
    wrote = out[-1]
    assert wrote.startswith("wrote pretrained-grid_collision-ep0.gif (episode 0, ")
    assert "CAPTURE: pursuer" in wrote and "caught the evader at step" in wrote
    frames, durations, (width, height) = gif_frames(tmp_path / "pretrained-grid_collision-ep0.gif")
    length = int(wrote.split(", ")[1].split()[0])
    assert frames == length + 1  # the start and the state after every step
    assert set(durations[:-1]) == {int(1000 * GRID_FRAME_SECONDS)} and durations[-1] >= 2000
    assert width == 480 and height > width

    # --json lists the pictures in the report; --out names the file, -epN with several
    gif = tmp_path / "sub" / "team.gif"
    args = [*argv, *QUICK, "--json", "--render", "gif", "--out", str(gif)]
    assert main([*args, "--render-episodes", "2", "--size", "200"]) == 0
    pictures = json.loads(capsys.readouterr().out)["pictures"]
    assert [p["file"] for p in pictures] == [str(gif.with_name(f"team-ep{k}.gif")) for k in (0, 1)]
    for p in pictures:
        assert p["ending"].startswith("CAPTURE: pursuer") and p["frames"] == p["length"] + 1
        frames, _, (width, _) = gif_frames(Path(p["file"]))
        assert frames == p["length"] + 1 and width == 200
    assert pictures[0]["length"] == length  # same seed, greedy: the same first episode


def test_the_episodes_drawn_are_those_the_evaluation_plays_and_a_log_would_hold() -> None:
    """Greedy, the first episode drawn is the evaluation's first in its first game; every
    one re-simulates bit for bit from its seed and actions, as ``replay --verify`` checks."""
    sc = load_scenario("grid_collision")
    game = matchup(sc, "pretrained:grid_collision", greedy=True)
    trajs = play_episodes(game, 5, seed=3, progress=False)
    evaluated = play(game.scenario, game.pursuers, 32, 16, 3)
    assert [t.episode for t in trajs] == list(range(5))
    assert trajs[0].length == evaluated.lengths[0]
    assert all(t.captured[-1] and not t.captured[:-1].any() for t in trajs)
    assert trajs[1].t0 == trajs[0].length  # one game's clock, one second a step
    core = make_core(game.scenario, 1)
    assert [verify_trajectory(game.scenario, t, core) for t in trajs] == [None] * 5
    sampled = matchup(sc, "random", greedy=False)
    trajs = play_episodes(sampled, 3, seed=3, progress=False)
    assert [verify_trajectory(sc, t, core) for t in trajs] == [None] * 3


def test_physics_episodes_carry_their_contacts_and_are_drawn(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("pymunk")
    sc = load_scenario("phys")
    game = matchup(sc, "pursuit", greedy=True)
    (traj,) = play_episodes(game, 1, seed=0, progress=False)
    assert verify_trajectory(game.scenario, traj, make_core(game.scenario, 1)) is None
    assert any(kind == "pursuer_evader" for kind, *_ in traj.events)  # the capture's contact

    out = tmp_path / "phys.png"
    argv = ["--pursuers", "pretrained:phys_cont", "--greedy", "--episodes", "2"]
    argv += ["--num-envs", "2", *QUICK, "--json", "--render", "png", "--out", str(out)]
    assert main([*argv, "--max-frames", "4", "--size", "160"]) == 0
    (picture,) = json.loads(capsys.readouterr().out)["pictures"]
    assert picture["file"] == str(out) and picture["frames"] == 4
    assert picture["ending"].startswith("CAPTURE: pursuer") and "(t = " in picture["ending"]
    with Image.open(out) as im:
        assert im.size[0] == 4 * 160  # a contact sheet of 4 frames in a row


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--render", "gif", "--out", "x.png"], "--out x.png: expected a .gif file"),
        (["--render", "png", "--out", "{tmp}/sheet.png"], "is a folder"),
        (["--render", "gif", "--out", "{tmp}/file/x.gif"], "--out {tmp}/file: is a file"),
        (["--out", "x.gif"], "--out draws pictures: give --render gif|png"),
        (["--render-episodes", "3"], "--render-episodes draws pictures"),
        (["--render", "gif", "--cross-play"], "not with --cross-play"),
    ],
)
def test_bad_picture_options_are_one_line_before_anything_is_played(
    extra: list[str], words: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "sheet.png").mkdir()
    (tmp_path / "file").write_text("a file, not a folder")
    extra = [e.replace("{tmp}", str(tmp_path)) for e in extra]
    words = words.replace("{tmp}", str(tmp_path))
    argv = ["--pursuers", "pretrained:grid_collision", "--episodes", "100000000"]
    assert main([*argv, "--no-progress", *extra]) == 2
    captured = capsys.readouterr()
    assert words in captured.err and captured.err.count("\n") == 1 and captured.out == ""


def test_default_names_say_whose_episode_it_is(tmp_path: Path) -> None:
    assert picture_stem("pretrained:phys_cont", "phys_cont") == "pretrained-phys_cont"
    assert picture_stem(f"onnx:{tmp_path}/team", "grid") == "onnx-team"
    assert picture_stem("oracle", "grid_collision") == "oracle-grid_collision"
    run = tmp_path / "grid-a2cm-s0-20260101-000000"
    run.mkdir()
    (run / "checkpoint.pt").write_bytes(b"")
    assert picture_stem(str(run), "grid") == picture_stem(str(run / "checkpoint.pt"), "grid")
    assert picture_stem(str(run), "grid") == run.name
