"""A sweep's run directories: what one holds (:func:`run_state`, :func:`stored_config`),
whether a run may reuse it (:func:`check_reusable`: only a run of exactly the requested
resolved configuration), and running one run in it under its lock (:func:`execute`: run,
resume from its checkpoint, skip when done, or report it busy)."""

from __future__ import annotations

import contextlib
import json
import signal
from pathlib import Path
from typing import Any

from ..config import ConfigError, stored_train, to_dict
from ..training import checkpoint
from ..training.rundir import (
    CHECKPOINT_NAME,
    CONFIG_NAME,
    SUMMARY_NAME,
    RunBusy,
    read_config,
    remove_stray_temps,
    run_lock,
    write_config,
)
from ..training.trainer import Trainer
from .runspec import RunSpec
from .stopping import Interrupted

BUSY = "busy"
"""The outcome of a run that another process writes (it holds the run's lock)."""


def run_state(run_dir: Path) -> str:
    """``done`` (summary of a finished run), ``partial`` (a checkpoint) or ``new``."""
    summary = run_dir / SUMMARY_NAME
    if summary.exists():
        try:
            if json.loads(summary.read_text()).get("status") == "done":
                return "done"
        except (OSError, json.JSONDecodeError):
            pass
    return "partial" if (run_dir / CHECKPOINT_NAME).exists() else "new"


def _plain(obj: Any) -> Any:
    return json.loads(json.dumps(to_dict(obj)))


def stored_config(run_dir: Path) -> dict[str, Any] | None:
    """The resolved ``scenario`` and ``train`` config a run directory holds (its
    ``config.json``, else its checkpoint), or ``None`` if it holds no run."""
    if (run_dir / CONFIG_NAME).exists():
        try:
            return read_config(run_dir)
        except ConfigError as err:
            raise ConfigError(f"{err}; cannot tell which run this is") from None
    if (run_dir / CHECKPOINT_NAME).exists():
        try:
            state = checkpoint.load(run_dir)
        except (OSError, ValueError) as err:
            raise ConfigError(str(err)) from None
        return {"scenario": state["scenario"], "train": state["train"]}
    return None


def differences(stored: Any, wanted: Any, prefix: str = "") -> list[str]:
    """``key: stored vs wanted`` for every leaf that differs between two nested dicts."""
    if isinstance(stored, dict) and isinstance(wanted, dict):
        out = []
        for key in sorted(set(stored) | set(wanted)):
            out += differences(stored.get(key), wanted.get(key), f"{prefix}{key}.")
        return out
    return [] if stored == wanted else [f"{prefix[:-1]}: {stored!r} there, {wanted!r} now"]


def check_reusable(spec: RunSpec, sweep_dir: Path) -> None:
    """A :class:`ConfigError` if ``spec``'s run directory holds a run of another resolved
    configuration (it would be reported as this run's result)."""
    run_dir = sweep_dir / spec.name
    stored = stored_config(run_dir)
    if stored is None:
        return
    scenario, cfg = spec.resolve()
    stored = {**stored, "train": stored_train(stored["train"])}
    diff = differences(stored, {"scenario": _plain(scenario), "train": _plain(cfg)})
    if diff:
        shown = "; ".join(diff[:3]) + (f"; and {len(diff) - 3} more" if len(diff) > 3 else "")
        raise ConfigError(
            f"{run_dir}: holds a run of another configuration ({shown}); use another --logdir,"
            " or move that run away"
        )


def execute(spec: RunSpec, sweep_dir: str) -> dict[str, Any]:
    """Run (or resume, or skip) one run holding its run directory's lock; returns its
    summary, with ``"sweep"`` saying what was done (``ran``, ``resumed``, ``skipped``), or
    ``{"sweep": "busy", "busy": why}`` if another process holds the lock. Runs inside a Ray
    task or in the sweep's process."""
    run_dir = Path(sweep_dir) / spec.name
    run_dir.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as held:
        try:
            held.enter_context(run_lock(run_dir))
        except RunBusy as err:
            return {"sweep": BUSY, "busy": str(err)}
        # everything below, from reading the run's state on, happens under the lock
        return _execute_locked(spec, run_dir)


def _execute_locked(spec: RunSpec, run_dir: Path) -> dict[str, Any]:

    check_reusable(spec, run_dir.parent)
    state = run_state(run_dir)
    if state == "done":
        return {**json.loads((run_dir / SUMMARY_NAME).read_text()), "sweep": "skipped"}
    remove_stray_temps(run_dir)  # a writer killed mid-write left them; we hold the lock
    options = {"record": spec.record, "log_every": spec.log_every, "progress": False}
    if state == "partial":
        trainer = Trainer.resume(run_dir, **options)
    else:
        scenario, cfg = spec.resolve()
        write_config(run_dir, scenario, cfg, spec.command(run_dir))
        trainer = Trainer(scenario, cfg, run_dir, **options)
    try:
        status = trainer.run()
    finally:
        trainer.close()
    if status == "interrupted":  # Ctrl-C or SIGTERM: the checkpoint is saved, stop the sweep
        raise Interrupted(trainer.stop_signal or signal.SIGINT)
    if status != "done":
        raise RuntimeError(f"{spec.name}: training stopped ({status}) {trainer.stop_reason}")
    return {**trainer.last_summary, "sweep": "resumed" if state == "partial" else "ran"}
