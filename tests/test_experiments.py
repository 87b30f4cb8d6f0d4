"""The experiments report runs end to end on a tiny configuration."""

from __future__ import annotations

import json

from a2cm_phys import experiments


def test_report_end_to_end_on_a_tiny_configuration(tmp_path):
    out = tmp_path / "docs"
    argv = [
        "--seeds",
        "0-1",
        "--modes",
        "grid",
        "--updates",
        "4",
        "--num-envs",
        "4",
        "--eval-episodes",
        "20",
        "--sequential",
        "--sweep-dir",
        str(tmp_path / "runs"),
        "--out",
        str(out),
    ]
    assert experiments.main(argv) == 0
    text = (out / "RESULTS.md").read_text()
    for exp, (name, _) in experiments.EXPERIMENTS.items():
        assert f"| {exp}: {name} | A2C |" in text and f"| {exp}: {name} | A2CM |" in text
    assert "2.939" in text  # the oracle's optimum beside the learned policies
    assert "82,119" in text  # the paper's figure beside ours
    assert "Where we agree with the paper" in text
    assert (out / "figures" / "grid_overview.png").stat().st_size > 10_000
    runs = json.loads((out / "results.json").read_text())["runs"]
    assert len(runs) == 12 and {r["algo"] for r in runs} == {"a2c", "a2cm"}
    # a second invocation reuses the finished runs
    assert experiments.main(argv) == 0


def test_bad_options_exit_2(capsys):
    assert experiments.main(["--modes", "water"]) == 2
    assert "--modes" in capsys.readouterr().err
    assert experiments.main(["--set", "size=3"]) == 2
