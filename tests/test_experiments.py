"""The reproduction report end to end on tiny budgets, its options, and its statistics."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as st

from a2cm_phys.analysis.stats import (
    iqm,
    iqm_interval,
    mean_interval,
    probability_of_improvement,
    ratio_interval,
    verdict_bound,
    verdict_test,
    welch_p,
)
from a2cm_phys.commands import experiments
from a2cm_phys.study.report import build
from a2cm_phys.study.report.claim import Claim, claims_table

TINY = [
    "--seeds", "0", "--modes", "grid", "--updates", "3", "--cont-updates", "3",
    "--selfplay-updates", "3", "--eval-episodes", "4", "--crossplay-episodes", "2",
    "--exploit-max-steps", "5", "--cont-set", "max_steps=40", "--sequential",
    "--estimate-updates", "2",
]  # fmt: skip


@pytest.fixture(autouse=True)
def quick_game_value(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The game's value takes minutes and 3.5 GiB even at a short horizon (the solver is
    tested in tests/test_nash.py): the report gets a stand-in, and its calls are kept."""
    calls: list[int] = []

    def bracket(scenario: str, horizon: int | None, cache: Path) -> dict:
        calls.append(horizon)
        return {"lower": 3.875, "upper": 4.125, "horizon": horizon}

    monkeypatch.setattr(build, "game_value_bracket", bracket)
    return calls


def test_report_end_to_end_on_tiny_budgets(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    quick_game_value: list[int],
) -> None:
    out, logdir = tmp_path / "docs", tmp_path / "runs"
    argv = [*TINY, "--logdir", str(logdir), "--out", str(out)]
    assert experiments.main([*argv, "--dry-run"]) == 0
    dry = capsys.readouterr().out
    assert "22 runs" in dry and "paper/grid_collision-a2cm-paper-s0: new" in dry
    assert "descent/grid_vs-a2cm-descent-s0: new" in dry
    assert re.search(r"continuous: 6 runs \(6 new.*wall", dry) and "estimated total" in dry
    assert not (out / "RESULTS.md").exists()

    assert experiments.main(argv) == 0
    text = (out / "RESULTS.md").read_text()
    claims = text[text.index("## Claims") : text.index("## The paper's experiments")]
    for claim in (
        "A2CM completes more episodes than A2C",
        "A2CM settles near 6 steps",
        "A2CM is better than A2C with collisions",
        "A2CM trains in about the time A2C does",
        "captures within 3.1 greedy steps",
        "Our defaults learn faster",
        "Continuous A2CM within 5% of pursuit",
        "at least 20% faster than pursuit",
        "less exploitable than the oracle",
        "self-play evader outlasts the random and fleeing evaders",
    ):
        assert claim in claims, claim
    # one seed a side: every verdict is inconclusive and says why
    assert re.search(r"\*\*inconclusive\*\* \(n = 1\) \| Welch t", claims)
    assert not re.search(r"\*\*(holds|does not hold)\*\* \(n = 1", claims)
    assert "truncated to 5 steps" in claims  # --exploit-max-steps is said
    assert "[s0](../runs/paper/grid-a2cm-paper-s0)" in text  # rows link their runs
    assert "2.939 (optimum)" in text and "82,119" in text
    assert "Cross-play" in text and "evader: flee" in text
    # exact bounds from the minimax solver, truncated at the same 5 steps: [3, 5]
    assert "minimax capture time lies in [3, 5]" in text
    assert "| minimax | " in text  # the minimax team is a row of the cross-play table
    assert "game's value lies in [3.875, 4.125] (horizon 5" in text and quick_game_value == [5]
    # the later issues' targets: export parity measured on the runs, the rest from records
    assert re.search(r"Actors exported to ONNX act as the trained ones.*\*\*holds\*\*", claims)
    assert "Recurrent (gru) actors capture in at most 0.85×" in claims  # benchmarks/results
    assert "## Later work" in text
    assert "a2cm_phys 0." in text and "Total wall time" in text
    assert "Every planned run finished." in text
    for name in re.findall(r"!\[[^]]*\]\((figures/[^)]+)\)", text):
        assert (out / name).stat().st_size > 10_000, name
    assert (out / "figures" / "paper_grid_lengths.png").exists()
    data = json.loads((out / "results.json").read_text())
    assert len(data["runs"]) == 22 and data["claims"]
    assert (logdir / "paper" / "grid-a2c-paper-s0" / "report_eval.json").exists()

    # again: every run is skipped, every measurement comes from the caches; a run named
    # the old way (before the preset was part of the name) is found by its configuration
    (logdir / "paper" / "grid-a2cm-paper-s0").rename(logdir / "paper" / "grid-a2cm-s0")
    capsys.readouterr()
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "1e-6")  # no grace: every step reports
    assert experiments.main(argv) == 0
    err = capsys.readouterr().err
    assert "paper/grid-a2cm-s0: skipped" in err and ": ran\n" not in err
    assert "runs: started (22 runs)" in err and "runs: done, 22/22 runs" in err  # progress
    assert not (logdir / "paper" / "grid-a2cm-paper-s0").exists()
    assert "[s0](../runs/paper/grid-a2cm-s0)" in (out / "RESULTS.md").read_text()

    # the runs as the repository keeps them (docs/runs, .gitignore): no log, no checkpoint,
    # the actors the cross-play plays; the same report, cross-play, figures and all
    text = (out / "RESULTS.md").read_text()
    actors = sorted(p.relative_to(logdir).as_posix() for p in logdir.rglob("report_actors.pt"))
    assert actors == [
        *(f"descent/grid_vs-{a}-descent-s0/report_actors.pt" for a in ("a2c", "a2cm")),
        "ours/grid-a2cm-s0/report_actors.pt",
        *(f"selfplay/grid_vs-{a}-s0/report_actors.pt" for a in ("a2c", "a2cm")),
    ]
    for f in [*logdir.rglob("episodes*.mcap"), *logdir.rglob("checkpoint*.pt")]:
        f.unlink()
    crossplay = json.loads((out / "results.json").read_text())["crossplay"]
    figures = {f: f.stat().st_mtime_ns for f in (out / "figures").glob("*.png")}
    assert experiments.main([*argv, "--report-only"]) == 0
    again = (out / "RESULTS.md").read_text()
    before, after = (r.split("## Claims")[1].split("Total wall time")[0] for r in (text, again))
    assert after == before
    assert all(f.stat().st_mtime_ns > t for f, t in figures.items())  # drawn again
    assert json.loads((out / "results.json").read_text())["crossplay"] == crossplay
    assert "could not be measured" not in again

    # --quote-in rewrites another document's quotes of the headline figures
    readme = tmp_path / "README.md"
    readme.write_text("Greedy: <!-- results: main-job -->old<!-- /results -->.\n")
    assert experiments.main([*argv, "--report-only", "--quote-in", str(readme)]) == 0
    assert f"quotes rewritten: {readme}" in capsys.readouterr().out
    assert "old" not in readme.read_text() and "steps (1 seed)" in readme.read_text()

    # a run that is missing is listed, not fatal
    (logdir / "ours" / "grid-a2c-s0" / "summary.json").unlink()
    assert experiments.main([*argv, "--groups", "ours", "--report-only"]) == 0
    text = (out / "RESULTS.md").read_text()
    assert "Cells that could not be run" in text  # (its checkpoint went above: not run)
    assert "`ours/grid-a2c-s0`: not run" in text


def test_an_interrupted_session_still_counts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C while training: exit 130, and the session's time is in the log folder's
    record, so that the report's total over sessions (which may be many) adds up."""

    def interrupted(*args: object) -> bool:
        raise KeyboardInterrupt

    monkeypatch.setattr(experiments, "_train", interrupted)
    logdir = tmp_path / "runs"
    argv = [*TINY, "--groups", "ours", "--logdir", str(logdir), "--out", str(tmp_path / "d")]
    assert experiments.main(argv) == 130
    assert "interrupted: finished runs are kept" in capsys.readouterr().err
    sessions = json.loads((logdir / "report_sessions.json").read_text())
    assert len(sessions) == 1 and sessions[0]["elapsed_s"] > 0
    assert "--groups ours" in sessions[0]["command"]
    assert not (tmp_path / "d" / "RESULTS.md").exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--groups", "paper,water"], ["--groups", "water", "selfplay"]),
        (["--groups", "paper,paper"], ["--groups", "twice"]),
        (["--seeds", "0-x"], ["--seeds"]),
        (["--seeds", "1,1"], ["--seeds", "twice"]),
        (["--modes", "water"], ["--modes"]),
        (["--set", "size=3"], ["--set", "train.KEY"]),
        (["--cont-set", "train.nope=1", "--dry-run"], ["nope"]),
        (
            ["--cont-set", "max_steps=40", "train.lr=0.1"],
            ["--cont-set max_steps=40 --cont-set train.lr=0.1"],
        ),
        (["--set", "train.lr=0.1", "train.gamma=0.9"], ["--set train.lr=0.1 --set train.gamma"]),
        (["--exploit-max-steps", "0"], ["--exploit-max-steps"]),
    ],
)
def test_bad_options_are_one_line_errors(
    argv: list[str], words: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [*argv, "--logdir", str(tmp_path / "r"), "--out", str(tmp_path / "d")]
    assert experiments.main([*argv, "--estimate-updates", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and err.count("\n") == 1 and "Traceback" not in err
    for word in words:
        assert word in err


def test_session_totals_count_overlapping_sessions_once() -> None:
    from a2cm_phys.study.report.build import session_totals

    sessions = [
        {"command": "x --sequential", "elapsed_s": 50.0},  # an old record: no start time
        {"command": "x", "elapsed_s": 100.0, "started": 1000.0, "training": "sequential"},
        {"command": "x", "elapsed_s": 100.0, "started": 1050.0, "training": "sequential"},
        {"command": "x", "elapsed_s": 10.0, "started": 2000.0, "training": "on Ray"},
        {"command": "x --report-only", "elapsed_s": 5.0, "started": 3000.0, "training": "r"},
    ]
    totals = session_totals(sessions)
    assert totals["total_wall"] == 265.0
    assert totals["clock_wall"] == 50.0 + 150.0 + 10.0 + 5.0  # 1000–1150 counted once
    assert totals["sessions"] == 5
    assert totals["parallel"] == "sequential, on Ray"  # report-only sessions train nothing
    newer = {"command": "x", "elapsed_s": 1.0, "started": 4000.0, "training": "on Ray, 2 at a time"}
    # an older record's bare "on Ray" is not named beside the newer, fuller one
    assert session_totals([*sessions, newer])["parallel"] == "sequential, on Ray, 2 at a time"


# --------------------------------------------------------------------------- statistics


def test_mean_interval_is_students_t() -> None:
    m, lo, hi = mean_interval([1.0, 2.0, 3.0])
    half = st.t.ppf(0.975, 2) * 1.0 / np.sqrt(3)  # sd = 1
    assert m == 2.0 and lo == pytest.approx(2 - half) and hi == pytest.approx(2 + half)
    assert np.isnan(mean_interval([4.0])[1]) and mean_interval([4.0])[0] == 4.0
    assert np.isnan(mean_interval([])[0])


def test_mean_interval_floor_clips_only_the_lower_bound() -> None:
    values = [0.0, 0.0, 0.0, 0.0, 0.5]  # collisions per episode: t reaches below 0
    m, lo, hi = mean_interval(values)
    assert lo < 0.0
    assert mean_interval(values, floor=0.0) == (m, 0.0, hi)
    assert mean_interval([2.0, 3.0, 4.0], floor=0.0) == mean_interval([2.0, 3.0, 4.0])
    rates = [1.0, 1.0, 1.0, 1.0, 0.5]
    assert mean_interval(rates)[2] > 1.0 and mean_interval(rates, ceiling=1.0)[2] == 1.0


def test_a_claim_names_its_samples_and_one_sample_decides_nothing() -> None:
    def claim(verdict: str, sizes: tuple[int, ...]) -> Claim:
        return Claim("paper", "c", "s", "m", "i", verdict, "t", "", sizes)

    assert claim("holds", (5, 5)).verdict == "holds"
    assert claim("holds", (5, 5)).evidence == "n = 5 vs 5"
    assert claim("does not hold", (1, 1)).verdict == "inconclusive"
    assert claim("does not hold", (1, 1)).evidence == "n = 1"
    assert claim("holds", (3, 1)).verdict == "inconclusive"
    assert claim("holds", (3, 1)).evidence == "n = 3 vs 1"
    assert claim("holds", (4,)).evidence == "n = 4" and claim("holds", ()).evidence == ""
    row = claims_table([claim("does not hold", (1, 1))])[-1]
    assert "**inconclusive** (n = 1) |" in row


def test_welch_p_one_sided_and_degenerate_cases() -> None:
    a, b = [5.0, 6.0, 7.0], [1.0, 2.0, 3.0]
    # t = 4 / sqrt(2/3) with Welch df 4: a hand-checkable p
    assert welch_p(a, b) == pytest.approx(st.t.sf(4 / np.sqrt(2 / 3), 4))
    assert welch_p(a, b, "less") == pytest.approx(1 - welch_p(a, b))
    assert np.isnan(welch_p([1.0], b))  # one seed: no test
    assert np.isnan(welch_p([853.0], [695.0]))  # one against one, however far apart
    assert welch_p([2.0, 2.0], [1.0, 1.0]) == 0.0  # no variance, different: certain
    assert np.isnan(welch_p([1.0, 1.0], [1.0, 1.0]))


def test_ratio_interval() -> None:
    value, lo, hi = ratio_interval([2.0, 2.2, 1.8], [1.0, 1.0, 1.0])
    assert value == pytest.approx(2.0) and 1.8 <= lo < 2.0 < hi <= 2.2
    assert ratio_interval([3.0, 3.0], [1.5, 1.5]) == (2.0, 2.0, 2.0)
    assert np.isnan(ratio_interval([1.0], [2.0])[1])


def test_iqm_and_stratified_interval() -> None:
    assert iqm([1, 2, 3, 4, 100, 5, 6, 7]) == pytest.approx(4.5)  # middle 4 of 8
    value, lo, hi = iqm_interval([[1.0, 1.0], [3.0, 3.0]])
    assert value == 2.0 and lo == hi == 2.0  # no spread within strata: no spread at all
    value, lo, hi = iqm_interval([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    assert value == 3.5 and lo < 3.5 < hi


def test_probability_of_improvement() -> None:
    # task 1: X always above Y (1); task 2: a tie (1/2); the mean over tasks: 3/4
    assert probability_of_improvement([[3, 4], [1]], [[1, 2], [1]]) == (0.75, 0.75, 0.75)
    value, lo, hi = probability_of_improvement([[1.0, 3.0]], [[2.0, 2.0]])
    assert value == 0.5 and lo == 0.0 and hi == 1.0


def test_verdicts() -> None:
    assert verdict_bound((3.0, 2.9, 3.05), at_most=3.1) == "holds"
    assert verdict_bound((3.3, 3.2, 3.4), at_most=3.1) == "does not hold"
    assert verdict_bound((3.1, 3.0, 3.2), at_most=3.1) == "inconclusive"
    assert verdict_bound((6.0, 5.5, 6.5), at_least=5, at_most=7) == "holds"
    assert verdict_bound((3.0, 2.9, 3.1), at_least=5, at_most=7) == "does not hold"
    assert verdict_bound((3.0, np.nan, np.nan), at_most=7) == "inconclusive"
    assert verdict_test(0.01, 0.99) == "holds"
    assert verdict_test(0.99, 0.01) == "does not hold"
    assert verdict_test(0.2, 0.8) == "inconclusive"
    assert verdict_test(np.nan, np.nan) == "inconclusive"


def test_cross_play_cache_tells_a_retrained_run_from_the_old_one(tmp_path: Path) -> None:
    import os

    from a2cm_phys.study.report.measure import ACTORS_FILE, _stamped, played_actors
    from a2cm_phys.training import checkpoint

    run = tmp_path / "grid_vs-a2cm-s0"
    run.mkdir()
    state = {
        "scenario": {},
        "train": {},
        "update": 7,
        "learner": {"model": {}},
        "rng": {},
        "stats": {"episodes": 3},
        "wall_time": 1.0,
        "descent": {"values": [1.0] * 999},
    }
    checkpoint.save(run / "checkpoint.pt", state)  # fmt: skip
    played = played_actors(run)
    assert played == str(run / ACTORS_FILE)
    kept = checkpoint.load(played)
    assert kept["descent"] is None and kept["update"] == 7  # training's tables left out
    before = _stamped((played, "random"))
    assert before[1] == "random"  # named policies are their own identity
    os.utime(run / "checkpoint.pt", ns=(1, 1))  # a copy of the run (a clone): the same
    assert _stamped((played_actors(run), "random")) == before
    (run / "checkpoint.pt").unlink()  # as the repository keeps it: the actors alone
    assert _stamped((played_actors(run), "random")) == before
    checkpoint.save(run / "checkpoint.pt", {**state, "update": 8})  # trained again
    assert _stamped((played_actors(run), "random"))[0] != before[0]
    assert checkpoint.load(run / ACTORS_FILE)["update"] == 8
