"""Train A2C or A2CM on a scenario: ``python -m a2cm_phys.train --scenario grid``.

One trainer for both algorithms; only the model differs (``make_model``: one critic for
A2CM, N for A2C). Each update collects ``batch_size`` steps (``batch_size / num_envs`` per
game) and takes one learner step. A run lives in ``<logdir>/<scenario>-<algo>-s<seed>-<time>/``:

- ``config.json``: the resolved scenario and training config and the command line(s);
- ``checkpoint.pt``: everything to continue exactly (:meth:`Trainer.checkpoint_state`),
  written atomically every ``checkpoint_seconds`` (or ``checkpoint_every`` updates), on
  Ctrl-C and at the end;
- ``summary.json``: episode counts, mean length, collisions, captures, time, speed;
- ``episodes.mcap``: the episode log (:mod:`a2cm_phys.record`; not continued on resume yet).

``--resume RUN_DIR`` continues bit for bit in grid mode (an interrupted and resumed run
ends with the same weights and episode statistics as an uninterrupted one). In physics
mode the games running at the checkpoint are restarted on resume unless the physics core
can save its state (see :meth:`a2cm_phys.envs.vector.VectorEnv.state`).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

from . import checkpoint
from .config import (
    ConfigError,
    Scenario,
    Train,
    load_scenario,
    load_train,
    parse_assignments,
    to_dict,
)
from .trainer import (
    EXIT_INTERRUPTED,
    EXIT_NONFINITE,
    Trainer,
    check_seed,
    check_workers,
    policy_rng,
)

__all__ = ["EXIT_INTERRUPTED", "EXIT_NONFINITE", "Trainer", "build_parser", "main", "policy_rng"]

# ---------------------------------------------------------------------- command line

_TRAIN_FLAGS = (
    "algo", "num_envs", "updates", "batch_size", "seed", "lr",
    "reward_scale", "max_grad_norm", "device", "threads", "workers",
)  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.train`` argument parser."""
    p = argparse.ArgumentParser(
        prog="python -m a2cm_phys.train",
        description="Train A2CM (one shared critic) or A2C (N actor-critic pairs).",
    )
    p.add_argument("--scenario", help="scenario name (scenarios/*.toml) or TOML path")
    p.add_argument("--algo", choices=["a2cm", "a2c"])
    p.add_argument("--num-envs", type=int, help="parallel games (1 = the paper's setting)")
    p.add_argument("--updates", type=int, help="gradient updates (default 5000)")
    p.add_argument("--batch-size", type=int, help="steps per update over all games (128)")
    p.add_argument("--seed", type=int)
    p.add_argument("--lr", type=float)
    p.add_argument("--reward-scale", type=float)
    p.add_argument("--max-grad-norm", type=float, help="0 disables clipping")
    p.add_argument("--device")
    p.add_argument("--threads", type=int, help="torch threads (default 1)")
    p.add_argument("--workers", type=int, help="physics: processes stepping the games (1)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="scenario override (rewards.step=-2), or train.KEY=VALUE for any Train field",
    )
    p.add_argument("--logdir", default="logs", help="parent folder of run directories")
    p.add_argument("--run-dir", help="exact run directory (instead of one under --logdir)")
    p.add_argument("--resume", metavar="RUN_DIR", help="continue a run (--updates may extend it)")
    p.add_argument("--log-every", type=int, default=1, help="recorder: log every K-th episode")
    p.add_argument("--scene-every", type=int, default=0, help="recorder: scenes every K (0 off)")
    p.add_argument("--no-record", action="store_true", help="no MCAP episode log")
    p.add_argument("--checkpoint-every", type=int, default=0, help="also save every K updates")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def make_run_dir(logdir: str | Path, scenario: Scenario, cfg: Train) -> Path:
    """Create ``<logdir>/<scenario>-<algo>-s<seed>-<YYYYmmdd-HHMMSS>[-k]/`` and return it."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    base = Path(logdir) / f"{scenario.name}-{cfg.algo}-s{cfg.seed}-{stamp}"
    for k in range(1000):
        path = base if k == 0 else base.with_name(f"{base.name}-{k}")
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            continue
    raise FileExistsError(f"{base}: too many runs with this name")


def _trainer_from_args(args: argparse.Namespace, command: str) -> Trainer:
    options = {
        "record": not args.no_record,
        "log_every": args.log_every,
        "scene_every": args.scene_every,
        "checkpoint_every": args.checkpoint_every,
        "progress": not args.no_progress and sys.stderr.isatty(),
    }
    if args.resume:
        fixed = [f"--{k.replace('_', '-')}" for k in _TRAIN_FLAGS if k != "updates"]
        given = [f for f in fixed if getattr(args, f[2:].replace("-", "_")) is not None]
        given += ["--scenario"] * bool(args.scenario) + ["--set"] * bool(args.set)
        given += ["--run-dir"] * bool(args.run_dir)
        if given:
            raise ConfigError(f"--resume: {', '.join(given)} cannot change when resuming")
        trainer = Trainer.resume(args.resume, args.updates, **options)
        _append_command(trainer.run_dir, command, trainer.update, trainer.cfg)
        return trainer
    if not args.scenario:
        raise ConfigError("--scenario is required (or --resume RUN_DIR)")
    assignments = parse_assignments(args.set)
    train_set = {k[len("train.") :]: v for k, v in assignments.items() if k.startswith("train.")}
    scenario_set = {k: v for k, v in assignments.items() if not k.startswith("train.")}
    scenario = load_scenario(args.scenario, scenario_set)
    flags = {k: getattr(args, k) for k in _TRAIN_FLAGS if getattr(args, k) is not None}
    cfg = load_train({**train_set, **flags})
    check_seed(cfg)  # before the run directory exists
    check_workers(scenario, cfg)
    if args.run_dir:
        run_dir = Path(args.run_dir)
        if (run_dir / checkpoint.CHECKPOINT_NAME).exists():
            raise ConfigError(f"--run-dir {run_dir}: holds a run already (use --resume)")
        run_dir.mkdir(parents=True, exist_ok=True)
    else:
        run_dir = make_run_dir(args.logdir, scenario, cfg)
    write_config(run_dir, scenario, cfg, command)
    return Trainer(scenario, cfg, run_dir, **options)


def write_config(run_dir: Path, scenario: Scenario, cfg: Train, command: str) -> None:
    """Write ``config.json``: the resolved scenario and training config, and the command."""
    config = {
        "scenario": to_dict(scenario),
        "train": to_dict(cfg),
        "command": command,
        "created": datetime.now().isoformat(timespec="seconds"),
    }
    (Path(run_dir) / "config.json").write_text(json.dumps(config, indent=2) + "\n")


def _append_command(run_dir: Path, command: str, update: int, cfg: Train) -> None:
    path = run_dir / "config.json"
    config = json.loads(path.read_text()) if path.exists() else {}
    config["train"] = to_dict(cfg)
    config.setdefault("resumed", []).append({"command": command, "at_update": update})
    path.write_text(json.dumps(config, indent=2) + "\n")


def _print_summary(summary: dict[str, Any]) -> None:
    for key, value in summary.items():
        text = f"{value:.4g}" if isinstance(value, float) else value
        print(f"{key:>24}: {text}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.train``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    command = shlex.join(["python", "-m", "a2cm_phys.train", *argv])
    try:
        trainer = _trainer_from_args(args, command)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"run directory: {trainer.run_dir}", file=sys.stderr)
    try:
        status = trainer.run()
    finally:
        trainer.close()
    _print_summary(trainer.last_summary)
    resume = f"python -m a2cm_phys.train --resume {shlex.quote(str(trainer.run_dir))}"
    if status == "interrupted":
        print(
            f"interrupted: checkpoint at update {trainer.saved_update}; resume with:\n  {resume}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if status == "nonfinite":
        print(
            f"stopped: {trainer.stop_reason} at update {trainer.update + 1}; the last"
            f" good checkpoint (update {trainer.saved_update}) is kept in {trainer.run_dir}"
            " (a lower --lr, a --reward-scale or a --max-grad-norm may help)",
            file=sys.stderr,
        )
        return EXIT_NONFINITE
    print(f"summary: {trainer.run_dir / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
