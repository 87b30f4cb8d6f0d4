"""``python -m a2cm_phys.train --scenario grid``: train A2C or A2CM on a scenario.

Parses the options, claims the run directory (a new one under ``--logdir`` named
``<scenario>-<algo>[-<preset>]-s<seed>-<time>``, ``--run-dir``, or ``--resume RUN_DIR``:
:mod:`a2cm_phys.training.rundir`, its lock held for the session),
hands over to :class:`a2cm_phys.training.trainer.Trainer` and prints the summary and how
the session ended, with the command that resumes it (exit statuses:
:mod:`a2cm_phys.base.exitcodes`). What a run directory holds and why nothing is lost:
``docs/design.md``.
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import signal
import sys
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..base.exitcodes import EXIT_INTERRUPTED, EXIT_NO_SPACE, EXIT_NONFINITE, EXIT_WORKER_DIED
from ..config import Train, resolve_train
from ..training.rundir import (
    CHECKPOINT_NAME,
    CONFIG_NAME,
    LOCK_NAME,
    LOG_PART,
    RUN_FILES,
    append_session,
    make_run_dir,
    remove_stray_temps,
    run_lock,
    write_config,
)
from ..training.rundir import PREVIOUS_CHECKPOINT_NAME as PREVIOUS_NAME
from .options import (
    SEED,
    Parser,
    UsageError,
    add_scenario_options,
    int_range,
    run_cli,
    scenario_from_args,
    train_from_args,
    writable_dir,
)

if TYPE_CHECKING:  # the trainer (torch) is imported once the options are parsed
    from ..config import Scenario
    from ..training.live import LiveView
    from ..training.trainer import Trainer

__all__ = [
    "EXIT_INTERRUPTED",
    "EXIT_NONFINITE",
    "EXIT_NO_SPACE",
    "EXIT_WORKER_DIED",
    "build_parser",
    "main",
]

# ---------------------------------------------------------------------- command line

_TRAIN_FLAGS = (
    "algo", "num_envs", "updates", "batch_size", "seed", "lr",
    "reward_scale", "max_grad_norm", "device", "threads", "workers",
)  # fmt: skip

_COUNT = int_range(1)
_EVERY = int_range(0)


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.train`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.train",
        description="Train A2CM (one shared critic) or A2C (N actor-critic pairs).",
    )
    add_scenario_options(
        p,
        scenario_help="scenario name (see a2cm_phys/scenarios/) or path to a TOML file"
        " (no default: required unless --resume)",
    )
    _add_train_flags(p)
    _add_run_flags(p)
    return p


def _add_train_flags(p: argparse.ArgumentParser) -> None:
    """The training options that have a flag of their own (the rest: ``--set train.KEY``)."""
    d = Train()
    p.add_argument("--algo", choices=["a2cm", "a2c"], help=f"the learner (default: {d.algo})")
    p.add_argument(
        "--num-envs",
        type=_COUNT,
        help="parallel games (default: 16; against the random evader, grid or continuous"
        " control: 64; --preset paper: 1, the paper's setting)",
    )
    p.add_argument(
        "--updates",
        type=_COUNT,
        help="gradient updates (default: 5000; grid against the random evader: 640,000"
        " steps' worth; continuous control: 2,000,000 steps' worth, 4,000,000 against the"
        " fleeing evader)",
    )
    p.add_argument(
        "--batch-size",
        type=_COUNT,
        help="steps per update over all games (default: 128; against the random evader, grid"
        " or continuous control, and continuous control against the fleeing evader: 512)",
    )
    p.add_argument("--seed", type=SEED, help=f"the run's seed (default: {d.seed})")
    p.add_argument(
        "--lr",
        type=float,
        help="learning rate (default: 0.007, the paper's; against the random evader, grid or"
        " continuous control: 0.01)",
    )
    p.add_argument(
        "--reward-scale",
        type=float,
        help=f"rewards are multiplied by this before learning (default: {d.reward_scale:g})",
    )
    p.add_argument(
        "--max-grad-norm",
        type=float,
        help="gradient clipping; 0 disables it (default: 0; continuous control: 0.5)",
    )
    p.add_argument("--device", help=f"torch device: cpu, cuda, cuda:1, mps (default: {d.device})")
    p.add_argument("--threads", type=_COUNT, help=f"torch threads (default: {d.threads})")
    p.add_argument(
        "--workers",
        type=_COUNT,
        help=f"physics: processes stepping the games (default: {d.workers})",
    )


def _add_run_flags(p: argparse.ArgumentParser) -> None:
    """Where the run goes, what it logs, how it shows its progress."""
    p.add_argument(
        "--logdir",
        default="logs",
        help="parent folder of new run directories, named SCENARIO-ALGO[-PRESET]-sSEED-TIME",
    )
    p.add_argument(
        "--run-dir",
        help="exact run directory, instead of a new one under --logdir (default: none)",
    )
    p.add_argument(
        "--resume",
        metavar="RUN_DIR",
        help="continue a run; --updates may extend it (default: none, a new run)",
    )
    p.add_argument(
        "--log-every",
        type=_EVERY,
        help="log every K-th episode's trajectory; 0: none (default: 1; a resumed run: its own)",
    )
    p.add_argument(
        "--scene-every",
        type=_EVERY,
        help="Foxglove scenes every K episodes; 0: off (default: 0; a resumed run: its own)",
    )
    p.add_argument("--no-record", action="store_true", help="no MCAP episode log")
    p.add_argument(
        "--checkpoint-every",
        type=_EVERY,
        default=0,
        help="also save a checkpoint every K updates, besides every 30 s; 0: only those"
        " (default: 0)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar or lines")
    p.add_argument(
        "--live",
        nargs="?",
        const="",
        metavar="[HOST:]PORT",
        help="serve the run to Foxglove while it trains: one game's episodes and the learning"
        " curve (default: off; given alone, 127.0.0.1:8765, local only unless a host is"
        " named)",
    )
    p.add_argument(
        "--logger",
        action="append",
        choices=("tensorboard", "wandb", "csv"),  # training.loggers.LOGGERS, not imported
        default=[],
        help="also log the updates' metrics and the learning curve to TensorBoard, Weights &"
        " Biases (offline) or CSV files, in RUN_DIR; may be repeated (default: none)",
    )


def check_new_run_dir(run_dir: Path) -> None:
    """A :class:`UsageError` unless ``run_dir`` can take a new run: it must not hold a run
    (a checkpoint: ``--resume`` it) nor a run's files (which a new run would overwrite)."""
    if run_dir.exists() and not run_dir.is_dir():
        raise UsageError(f"--run-dir {run_dir}: is a file")
    if (run_dir / CHECKPOINT_NAME).exists():
        raise UsageError(f"--run-dir {run_dir}: holds a run already (use --resume)")
    found = [f for f in RUN_FILES if (run_dir / f).exists()]
    found += sorted(p.name for p in run_dir.glob("episodes*.mcap") if LOG_PART.fullmatch(p.name))
    if found:
        raise UsageError(
            f"--run-dir {run_dir}: holds {', '.join(found)} of an earlier run but no checkpoint;"
            " a new run would overwrite them (choose another folder or move them away)"
        )
    writable_dir(run_dir, "--run-dir")


def _check_run_files(run_dir: Path) -> None:
    """A :class:`UsageError` if one of the run's files is not a file (it could not be
    written at the end of the session)."""
    for name in RUN_FILES:
        path = run_dir / name
        if path.exists() and not path.is_file():
            raise UsageError(f"--resume {run_dir}: {path} is not a file (move it away)")


def _resume_dir(args: argparse.Namespace) -> Path:
    """The run directory ``--resume`` names, checked: it holds a run, and no option that
    cannot change is given (a :class:`UsageError` otherwise)."""
    fixed = [f"--{k.replace('_', '-')}" for k in _TRAIN_FLAGS if k != "updates"]
    given = [f for f in fixed if getattr(args, f[2:].replace("-", "_")) is not None]
    given += ["--scenario"] * bool(args.scenario) + ["--set"] * bool(args.set)
    given += ["--run-dir"] * bool(args.run_dir) + ["--preset"] * (args.preset is not None)
    if given:
        raise UsageError(f"--resume: {', '.join(given)} cannot change when resuming")
    run = Path(args.resume)
    run_dir = run if run.is_dir() else run.parent
    if not run_dir.is_dir():
        raise UsageError(f"--resume {run}: no such run directory")
    if run.is_file() and run.name != CHECKPOINT_NAME:
        raise UsageError(f"--resume {run}: not a run directory or its {CHECKPOINT_NAME}")
    if not any((run_dir / n).is_file() for n in (CONFIG_NAME, CHECKPOINT_NAME, PREVIOUS_NAME)):
        raise UsageError(f"--resume {run_dir}: no checkpoint (and no config.json): not a run")
    writable_dir(run_dir, "--resume")
    return run_dir


def _open_run(args: argparse.Namespace, command: str, held: ExitStack) -> Trainer:
    """The trainer of a new or resumed run, with the run's lock entered into ``held``."""
    from ..training.trainer import Trainer

    options = {
        "checkpoint_every": args.checkpoint_every,
        "progress": not args.no_progress,  # a bar on a terminal, plain lines elsewhere
        "loggers": args.logger,  # a library not installed fails before the games start
    }
    if args.resume:
        run_dir = _resume_dir(args)
        held.enter_context(run_lock(run_dir))
        remove_stray_temps(run_dir)
        _check_run_files(run_dir)
        trainer = Trainer.resume(
            args.resume,
            args.updates,
            record=False if args.no_record else None,
            log_every=args.log_every,
            scene_every=args.scene_every,
            **options,
        )
        trainer.live = _open_live(args, trainer.scenario, held)
        append_session(trainer.run_dir, command, trainer.update, trainer.scenario, trainer.cfg)
        return trainer
    if not args.scenario:
        raise UsageError("--scenario is required (or --resume RUN_DIR)")
    scenario = scenario_from_args(args)
    cfg = train_from_args(args, {k: getattr(args, k) for k in _TRAIN_FLAGS})
    cfg = resolve_train(scenario, cfg)  # checked, before the run directory exists
    live = _open_live(args, scenario, held)  # a busy port fails before anything is written
    if args.run_dir:
        run_dir = Path(args.run_dir)
        if run_dir.exists() and not run_dir.is_dir():
            raise UsageError(f"--run-dir {run_dir}: is a file")
        writable_dir(run_dir, "--run-dir")
        existed = run_dir.exists()
        run_dir.mkdir(parents=True, exist_ok=True)
        lock_existed = (run_dir / LOCK_NAME).exists()
        held.enter_context(run_lock(run_dir))  # before looking: two new runs race here
        try:
            check_new_run_dir(run_dir)
        except UsageError:  # refused: leave the folder as it was
            if not lock_existed:
                (run_dir / LOCK_NAME).unlink(missing_ok=True)
            raise
    else:
        writable_dir(args.logdir, "--logdir")
        run_dir, existed = make_run_dir(args.logdir, scenario, cfg, args.preset), False
        held.enter_context(run_lock(run_dir))
    try:
        write_config(run_dir, scenario, cfg, command, args.preset)
        return Trainer(
            scenario,
            cfg,
            run_dir,
            record=not args.no_record,
            log_every=1 if args.log_every is None else args.log_every,
            scene_every=args.scene_every or 0,
            live=live,
            **options,
        )
    except BaseException:  # e.g. no memory for the games: leave no half-made run behind
        (run_dir / CONFIG_NAME).unlink(missing_ok=True)
        if not existed:
            shutil.rmtree(run_dir, ignore_errors=True)
        raise


def _open_live(args: argparse.Namespace, scenario: Scenario, held: ExitStack) -> LiveView | None:
    """The live view ``--live`` asks for (closed with ``held``), or ``None``."""
    if args.live is None:
        return None
    from ..training.live import LiveView, live_address  # the Foxglove SDK: only when asked

    live = LiveView.open(scenario, *live_address(args.live))
    held.callback(live.close)
    print(
        f"live view: {live.url} (in Foxglove: Open connection, with the layout"
        " docs/foxglove/layout.json)",
        file=sys.stderr,
    )
    return live


def _print_summary(summary: dict[str, Any]) -> None:
    for key, value in summary.items():
        text = f"{value:.4g}" if isinstance(value, float) else value
        print(f"{key:>24}: {text}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.train``; returns the exit status."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    command = shlex.join(["python", "-m", "a2cm_phys.train", *argv])
    with ExitStack() as held:  # the run's lock, for the whole session
        trainer = _open_run(args, command, held)
        print(f"run directory: {trainer.run_dir}", file=sys.stderr)
        if trainer.resume_note:
            print(f"note: {trainer.resume_note}", file=sys.stderr)
        if trainer.finished:
            print(
                f"note: the run is at update {trainer.update} of {trainer.cfg.updates}:"
                " nothing to train (--updates N extends it)",
                file=sys.stderr,
            )
        try:
            status = trainer.run()
        finally:
            trainer.close()
    return _report(trainer, status)


def _report(trainer: Trainer, status: str) -> int:
    """Print the summary and how the session ended; the exit status."""
    _print_summary(trainer.last_summary)
    resume = f"python -m a2cm_phys.train --resume {shlex.quote(str(trainer.run_dir))}"
    if status == "interrupted":
        signum = trainer.stop_signal or signal.SIGINT
        print(
            f"interrupted ({signal.Signals(signum).name}): checkpoint at update"
            f" {trainer.saved_update}; resume with:\n  {resume}",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED if signum == signal.SIGINT else 128 + signum
    if status == "worker_died":
        print(
            f"stopped: {trainer.stop_reason}\ncheckpoint at update {trainer.saved_update};"
            f" resume with:\n  {resume}",
            file=sys.stderr,
        )
        return EXIT_WORKER_DIED
    if status == "no_space":
        print(
            f"stopped: {trainer.stop_reason}\nthe last good checkpoint (update"
            f" {trainer.saved_update}) is kept, and the log holds every episode up to it;"
            f" free some space (or copy {trainer.run_dir} elsewhere) and resume with:"
            f"\n  {resume}",
            file=sys.stderr,
        )
        return EXIT_NO_SPACE
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
