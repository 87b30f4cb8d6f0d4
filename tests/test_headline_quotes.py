"""The README's and BENCHMARKS.md's headline figures are the report's: each quote equals
what ``docs/results.json`` gives, and rewriting the quotes mends a drifted one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from a2cm_phys.commands import experiments
from a2cm_phys.config import ConfigError
from a2cm_phys.study.report.headline import (
    PENDING,
    QUOTE,
    ROWS,
    fill_quotes,
    headline_figures,
    quote_in,
)

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = ("README.md", "BENCHMARKS.md")
REQUIRED = ("main-job", "continuous-phys_cont", "descent-worst", "selfplay-worst", "game-value")
"""The figures the README must quote (the issue's headline figures), in its table."""


def committed_results() -> dict:
    return json.loads((ROOT / "docs" / "results.json").read_text())


@pytest.mark.parametrize("name", DOCUMENTS)
def test_every_quote_is_the_reports(name: str) -> None:
    text = (ROOT / name).read_text()
    quotes = QUOTE.findall(text)
    assert quotes, f"{name} quotes no figure of the report"
    filled = fill_quotes(text, committed_results(), "docs/RESULTS.md")
    for (key, said), (_, truth) in zip(quotes, QUOTE.findall(filled), strict=True):
        assert said == truth, f"{name}: the quote of '{key}' drifted from docs/results.json"


@pytest.mark.parametrize("name", DOCUMENTS)
def test_the_headline_table_is_quoted_whole(name: str) -> None:
    keys = [key for key, _ in QUOTE.findall((ROOT / name).read_text())]
    assert "headline" in keys
    for key in REQUIRED:
        assert key in ROWS


def small_results() -> dict:
    def run(group: str, scenario: str, seed: int, steps: float) -> dict:
        greedy = {"length": steps, "capture_steps": steps, "collisions": 0.0}
        return {"group": group, "scenario": scenario, "algo": "a2cm", "seed": seed,
                "greedy": greedy}  # fmt: skip

    return {
        "meta": {"runs": 4, "date": "2026-12-03"},
        "runs": [
            run("ours", "grid_collision", 0, 2.95),
            run("ours", "grid_collision", 1, 2.93),
            run("ours", "grid_collision", 2, 3.20),
            run("continuous", "phys_cont", 0, 18.0),
        ],
        "references": {"grid_collision": {"length": 2.9393}},
        "pursuit": {"phys_cont": {"length": 17.5}},
        "exploit": {"descent/a2cm": [{"exploit_worst_case": 7.0}, {"exploit_worst_case": 6.0}]},
        "game_value": {"lower": 4.5641, "upper": 4.5812, "horizon": 200},
    }


def test_figures_read_from_results() -> None:
    figures = headline_figures(small_results())
    assert figures["main-job"].startswith("2.950 steps (median of 3 seeds; worst 3.200)")
    assert figures["optimum"] == "2.939 steps"
    assert figures["continuous-phys_cont"].startswith("1.029× `pursuit` (18.00 against 17.50")
    assert "1 seed" in figures["continuous-phys_cont"]
    worst = "A2CM 6.50, 6.00–7.00 steps (median of 2 seeds, range over seeds)"
    assert figures["descent-worst"] == worst
    assert figures["game-value"] == "[4.564, 4.581] steps (horizon 200)"
    # a group the report lacks says so, rather than quoting an old figure
    assert figures["selfplay-worst"] == PENDING
    assert figures["continuous-phys_cont_flee"] == PENDING


def test_a_drifted_quote_is_rewritten(tmp_path: Path) -> None:
    results = tmp_path / "docs" / "results.json"
    results.parent.mkdir()
    results.write_text(json.dumps(small_results()))
    doc = tmp_path / "README.md"
    stale = "Greedy: <!-- results: main-job -->2.949 steps<!-- /results -->, done.\n"
    doc.write_text(stale + "<!-- results: headline --><!-- /results -->\n")
    assert quote_in([doc], results) == [doc]
    text = doc.read_text()
    assert "2.949" not in text and "Greedy: <!-- results: main-job -->2.950 steps" in text
    assert "](docs/RESULTS.md#descent)" in text  # links relative to the document
    assert quote_in([doc], results) == []  # nothing left to change: not written again
    doc.write_text("<!-- results: main-jobs -->2.9<!-- /results -->")
    with pytest.raises(ConfigError, match=r"README\.md: no headline figure 'main-jobs'"):
        quote_in([doc], results)


def test_quote_in_names_a_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    missing = tmp_path / "NOPE.md"
    argv = ["--report-only", "--logdir", str(tmp_path / "r"), "--out", str(tmp_path / "d")]
    assert experiments.main([*argv, "--quote-in", str(missing)]) == 2
    assert f"--quote-in: no file {missing}" in capsys.readouterr().err
    assert not (tmp_path / "d" / "RESULTS.md").exists()
