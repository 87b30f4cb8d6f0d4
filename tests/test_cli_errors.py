"""Bad input to any command: exit 2, one line naming the option, key or file, no traceback,
nothing left behind (issue 15). Each case is one probe of a class of mistakes."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest
import torch

BIG = str(2**63 - 100)

CASES = [
    # train: options
    ("train", ["--device", "nonsense"], "--device"),
    ("train", ["--seed", str(2**64)], "--seed"),
    ("train", ["--seed", "-1"], "--seed"),
    ("train", ["--updates", "0"], "--updates"),
    ("train", ["--updates", "many"], "--updates"),
    ("train", ["--num-envs", "0"], "--num-envs"),
    ("train", ["--num-envs", BIG], "num_envs"),
    ("train", ["--batch-size", BIG], "batch_size"),
    ("train", ["--scenario", "phys_cont_flee", "--num-envs", "48"], "default of 512"),
    ("train", ["--threads", "100000"], "threads"),
    ("train", ["--log-every", "-1"], "--log-every"),
    ("train", ["--scene-every", "-1"], "--scene-every"),
    ("train", ["--checkpoint-every", "-1"], "--checkpoint-every"),
    ("train", ["--lr", "nan"], "lr"),
    ("train", ["--lr", "inf"], "lr"),
    ("train", ["--lr", "1e308"], "'lr': must be at most"),
    ("train", ["--algo", "ppo"], "--algo"),
    ("train", ["--preset", "nope"], "--preset"),
    ("train", ["--frobnicate"], "--frobnicate"),
    ("train", ["--logdir", "{file}"], "--logdir"),
    ("train", ["--logdir", "{file}/below"], "--logdir"),
    ("train", ["--run-dir", "{file}"], "--run-dir"),
    ("train", ["--resume", "{file}"], "checkpoint"),
    ("train", ["--resume", "{dir}"], "no checkpoint"),
    # train: scenario values
    ("train", ["--set", f"size={BIG}"], "'size': must be at most 1,000"),
    ("train", ["--set", f"max_steps={BIG}"], "'max_steps': must be at most"),
    ("train", ["--set", "pursuers=1000"], "'pursuers'"),
    ("train", ["--set", "size=1"], "'size'"),
    ("train", ["--set", "rewards.step=nan"], "rewards.step"),
    ("train", ["--set", "evader=teleport"], "'evader'"),
    ("train", ["--set", "nope=1"], "'nope'"),
    ("train", ["--set", "size"], "key=value"),
    ("train", ["--set", 'name="../../x"'], "'name'"),
    ("train", ["--set", "name=/tmp/abs"], "'name'"),
    ("train", ["--set", f"train.hidden={BIG}"], "hidden"),
    ("train", ["--set", "train.exploit_every=-1"], "exploit_every"),
    ("train", ["--scenario", "phys_vs", "--preset", "descent"], "'descent_every'"),
    ("train", ["--set", "train.descent_lr=0"], "descent_lr"),
    ("train", ["--scenario", "grid_vs", "--set", "train.descent_teams=both"], "'descent_teams'"),
    ("train", ["--set", "train.descent_teams=evader"], "descent_teams"),
    ("train", ["--set", "train.layers=0"], "layers"),
    ("train", ["--set", "train.encoding=bits"], "encoding"),
    ("train", ["--scenario", "phys", "--set", "train.encoding=onehot"], "'encoding'"),
    ("train", ["--set", "train.gae_lambda=2"], "gae_lambda"),
    ("train", ["--set", "train.normalize_advantages=1"], "normalize_advantages"),
    ("train", ["--set", "train.value_norm_beta=1"], "value_norm_beta"),
    (
        "train",
        ["--set", "train.constrain_collisions=true", "--set", "train.split_rewards=false"],
        "constrain_collisions",
    ),
    ("train", ["--set", "train.nope=1"], "'nope'"),
    ("train", ["--set", "train.device=nonsense"], "--device"),
    ("train", ["--scenario", "nope"], "unknown scenario 'nope'"),
    ("train", ["--scenario", "missing.toml"], "missing.toml"),
    ("train", ["--scenario", "{bad_toml}"], "invalid TOML"),
    # evaluate
    ("evaluate", ["--policy", "random", "--episodes", "0"], "--episodes"),
    ("evaluate", ["--policy", "random", "--num-envs", BIG], "--num-envs"),
    ("evaluate", ["--policy", "random", "--seed", str(2**64)], "--seed"),
    ("evaluate", ["--policy", "random", "--set", "size=3"], "--set"),
    ("evaluate", ["{dir}"], "no checkpoint"),
    ("evaluate", ["--pursuers", "orcale", "--scenario", "grid"], "--pursuers orcale: not one of"),
    ("evaluate", ["--pursuers", "oracle", "--evader", "fle", "--scenario", "grid"], "--evader fle"),
    (
        "evaluate",
        ["--evader", "best-response", "--pursuers", "pursuit", "--scenario", "phys"],
        "grids only",
    ),
    (
        "evaluate",
        ["--reference", "optimum", "--policy", "random", "--scenario", "grid"],
        "--reference",
    ),
    ("evaluate", ["--policy", "random", "--scenario", "nope"], "unknown scenario"),
    # replay
    ("replay", ["{dir}"], "no episodes.mcap"),
    ("replay", ["{file}"], "not an MCAP file"),
    ("replay", ["{dir}/missing.mcap"], "no such file"),
    ("replay", ["{file}", "--max-frames", "0"], "--max-frames"),
    ("replay", ["{file}", "--fps", "-2"], "--fps"),
    ("replay", ["{file}", "--parts", "0"], "--parts"),
    ("replay", ["{file}", "--episode", "-1"], "--episode"),
    ("replay", ["{file}", "--out", "{dir}"], "--out"),
    ("replay", ["{file}", "--export-foxglove", "{dir}"], "--export-foxglove"),
    # plot
    ("plot", ["{dir}"], "no episodes.mcap"),
    ("plot", ["{dir}/nope"], "no such file"),
    ("plot", ["{dir}", "--window", "0"], "--window"),
    ("plot", ["{dir}", "--out", "{file}"], "--out"),
    # oracle
    ("oracle", ["--set", "size=1"], "'size'"),
    ("oracle", ["--scenario", "phys"], "grid mode only"),
    ("oracle", ["--set", "train.lr=1"], "train.lr"),
    ("oracle", ["--scenario", "nope"], "unknown scenario"),
    # sweep
    ("sweep", ["--scenarios", "grid", "--seeds", "0,0,1"], "--seeds"),
    ("sweep", ["--scenarios", "grid", "--algos", "ppo"], "'algo'"),
    ("sweep", ["--scenarios", "grid", "--algos", ","], "--algos"),
    ("sweep", ["--scenarios", "grid,grid"], "--scenarios"),
    ("sweep", ["--scenarios", "nope"], "unknown scenario"),
    ("sweep", ["--scenarios", "grid", "--logdir", "{file}"], "--logdir"),
    ("sweep", ["--scenarios", "grid", "--cpus-per-run", "0"], "--cpus-per-run"),
    ("sweep", ["--scenarios", "grid", "--log-every", "-1"], "--log-every"),
    ("sweep", ["--scenarios", "grid", "--set", "train.device=nonsense"], "--device"),
    ("sweep", ["--scenarios", "grid", "--set", f"size={BIG}"], "'size'"),
    ("sweep", ["--scenarios", "grid", "--live"], "--live: a sweep trains many runs"),
    # experiments
    ("experiments", ["--modes", "water"], "--modes"),
    ("experiments", ["--seeds", "1,1"], "--seeds"),
    ("experiments", ["--set", "size=3"], "--set"),
    ("experiments", ["--updates", "0"], "--updates"),
    ("experiments", ["--eval-episodes", "0"], "--eval-episodes"),
    ("experiments", ["--logdir", "{file}"], "--logdir"),
    ("experiments", ["--out", "{file}"], "--out"),
]

DEFAULTS = {  # what makes the command otherwise valid
    "train": ["--scenario", "grid", "--updates", "1", "--no-progress", "--logdir", "logs"],
    "evaluate": [],
    "replay": [],
    "plot": [],
    "oracle": ["--no-cache"],
    "sweep": ["--sequential", "--logdir", "sweep", "--no-record"],
    "experiments": ["--sequential", "--logdir", "runs", "--out", "docs"],
}


def _argv(command: str, args: list[str], tmp_path: Path) -> list[str]:
    names = {"file": "a-file.txt", "dir": "a-folder", "bad_toml": "bad.toml"}
    filled = [a.format(**{k: str(tmp_path / v) for k, v in names.items()}) for a in args]
    given = {a for a in filled if a.startswith("--")}
    defaults, out = DEFAULTS[command], []
    i = 0
    while i < len(defaults):  # a default option is dropped when the case gives it
        takes_value = i + 1 < len(defaults) and not defaults[i + 1].startswith("--")
        if defaults[i] not in given:
            out += defaults[i : i + 1 + takes_value]
        i += 1 + takes_value
    if command == "train" and "--resume" in given:
        out = [a for a in out if a not in ("--scenario", "grid", "--updates", "1")]
    return [*filled, *out]


@pytest.mark.parametrize(("command", "args", "message"), CASES)
def test_bad_input_exits_2_with_one_line_and_leaves_nothing(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    command: str,
    args: list[str],
    message: str,
) -> None:
    (tmp_path / "a-file.txt").write_text("not a log, not a folder\n")
    (tmp_path / "a-folder").mkdir()
    (tmp_path / "bad.toml").write_text("size = = 3\n")
    before = sorted(tmp_path.rglob("*"))
    monkeypatch.chdir(tmp_path)
    main = importlib.import_module(f"a2cm_phys.{command}").main
    assert main(_argv(command, args, tmp_path)) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert message in err, err
    assert sorted(tmp_path.rglob("*")) == before  # no run directory, no output


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_cuda_without_cuda_is_a_one_line_error(tmp_path: Path, capsys) -> None:
    from a2cm_phys.commands.train import main

    assert main(["--scenario", "grid", "--device", "cuda", "--logdir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--device" in err and "CUDA is not available" in err
    assert not any(tmp_path.iterdir())


def test_argparse_errors_have_no_usage_dump_and_no_traceback(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "a2cm_phys.replay", "x.mcap", "--max-frames", "0"]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "Traceback" not in proc.stderr and "usage:" not in proc.stderr
