"""Training runs in the robots' arenas (issue 46) are deterministic and resume: on the grid
with obstacles an interrupted run resumes bit for bit; in physics (differential drive,
obstacles, range sensors with occlusion) the same seed trains the same weights, with one
process or two, and a run interrupted mid-rollout resumes the same way every time (a
physics resume restarts the games, as every physics resume does)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from a2cm_phys.commands.train import EXIT_INTERRUPTED, main
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.training import checkpoint

COMMON = ("--num-envs", "4", "--batch-size", "32", "--seed", "3", "--no-progress")
RAYS = ("--set", "sensing.radius=2.0", "--set", "sensing.rays=4", "--set", "sensing.occlusion=true")


def weights(run: Path) -> dict[str, torch.Tensor]:
    """The pursuers' learned weights of a run's checkpoint."""
    return checkpoint.load(run)["learner"]["model"]


def assert_same_weights(a: Path, b: Path) -> None:
    wa, wb = weights(a), weights(b)
    assert wa.keys() == wb.keys()
    for key, value in wa.items():
        assert torch.equal(value, wb[key]), key


def interrupted(run: list[str], where: Path, monkeypatch: pytest.MonkeyPatch, at: int) -> None:
    """Train ``run`` into ``where``, interrupted at the ``at``-th env step, then resumed."""
    step, calls = VectorEnv.step, []

    def interrupting(self: VectorEnv, *args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == at:
            raise KeyboardInterrupt
        return step(self, *args, **kwargs)

    monkeypatch.setattr(VectorEnv, "step", interrupting)
    assert main([*run, "--run-dir", str(where)]) == EXIT_INTERRUPTED
    monkeypatch.setattr(VectorEnv, "step", step)
    assert main(["--resume", str(where), "--no-progress"]) == 0


def test_a_grid_run_with_obstacles_resumes_bit_for_bit(tmp_path, monkeypatch) -> None:
    run = ["--scenario", "grid_obstacles", *COMMON, "--updates", "12"]
    assert main([*run, "--run-dir", str(tmp_path / "full")]) == 0
    interrupted(run, tmp_path / "part", monkeypatch, at=8 * 6 + 3)  # inside update 7
    assert_same_weights(tmp_path / "full", tmp_path / "part")
    full, part = checkpoint.load(tmp_path / "full"), checkpoint.load(tmp_path / "part")
    assert full["rng"] == part["rng"] and full["update"] == part["update"] == 12


@pytest.mark.parametrize("sets", [(), RAYS], ids=["plain", "rays"])
def test_a_robot_run_is_deterministic_and_resumes_alike(tmp_path, monkeypatch, sets) -> None:
    run = ["--scenario", "phys_diff_obstacles", *COMMON, "--updates", "6", *sets]
    assert main([*run, "--run-dir", str(tmp_path / "a")]) == 0
    assert main([*run, "--run-dir", str(tmp_path / "b")]) == 0
    assert_same_weights(tmp_path / "a", tmp_path / "b")
    if not sets:  # the headings and the obstacles' contacts cross the process boundary
        assert main([*run, "--workers", "2", "--run-dir", str(tmp_path / "w")]) == 0
        assert_same_weights(tmp_path / "a", tmp_path / "w")
    for name in ("r1", "r2"):
        interrupted(run, tmp_path / name, monkeypatch, at=8 * 3 + 5)  # inside update 4
        assert checkpoint.load(tmp_path / name)["update"] == 6
    assert_same_weights(tmp_path / "r1", tmp_path / "r2")
