"""``evaluate`` talks (issue 31): the episodes played are counted on stderr without a
terminal (a plain evaluation, a played reference, a cross-play), the gap to the reference
is a difference in steps and per cent (never a ratio of two negative returns), and
``--set KEY=VALUE`` leaves the run directory after it alone."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from a2cm_phys.commands.evaluate import format_cross_play, format_report, main
from a2cm_phys.config import load_scenario, load_train, resolve_train
from a2cm_phys.training.trainer import Trainer


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A three-update run on ``grid`` (a checkpoint to evaluate)."""
    path = tmp_path_factory.mktemp("run") / "run"
    grid = load_scenario("grid")
    cfg = resolve_train(grid, load_train({"num_envs": 4, "updates": 3}))
    assert Trainer(grid, cfg, path, record=False).run() == "done"
    return path


@pytest.fixture
def lines_often(monkeypatch: pytest.MonkeyPatch) -> None:
    """Plain progress lines every few milliseconds, progress not silenced."""
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "0.002")
    monkeypatch.delenv("A2CM_PROGRESS", raising=False)


def _progress(err: str, desc: str, total: int) -> list[str]:
    """The progress lines of ``desc`` in ``err``, checked: a start, at least one line
    while it plays (count, rate, elapsed), and an end at 100%."""
    lines = [line for line in err.splitlines() if line.startswith(f"{desc}: ")]
    assert lines[0] == f"{desc}: started ({total:,} ep)", lines
    assert lines[-1].startswith(f"{desc}: done, {total:,}/{total:,} ep (100%), ")
    during = re.compile(rf"{re.escape(desc)}: [\d,]+/{total:,} ep \(\d+%\), [\d.,]+ ep/s, ")
    assert any(during.match(line) for line in lines[1:-1]), lines
    return lines


def test_a_plain_evaluation_counts_its_episodes_without_a_terminal(
    run_dir: Path, lines_often: None, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [str(run_dir), "--scenario", "grid", "--set", "evader=flee", "--episodes", "40"]
    assert main([*argv, "--reference", "none", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["episodes"] == 40  # stdout: the report alone
    lines = _progress(err, "evaluate", 40)
    assert "mean length" in lines[-1]
    assert main([*argv, "--reference", "none", "--json", "--no-progress"]) == 0
    assert capsys.readouterr().err == ""


def test_a_played_reference_counts_its_episodes_too(
    lines_often: None, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--policy", "random", "--scenario", "grid", "--set", "evader=flee"]
    assert main([*argv, "--reference", "pursuit", "--episodes", "30"]) == 0
    out, err = capsys.readouterr()
    _progress(err, "evaluate", 30)
    _progress(err, "reference (pursuit)", 30)
    assert "reference, pursuit (played)" in out


def test_a_cross_play_counts_pairings_times_episodes(
    run_dir: Path, lines_often: None, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--cross-play", "--pursuers", f"{run_dir},random", "--evader", "random,flee"]
    assert main([*argv, "--episodes", "20", "--json"]) == 0
    out, err = capsys.readouterr()
    rows = json.loads(out)
    assert [(r["pursuers"], r["evader"]) for r in rows] == [
        (str(run_dir), "random"),
        (str(run_dir), "flee"),
        ("random", "random"),
        ("random", "flee"),
    ]
    lines = _progress(err, "cross-play", 4 * 20)
    assert lines[-1].endswith("4/4 random vs flee")  # which pairing plays, in its order
    assert any("run vs flee" in line for line in lines)


def _report(steps: float, ret: float, reference: dict) -> dict:
    value = {"value": steps, "lo": steps, "hi": steps}
    return {
        "capture_steps": {"mean": value, "median": value, "p95": value},
        "length": {"mean": value, "median": value, "p95": value},
        "capture_rate": {"value": 1.0, "lo": 1.0, "hi": 1.0},
        "collisions_per_episode": {"value": 0.0, "lo": 0.0, "hi": 0.0},
        "return": {"value": ret, "lo": ret, "hi": ret},
        "episodes": 1000,
        "truncated": 0,
        "reference": reference,
    }


def test_the_gap_to_the_exact_optimum_is_a_difference_in_steps_and_per_cent() -> None:
    exact = {"policy": "optimum (exact oracle)", "exact": True}
    text = format_report(
        _report(2.951, -2.951, {**exact, "capture_steps": 2.939, "return": -2.939}), "t"
    )
    assert "gap to the reference, capture steps: +0.012 steps (+0.4%) against the" in text
    assert "the reference's 2.939" in text
    assert "gap to the reference, return: -0.012 against the reference's -2.939" in text
    assert "×" not in text  # no ratio: -2.951 / -2.939 = 1.004 would read as "more"
    faster = format_report(
        _report(2.9, -2.9, {**exact, "capture_steps": 2.939, "return": -2.939}), "t"
    )
    assert "capture steps: -0.039 steps (-1.3%)" in faster
    assert "return: +0.039 against" in faster


def test_the_gap_to_a_played_reference_with_large_penalties_is_a_difference() -> None:
    ref = _report(4.0, -150_000_004.0, None)
    played = {"policy": "pursuit (played)", "exact": False, **ref}
    text = format_report(_report(3.0, -3.0, played), "t")
    assert "capture steps: -1.000 steps (-25.0%) against the reference's 4.000" in text
    assert "return: +150,000,001.000 against the reference's -150,000,004.000" in text


def test_a_side_with_no_capture_has_no_gap_and_no_nan() -> None:
    exact = {"policy": "optimum (exact oracle)", "exact": True}
    report = _report(math.nan, -1000.0, {**exact, "capture_steps": 2.939, "return": -2.939})
    report["capture_rate"] = {"value": 0.0, "lo": 0.0, "hi": 0.0}
    text = format_report(report, "t")
    assert "capture steps: none (the result has no value" in text
    assert "return: -997.061 against the reference's -2.939" in text
    assert "capture steps mean" in text and "nan" not in text
    row = {"pursuers": "pursuit", "evader": "best-response", **report}
    table = format_cross_play([row])
    assert "none (no capture)" in table and "nan" not in table


def test_set_before_the_run_leaves_the_run_to_the_positional(
    run_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The run after ``--set KEY=VALUE`` is the run (not swallowed): without --scenario
    the error is that --set needs one, naming the run's scenario, and with it the run
    plays against the evader set."""
    assert main(["--set", "evader=flee", str(run_dir), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "give a run directory" not in err
    assert "--set needs --scenario" in err and "--scenario grid --set evader=flee" in err
    tail = ["--episodes", "10", "--reference", "none", "--json", "--no-progress"]
    for argv in (
        ["--set", "evader=flee", str(run_dir), "--scenario", "grid"],
        ["--scenario", "grid", "--set", "evader=flee", str(run_dir)],
        [str(run_dir), "--set", "evader=flee", "--scenario", "grid"],
    ):
        assert main([*argv, *tail]) == 0, argv
        assert json.loads(capsys.readouterr().out)["policy"].endswith("vs flee evader")
