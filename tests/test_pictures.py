"""Episode pictures a person can read (issue 31): the GIF's pace, ``--size``, a collision's
and a capture's marks and captions, the legend, the text view's symbols, where the files go,
``replay --verify``'s progress and a fast ``--help``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_record import make_log

from a2cm_phys.analysis.episodes import episode_text
from a2cm_phys.analysis.pictures import GRID_FRAME_SECONDS, episode_picture
from a2cm_phys.commands import picture_options, replay
from a2cm_phys.commands.replay import main
from a2cm_phys.config import load_scenario
from a2cm_phys.envs import render
from a2cm_phys.envs.render import Contacts, legend_labels, render_rgb, render_text
from a2cm_phys.record import read_run
from a2cm_phys.record.runlog import Trajectory


@pytest.fixture(scope="module")
def grid_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("grid-run")
    make_log(path / "episodes.mcap", steps=60)
    return path


def gif_durations(path: Path) -> tuple[tuple[int, int], list[int]]:
    with Image.open(path) as im:
        durations = []
        for i in range(im.n_frames):
            im.seek(i)
            durations.append(im.info["duration"])
        return im.size, durations


def collision_ending() -> tuple[object, Trajectory]:
    """A grid_collision episode of 2 steps whose last step brings pursuers 0 and 2 into one
    cell: a collision that ends it."""
    sc = load_scenario("grid_collision")
    positions = np.array(
        [[[0, 0], [4, 0], [0, 2], [2, 4]], [[0, 1], [4, 0], [0, 2], [2, 4]],
         [[0, 2], [4, 0], [0, 2], [2, 3]]]
    )  # fmt: skip
    traj = Trajectory(
        episode=7, env=0, seed=1, t0=0.0, dt=1.0, positions=positions,
        actions=np.array([[0, 4, 4, 4], [0, 4, 4, 1]]), reward=np.array([-1e3, -1.5e8]),
        captured=np.array([False, False]), collisions=np.array([0, 1]),
        wall_contacts=np.array([0, 0]),
    )  # fmt: skip
    return sc, traj


def test_grid_gifs_play_two_frames_a_second_and_size_sets_the_width(
    grid_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "ep.gif"
    assert main([str(grid_run), "--episode", "1", "--render", "gif", "--out", str(out)]) == 0
    (width, height), durations = gif_durations(out)
    assert width == render.DEFAULT_PIXELS == picture_options.DEFAULT_PIXELS and height > width
    assert set(durations[:-1]) == {int(1000 * GRID_FRAME_SECONDS)} and durations[-1] >= 2000
    args = [str(grid_run), "--episode", "1", "--render", "gif", "--out", str(out), "--size", "200"]
    assert main(args) == 0
    assert gif_durations(out)[0][0] == 200
    assert main([*args, "--fps", "10"]) == 0
    assert set(gif_durations(out)[1][:-1]) == {100}


def test_physics_gifs_play_at_the_control_rate(tmp_path: Path) -> None:
    pytest.importorskip("pymunk")
    make_log(tmp_path / "episodes.mcap", "phys_cont", envs=1, steps=45, overrides={"max_steps": 12})
    out = tmp_path / "ep.gif"
    assert main([str(tmp_path), "--episode", "0", "--render", "gif", "--out", str(out)]) == 0
    _, durations = gif_durations(out)
    assert len(durations) == read_run(tmp_path).trajectory(0).length + 1
    assert set(durations[:-1]) == {100}  # physics.dt = 0.1 s: 10 frames a second


def test_a_collision_ending_is_marked_captioned_and_in_the_legend() -> None:
    sc, traj = collision_ending()
    picture = episode_picture(sc, traj, max_frames=10, pixels=160)
    assert picture.captions[-1].startswith("COLLISION of pursuers 0 and 2 at step")
    assert "the episode ends" in picture.captions[-1] and picture.captions[0] == ""
    assert "collision (star)" in legend_labels(sc) and "capture (ring)" in legend_labels(sc)
    assert legend_labels(sc)[:2] == ["pursuers 0, 1, 2", "evader"]
    assert "path so far" in legend_labels(load_scenario("phys"), trail=True)
    plain = render_rgb(sc, traj.positions[-1], pixels=320)
    marked = render_rgb(sc, traj.positions[-1], pixels=320, contacts=Contacts(collisions=((0, 2),)))
    yellow = [(np.abs(f.astype(int) - [255, 230, 0]).sum(-1) < 60).sum() for f in (plain, marked)]
    assert yellow[1] > yellow[0] + 50  # the star, beside the legend's


def test_the_text_view_tells_capture_from_collision() -> None:
    sc, traj = collision_ending()
    collided = render_text(sc, traj.positions[-1])
    caught = render_text(sc, np.array([[1, 1], [4, 0], [0, 4], [1, 1]]))
    assert "#" in collided and "X" not in collided and "1" in collided
    assert "X" in caught and "#" not in caught and "0" not in caught
    text = episode_text(sc, traj)
    assert render.TEXT_LEGEND in text and "ended by a collision" in text
    assert "collisions 1 (pursuers 0 and 2)" in text


def test_pictures_go_to_the_current_folder_named_after_the_run(
    grid_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    monkeypatch.chdir(tmp_path)
    before = set(grid_run.iterdir())
    argv = [str(grid_run), "--episode", "1", "2", "--render", "png", "--max-frames", "2"]
    assert main(argv) == 0
    names = [f"{grid_run.name}-ep1.png", f"{grid_run.name}-ep2.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == names
    assert set(grid_run.iterdir()) == before
    assert capsys.readouterr().out.split() == ["wrote", names[0], "wrote", names[1]]
    assert main([*argv, "--out", str(tmp_path / "x.png")]) == 0
    assert (tmp_path / "x-ep1.png").exists() and (tmp_path / "x-ep2.png").exists()


def test_verify_shows_progress_on_stderr_without_a_terminal(
    grid_run: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "0.001")
    assert main([str(grid_run), "--verify"]) == 0
    captured = capsys.readouterr()
    n = len(read_run(grid_run).logged_episodes)
    assert f"verify: started ({n:,} episodes)" in captured.err
    assert f"verify: done, {n:,}/{n:,} episodes (100%)" in captured.err
    assert "verify:" not in captured.out.replace(f"verify: {n} episodes", "")
    assert "all match" in captured.out and "none lost: holds" in captured.out


def test_help_is_quick_and_every_option_says_what_it_does() -> None:
    code = (
        "import sys; from a2cm_phys.commands.replay import build_parser;"
        "build_parser().format_help();"
        "print(sorted(m for m in ('torch', 'matplotlib', 'mcap') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    parser = replay.build_parser()
    assert all(action.help for action in parser._actions)
    text = parser.format_help()
    for default in ("(default: 480)", "(default: 10)", "(default: text)", "the control rate"):
        assert default in " ".join(text.split())
