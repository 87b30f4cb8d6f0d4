"""A training run's progress: the bar fits 80 columns with whole figures; without a terminal,
plain lines with the figures at least every A2CM_PROGRESS_SECONDS; --no-progress is silent."""

from __future__ import annotations

import io
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from tqdm import tqdm

from a2cm_phys.config import load_scenario
from a2cm_phys.training.episode_stats import EpisodeStats
from a2cm_phys.training.opponents import Pairing
from a2cm_phys.training.progress import (
    BAR_FORMAT,
    Figures,
    ProgressBar,
    first_line_room,
    fit,
    number,
    status_lines,
)

ROOT = Path(__file__).resolve().parents[1]


def test_numbers_are_short_and_readable() -> None:
    assert number(-2939.3) == "-2939"
    assert number(4.2) == "4.20"
    assert number(0.14) == "0.140"
    assert number(-4.53e7) == "-4.53e7"
    assert number(-9.996e5) == "-1.00e6"
    assert number(0.0) == "0"
    assert number(math.nan) == "–"
    assert all(len(number(x)) <= 7 for x in (-1.5e8, -123456.0, 99.999, 1e-5, -3e7 - 4000))


def test_fit_takes_whole_parts_and_hands_on_the_rest() -> None:
    assert fit(["ab", "cde", "f"], 7) == ("ab  cde", ["f"])
    assert fit(["ab", "cde", "f"], 6) == ("ab", ["cde", "f"])
    assert fit(["abcdefgh"], 4) == ("", ["abcdefgh"])
    assert fit(["a", "b"], 80) == ("a  b", [])


def _figures(**over: object) -> Figures:
    values = {
        "episodes": 12_345_678,
        "steps": 123.456,
        "collisions": 0.0123,
        "ret": -1.85e6 - 123456.0,
        "collision_part": -1.85e6,
        "evader_ret": 123456.0,
        "opponent": "past_evader",
        "descent": 987.6,
        "evader_descent": 3.21,
        "speed": 12345.6,
    }
    return Figures(**{**values, **over})


@pytest.mark.parametrize("total", [100, 5_000, 200_000, 20_000_000])
@pytest.mark.parametrize(
    "figures",
    [_figures(), _figures(collision_part=None, evader_ret=None, opponent=None, descent=None)],
    ids=["self-play, collisions", "plain"],
)
def test_every_line_fits_80_columns_and_no_figure_is_cut(total: int, figures: Figures) -> None:
    room = first_line_room(total, 80)
    lines = status_lines(figures, ["1:02:03 left", "0.22 upd/s"], 80, room)
    first = tqdm.format_meter(
        total - 1, total, 3723.0, ncols=80, prefix=lines[0], bar_format=BAR_FORMAT
    )
    assert len(first) <= 80 and first.endswith(lines[0])  # the bar shrank, not the text
    assert all(len(line) <= 80 for line in lines)
    assert "|" in first and re.search(r"█|▏|▎|▍|▌|▋|▊|▉", first)
    assert all(len(line) <= 80 for line in lines[1:])
    shown = "  ".join(lines)
    for part in [*figures.main(), *figures.detail(), "1:02:03 left"]:
        assert part in shown, part  # each figure whole, on one line
    if total <= 200_000:  # what a user watches, on the bar's own line
        assert lines[0] == "ep 12,345,678  steps 123  coll/ep 0.012  ret -1.97e6"


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def _run(scenario: str, **over: object) -> SimpleNamespace:
    """Enough of a run's state for its progress."""
    stats = EpisodeStats()
    stats.episodes = 1234
    stats.recent.extend([(5, -1.5e8 - 5000.0, 1, math.nan), (4, -4000.0, 0, math.nan)])
    run = SimpleNamespace(
        scenario=load_scenario(scenario),
        cfg=SimpleNamespace(updates=10_000),
        update=0,
        stats=stats,
        evader=None,
        pool=None,
        pairing=Pairing("latest"),
        descent=None,
        finished=False,
        session_speed=lambda now: 3456.0,
        evader_descends=lambda: False,
    )
    run.__dict__.update(over)
    return run


def test_the_bar_rendered_on_a_terminal_fits_and_shows_the_figures() -> None:
    out = _Tty()
    run = _run("grid_collision")
    with ProgressBar(run, file=out) as bar:
        for _ in range(3):
            run.update += 1
            bar.tick()
    screen = [s for s in re.split(r"\r|\n|\x1b\[A", out.getvalue()) if s.strip()]
    assert screen and all(len(s) <= 80 for s in screen)
    last_bar = [s for s in screen if "3/10000" in s][-1]
    assert last_bar.endswith("ep 1,234  steps 4.50  coll/ep 0.500  ret -7.50e7")
    status = [s for s in screen if "left" in s][-1]
    assert "3,456 steps/s" in status and "ret = time -4500 + coll -7.50e7" in status


def test_without_a_terminal_the_lines_carry_the_figures(monkeypatch) -> None:
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "0.001")
    out = io.StringIO()
    run = _run("grid_collision")
    with ProgressBar(run, file=out) as bar:
        for _ in range(3):
            time.sleep(0.01)
            run.update += 1
            bar.tick()
    lines = out.getvalue().splitlines()
    assert lines[0] == "train: started (10,000 updates)"
    assert len(lines) == 5  # a line every tick (0.001 s apart), then where it stopped
    for n, line in enumerate(lines[1:4], 1):
        assert re.match(rf"train: {n}/10,000 updates \(0%\), .+ updates/s, .+ elapsed", line)
    assert lines[-1].startswith("train: 3/10,000")  # not "done": the session stopped early
    assert lines[-1].endswith(
        "episodes 1,234, mean steps 4.50 (last 100), collisions/episode 0.500,"
        " return -7.50e7 (time -4500, collisions -7.50e7), 3,456 steps/s"
    )
    assert not ProgressBar(None, file=out).__enter__().plain  # no run: nothing


def _train(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    # 150 updates take ~1.5 s here and 0.2 s on a fast machine: lines every 0.05 s keep
    # several periodic lines on both (the grace is the interval, so the start line too)
    env = {**os.environ, "A2CM_PROGRESS_SECONDS": "0.05", "PYTHONPATH": str(ROOT)}
    env.pop("A2CM_PROGRESS", None)
    cmd = [sys.executable, "-m", "a2cm_phys.train", "--scenario", "grid_collision"]
    cmd += ["--num-envs", "4", "--updates", "150", "--no-record", "--logdir", str(tmp_path)]
    return subprocess.run(
        [*cmd, *extra], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300
    )


def test_train_without_a_terminal_prints_progress_lines(tmp_path: Path) -> None:
    proc = _train(tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("train: ")]
    assert lines[0] == "train: started (150 updates)", proc.stderr
    periodic = [line for line in lines[1:-1] if re.match(r"train: \d+/150 updates", line)]
    assert periodic, proc.stderr  # at least one line between the start and the end
    figures = (
        r"episodes [\d,]+, mean steps [\d.]+ \(last 100\), collisions/episode [\d.]+,"
        r" return -[\d.e]+ \(time -[\d.e]+, collisions -?[\d.e]+\), [\d,]+ steps/s"
    )
    for line in periodic:  # the time left, except on a line written after the last update
        assert re.fullmatch(
            rf"train: \d+/150 updates \(\d+%\), [\d.,]+ updates/s, .+ elapsed(, ~.+ left)?,"
            rf" {figures}",
            line,
        ), line
    assert any(" left, " in line for line in periodic), proc.stderr
    assert re.fullmatch(rf"train: done, 150/150 updates \(100%\), .+, {figures}", lines[-1])
    assert "train:" not in proc.stdout  # progress on stderr only


def test_no_progress_silences_the_lines(tmp_path: Path) -> None:
    proc = _train(tmp_path, "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "train: " not in proc.stderr and "updates/s" not in proc.stderr
