"""``evaluate --pursuers onnx:DIR`` and ``pretrained:NAME`` (issue 34): an exported team
plays through the torch-free runtime, in its own scenario unless ``--scenario`` names one,
and bad names are one line."""

from __future__ import annotations

import json

import pytest

from a2cm_phys.commands.evaluate import main


def test_a_pretrained_team_plays_its_own_scenario_near_the_optimum(capsys) -> None:
    argv = ["--pursuers", "pretrained:grid_collision", "--greedy", "--episodes", "400"]
    assert main([*argv, "--json", "--no-progress", "--reference", "none"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["scenario"] == "grid_collision"
    steps = report["capture_steps"]["mean"]["value"]
    # the exact optimum is 2.939; 400 greedy episodes of an optimal team sit within ±0.15
    assert 2.75 < steps < 3.15
    assert report["collisions_per_episode"]["value"] == 0


@pytest.mark.parametrize(
    ("spec", "words"),
    [("pretrained:nope", "available: grid_collision"), ("onnx:/no/such/dir", "not a folder")],
)
def test_a_bad_exported_team_is_one_line(spec: str, words: str, capsys) -> None:
    assert main(["--pursuers", spec, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1
