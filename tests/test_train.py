"""The trainer: exact resume, seeding, model shapes, CLI errors, Ctrl-C and NaN handling."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from a2cm_phys.algos import NonFiniteLoss
from a2cm_phys.algos.learner import Learner
from a2cm_phys.commands.replay import main as replay_main
from a2cm_phys.commands.train import EXIT_INTERRUPTED, EXIT_NONFINITE, main
from a2cm_phys.config import load_scenario, load_train, preset, resolve_train, scenario_names
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.record import read_run
from a2cm_phys.record.verify import verify
from a2cm_phys.training import checkpoint
from a2cm_phys.training.trainer import Trainer

TIMING = ("wall_time_s", "steps_per_s", "run_dir", "status", "last_checkpoint_update")
HAS_PHYSICS = importlib.util.find_spec("a2cm_phys.envs.physics") is not None


def _run(tmp_path: Path, *args: str) -> tuple[int, Path]:
    """Run the CLI in ``tmp_path/logs``; return the exit status and the newest run dir."""
    logdir = tmp_path / "logs"
    code = main([*args, "--logdir", str(logdir), "--no-progress"])
    runs = sorted(logdir.iterdir(), key=lambda p: p.stat().st_mtime) if logdir.exists() else []
    return code, runs[-1] if runs else logdir


def _weights(run_dir: Path) -> dict[str, torch.Tensor]:
    return checkpoint.load(run_dir)["learner"]["model"]


def _assert_same_run(a: Path, b: Path) -> None:
    wa, wb = _weights(a), _weights(b)
    assert wa.keys() == wb.keys()
    for key in wa:
        assert torch.equal(wa[key], wb[key]), key
    sa, sb = (json.loads((p / "summary.json").read_text()) for p in (a, b))
    assert {k: v for k, v in sa.items() if k not in TIMING} == {
        k: v for k, v in sb.items() if k not in TIMING
    }
    ca, cb = checkpoint.load(a), checkpoint.load(b)
    assert ca["rng"] == cb["rng"] and ca["env"]["seeds"] == cb["env"]["seeds"]
    for key in ca["env"]["core"] or ():  # grid: cells, t, episode_seed
        np.testing.assert_array_equal(ca["env"]["core"][key], cb["env"]["core"][key])
    np.testing.assert_array_equal(ca["stats"]["recent"], cb["stats"]["recent"])


# A run extended with --updates anneals its learning rate over the new length: comparing
# one with an uninterrupted run needs a constant schedule (a resume at the same length
# is exact either way).
GRID = ("--scenario", "grid", "--num-envs", "4", "--batch-size", "32", "--seed", "3")
CONSTANT_SCHEDULES = (
    "--set",
    "train.lr_schedule=constant",
    "--set",
    "train.entropy_schedule=constant",
)


def test_resume_reproduces_uninterrupted_run(tmp_path: Path) -> None:
    code, full = _run(tmp_path / "a", *GRID, *CONSTANT_SCHEDULES, "--updates", "20")
    assert code == 0
    code, part = _run(tmp_path / "b", *GRID, *CONSTANT_SCHEDULES, "--updates", "10")
    assert code == 0 and checkpoint.load(part)["update"] == 10
    assert main(["--resume", str(part), "--updates", "20", "--no-progress"]) == 0
    _assert_same_run(full, part)
    config = json.loads((part / "config.json").read_text())
    assert config["train"]["updates"] == 20 and len(config["resumed"]) == 1
    # which libraries computed the floats, at the start and at each resume
    assert config["versions"]["numpy"] == np.__version__
    assert config["resumed"][0]["versions"]["torch"] == torch.__version__


def test_interrupt_mid_rollout_rewinds_to_last_update(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    code, full = _run(tmp_path / "a", *GRID, "--updates", "12")
    assert code == 0
    step, calls = VectorEnv.step, []

    def interrupted_step(self: VectorEnv, *args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == 8 * 6 + 3:  # inside the rollout of update 7
            raise KeyboardInterrupt
        return step(self, *args, **kwargs)

    monkeypatch.setattr(VectorEnv, "step", interrupted_step)
    code, part = _run(tmp_path / "b", *GRID, "--updates", "12")
    assert code == EXIT_INTERRUPTED
    assert "--resume" in capsys.readouterr().err
    assert checkpoint.load(part)["update"] == 6
    assert json.loads((part / "summary.json").read_text())["status"] == "interrupted"
    monkeypatch.setattr(VectorEnv, "step", step)
    assert main(["--resume", str(part), "--no-progress"]) == 0
    _assert_same_run(full, part)


@pytest.mark.parametrize(
    ("scenario", "stop_at"),
    [
        ("grid_collision", None),  # a checkpoint at an update's end
        ("grid_collision", 8 * 6 + 3),  # a stop inside update 7's rollout: a rewind
        pytest.param(
            "phys_collision", 8 * 3 + 5, marks=pytest.mark.skipif(not HAS_PHYSICS, reason="pymunk")
        ),
    ],
)
def test_episodes_straddling_a_resume_keep_their_whole_trajectory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys, scenario: str, stop_at: int | None
) -> None:
    """Every episode the summary counts has its trajectory and re-simulates, although many
    were running when the run stopped (contact events and velocities too, in physics)."""
    argv = ["--scenario", scenario, "--num-envs", "4", "--batch-size", "32", "--seed", "2"]
    step, calls = VectorEnv.step, []

    def interrupted_step(self: VectorEnv, *args: object, **kwargs: object) -> object:
        calls.append(1)
        if len(calls) == stop_at:
            raise KeyboardInterrupt
        return step(self, *args, **kwargs)

    if stop_at is not None:
        monkeypatch.setattr(VectorEnv, "step", interrupted_step)
    first = 6 if stop_at is None else 12
    code, run = _run(tmp_path, *argv, "--updates", str(first))
    assert code == (0 if stop_at is None else EXIT_INTERRUPTED)
    monkeypatch.setattr(VectorEnv, "step", step)
    carried = checkpoint.load(run)["log"]["open"]
    if scenario.startswith("phys"):
        assert carried is None  # physics games restart on resume: nothing straddles
    else:  # games caught mid-episode, with steps to carry
        assert (carried["rows"]["lengths"] > 1).sum() >= 2
    assert main(["--resume", str(run), "--updates", "12", "--no-progress"]) == 0
    log = read_run(run)
    summary = json.loads((run / "summary.json").read_text())
    assert len(log.parts) == 2 and log.n_episodes == summary["episodes"]
    capsys.readouterr()
    assert verify(log) == 0
    assert f"verify: {summary['episodes']} episodes" in capsys.readouterr().out
    assert replay_main([str(run), "--verify"]) == 0


@pytest.mark.parametrize(
    ("signum", "status"), [(signal.SIGINT, EXIT_INTERRUPTED), (signal.SIGTERM, 128 + 15)]
)
def test_sigint_or_sigterm_saves_checkpoint_closes_log_and_exits(
    tmp_path: Path, signum: int, status: int
) -> None:

    cmd = [sys.executable, "-m", "a2cm_phys.train", *GRID, "--updates", "1000000"]
    cmd += ["--logdir", str(tmp_path), "--no-progress", "--checkpoint-every", "20"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # wait until training is under way
            ckpts = list(tmp_path.glob("*/checkpoint.pt"))
            if ckpts and checkpoint.load(ckpts[0])["update"] >= 20:
                break
            time.sleep(0.1)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == status, err
    assert "Traceback" not in err and "--resume" in err
    (run_dir,) = tmp_path.iterdir()
    state = checkpoint.load(run_dir)
    assert state["update"] >= 20
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["updates"] == state["update"]
    assert read_run(run_dir).clean


def test_nonfinite_loss_stops_and_keeps_last_good_checkpoint(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    update, calls = Learner.update, []

    def failing_update(self: Learner, *args: object) -> dict[str, float]:
        calls.append(1)
        if len(calls) == 8:
            raise NonFiniteLoss("non-finite loss nan (no step taken)", {})
        return update(self, *args)

    monkeypatch.setattr(Learner, "update", failing_update)
    code, run_dir = _run(tmp_path, *GRID, "--updates", "20", "--checkpoint-every", "5")
    assert code == EXIT_NONFINITE
    err = capsys.readouterr().err
    assert "non-finite" in err and "update 5" in err
    state = checkpoint.load(run_dir)
    assert state["update"] == 5
    assert json.loads((run_dir / "summary.json").read_text())["status"] == "nonfinite"


def test_config_rejects_nan_rewards() -> None:
    from a2cm_phys.config import ConfigError

    with pytest.raises(ConfigError, match=r"rewards\.step.*finite"):
        load_scenario("grid", {"rewards.step": float("nan")})


def test_same_seed_same_run_different_seed_differs(tmp_path: Path) -> None:
    sc = load_scenario("grid")

    def weights(seed: int, name: str) -> list[torch.Tensor]:
        cfg = load_train({"num_envs": 4, "batch_size": 32, "updates": 5, "seed": seed})
        (tmp_path / name).mkdir()
        trainer = Trainer(sc, resolve_train(sc, cfg), tmp_path / name, record=False)
        assert trainer.run() == "done"
        return [p.detach().clone() for p in trainer.model.parameters()]

    a, b, c = weights(1, "a"), weights(1, "b"), weights(2, "c")
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(torch.equal(x, z) for x, z in zip(a, c, strict=True))


@pytest.mark.parametrize("algo, critics", [("a2cm", 1), ("a2c", 3)])
@pytest.mark.parametrize("paper", [True, False])
def test_model_has_n_actors_and_right_number_of_critics(
    tmp_path: Path, algo: str, critics: int, paper: bool
) -> None:
    sc = load_scenario("grid")
    options = {**(preset("paper") if paper else {}), "algo": algo}
    trainer = Trainer(sc, resolve_train(sc, load_train(options)), tmp_path, record=False)
    model, d, h, a, n = trainer.model, sc.obs_dim, 128, sc.actions, sc.pursuers
    k = 1 if paper else 2  # ours values the time and collision components apart
    assert model.n_agents == n and model.n_critics == critics and model.n_values == k
    actor = sum(p.numel() for name, p in model.named_parameters() if name.startswith("actor"))
    critic = sum(p.numel() for name, p in model.named_parameters() if name.startswith("critic"))
    assert actor == n * (d * h + h + h * a + a)
    assert critic == critics * (d * h + h + k * h + k)


@pytest.mark.parametrize("name", scenario_names())
def test_every_scenario_trains_a_few_updates(tmp_path: Path, name: str) -> None:
    sc = load_scenario(name)
    if sc.mode == "physics" and not HAS_PHYSICS:
        pytest.skip("a2cm_phys.envs.physics is not available yet")
    code, run_dir = _run(tmp_path, "--scenario", name, "--num-envs", "4", "--updates", "3")
    assert code == 0
    summary = json.loads((run_dir / "summary.json").read_text())
    config = json.loads((run_dir / "config.json").read_text())
    wide = sc.evader == "random" and (sc.mode == "grid" or sc.continuous)  # WIDE_DEFAULTS
    batch = 512 if (sc.continuous and sc.evader == "flee") or wide else 128  # the game's
    assert config["train"]["batch_size"] == batch
    assert summary["steps"] == 3 * batch and summary["status"] == "done"
    assert run_dir.name.startswith(f"{name}-a2cm-s0-")
    assert config["scenario"]["name"] == name and "--scenario" in config["command"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--scenario", "nope"], "unknown scenario"),
        (["--scenario", "grid", "--set", "rewards.nope=1"], "rewards.nope"),
        (["--scenario", "grid", "--set", "rewards.step=nan"], "finite"),
        (["--scenario", "grid", "--set", "train.gamma=2"], "gamma"),
        (["--scenario", "grid", "--lr", "-1"], "lr"),
        (["--scenario", "grid", "--num-envs", "3"], "multiple of num_envs"),
        (["--scenario", "grid", "--seed", "-1"], "seed"),
        (
            ["--scenario", "phys", "--workers", "2", "--num-envs", "1"],
            "'workers': 2 processes for num_envs=1",
        ),
        (["--updates", "3"], "--scenario is required"),
        (["--resume", "does/not/exist"], "no such run directory"),
    ],
)
def test_cli_errors_exit_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    code, _ = _run(tmp_path, *args)
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "logs").exists()  # no run directory for a bad command


def test_cli_error_has_no_traceback_and_resume_options_are_fixed(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    cmd = [sys.executable, "-m", "a2cm_phys.train", "--scenario", "grid", "--set", "size=1"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "size" in proc.stderr
    code, run_dir = _run(tmp_path, *GRID, "--updates", "1")
    assert code == 0
    assert main(["--resume", str(run_dir), "--algo", "a2c"]) == 2


def test_run_dir_option_and_config(tmp_path: Path) -> None:
    run_dir = tmp_path / "exact"
    args = [*GRID, "--updates", "2", "--run-dir", str(run_dir), "--no-record"]
    assert main([*args, "--no-progress"]) == 0
    assert {p.name for p in run_dir.iterdir()} >= {"config.json", "checkpoint.pt", "summary.json"}
    config = json.loads((run_dir / "config.json").read_text())
    assert config["train"]["seed"] == 3 and config["train"]["num_envs"] == 4
    assert main([*args, "--no-progress"]) == 2  # the directory holds a run: --resume it


@pytest.mark.skipif(not HAS_PHYSICS, reason="a2cm_phys.envs.physics is not available yet")
def test_physics_resume_restarts_games_deterministically(tmp_path: Path) -> None:
    args = ["--scenario", "phys", "--num-envs", "4", "--updates", "2", "--no-record"]
    code, run_dir = _run(tmp_path, *args)
    assert code == 0
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "checkpoint.pt").write_bytes((run_dir / "checkpoint.pt").read_bytes())
    for path in (run_dir, copy):
        assert main(["--resume", str(path), "--updates", "4", "--no-progress"]) == 0
    _assert_same_run(run_dir, copy)


def test_a_resumed_run_continues_its_episode_log(tmp_path, monkeypatch):
    """Every episode of an interrupted and resumed run has a summary in the run's logs."""
    from a2cm_phys.analysis.run_series import log_files
    from a2cm_phys.commands.train import main as train_main
    from a2cm_phys.training.trainer import Trainer

    original = Trainer._one_update

    def interrupt_at_update_6(self, on_step):
        if self.update == 6:
            raise KeyboardInterrupt
        original(self, on_step)

    run_dir = tmp_path / "run"
    argv = ["--scenario", "grid", "--num-envs", "4", "--updates", "12", "--run-dir",
            str(run_dir), "--no-progress"]  # fmt: skip
    monkeypatch.setattr(Trainer, "_one_update", interrupt_at_update_6)
    assert train_main(argv) == 130
    monkeypatch.setattr(Trainer, "_one_update", original)
    assert train_main(["--resume", str(run_dir), "--no-progress"]) == 0
    logs = [read_run(f) for f in log_files(run_dir)]
    names = [f.name for f in log_files(run_dir)]
    assert names == ["episodes.mcap", "episodes-001-from-000006.mcap"]
    ids = [int(i) for lg in logs for i in lg.episodes["episode"]]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert ids == list(range(summary["episodes"]))
    assert all(lg.clean for lg in logs)


def test_trainer_creates_a_missing_run_directory(tmp_path: Path) -> None:
    """The Python API needs no mkdir first: run() makes the directory it saves into."""
    run_dir = tmp_path / "not" / "yet" / "there"
    grid = load_scenario("grid")
    trainer = Trainer(grid, resolve_train(grid, load_train({"updates": 2})), run_dir, record=False)
    assert trainer.run() == "done"
    assert (run_dir / checkpoint.CHECKPOINT_NAME).is_file()
