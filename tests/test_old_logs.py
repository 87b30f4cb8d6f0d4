"""Runs written before the log's invariant was enforced (``tests/data/pre_issue29``: a grid
and a physics run, each resumed once, by the code of commit 61cf8cf) still read, verify and
resume: their parts are named ``episodes-from-UUUUUU.mcap`` and their checkpoints carry no
checksum."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from faults import invariant_problems

from a2cm_phys.commands.replay import main as replay_main
from a2cm_phys.commands.train import main as train_main
from a2cm_phys.record import read_run
from a2cm_phys.training import checkpoint

OLD = Path(__file__).parent / "data" / "pre_issue29"


@pytest.mark.parametrize("name", ["grid", "phys"])
def test_an_old_run_verifies_and_holds_the_invariant(name, capsys):
    assert replay_main([str(OLD / name), "--verify"]) == 0
    out = capsys.readouterr().out
    assert "all match" in out and "none lost: holds" in out
    assert invariant_problems(OLD / name, finished=True) == []


@pytest.mark.parametrize("name", ["grid", "phys"])
def test_an_old_run_resumes_into_a_numbered_part(tmp_path, name):
    run_dir = tmp_path / name
    shutil.copytree(OLD / name, run_dir)
    updates = checkpoint.load(run_dir)["update"]
    assert train_main(["--resume", str(run_dir), "--updates", str(updates + 5),
                       "--no-progress"]) == 0  # fmt: skip
    parts = [p.name for p in read_run(run_dir).parts]
    assert parts[-1] == f"episodes-002-from-{updates:06d}.mcap"
    assert parts[:2] == ["episodes.mcap", parts[1]] and parts[1].startswith("episodes-from-")
    assert invariant_problems(run_dir, finished=True) == []
    assert replay_main([str(run_dir), "--verify"]) == 0
