"""A sweep's run directories: what one holds (:func:`run_state`, :func:`stored_config`),
where a run is (:func:`find_run`: the folder whose ``config.json`` holds its resolved
scenario and training config, whatever its name, so that runs named before the preset was
part of the name are found and never trained again), whether a run may reuse it
(:func:`check_reusable`: only a run of exactly the requested resolved configuration), and
running one run in it under its lock (:func:`execute`: run, resume from its checkpoint,
skip when done, or report it busy)."""

from __future__ import annotations

import contextlib
import json
import signal
from pathlib import Path
from typing import Any

from ..config import ConfigError, Scenario, build, stored_train, to_dict
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
        from ..training import checkpoint

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


def _wanted(spec: RunSpec) -> dict[str, Any]:
    """``spec``'s resolved scenario and training config, as ``config.json`` holds them."""
    scenario, cfg = spec.resolve()
    return {"scenario": _plain(scenario), "train": _plain(cfg)}


def _normalised(stored: dict[str, Any]) -> dict[str, Any]:
    """A stored run's config completed for the keys added after it was written: the
    scenario's by building it as a resume does (a key it lacks holds its default, e.g.
    the fixed ``start``), the training config's by :func:`~a2cm_phys.config.stored_train`."""
    scenario = build(Scenario, stored["scenario"], "the run's scenario")
    return {"scenario": _plain(scenario), "train": stored_train(stored["train"])}


def existing_runs(sweep_dir: Path) -> dict[Path, dict[str, Any]]:
    """The runs in ``sweep_dir`` (its folders with a readable ``config.json``), each with
    its stored scenario and training config (completed for keys added since)."""
    runs: dict[Path, dict[str, Any]] = {}
    if not sweep_dir.is_dir():
        return runs
    for folder in sorted(sweep_dir.iterdir()):
        if not (folder / CONFIG_NAME).is_file():
            continue
        try:
            runs[folder] = _normalised(read_config(folder))
        except (ConfigError, OSError, TypeError):
            continue  # not a run this sweep can tell; its name alone may still be checked
    return runs


_STATE_ORDER = {"done": 0, "partial": 1, "new": 2}


def find_run(
    spec: RunSpec, sweep_dir: Path, runs: dict[Path, dict[str, Any]] | None = None
) -> Path:
    """The run directory of ``spec`` in ``sweep_dir``: the folder whose ``config.json``
    holds exactly ``spec``'s resolved scenario and training config, whatever its name (the
    one named :attr:`RunSpec.name` first, then the most advanced: done, partial); else
    ``sweep_dir / spec.name``, where a new run goes. ``runs`` is
    :func:`existing_runs` of ``sweep_dir``, when the caller has read it already."""
    sweep_dir = Path(sweep_dir)
    named = sweep_dir / spec.name
    runs = existing_runs(sweep_dir) if runs is None else runs
    wanted = _wanted(spec)
    same = [folder for folder, stored in runs.items() if not differences(stored, wanted)]
    if not same or named in same:
        return named
    return min(same, key=lambda folder: (_STATE_ORDER[run_state(folder)], folder.name))


def check_reusable(spec: RunSpec, run_dir: Path) -> None:
    """A :class:`ConfigError` if ``run_dir`` (``spec``'s, from :func:`find_run`) holds a
    run of another resolved configuration (it would be reported as this run's result)."""
    stored = stored_config(run_dir)
    if stored is None:
        return
    diff = differences(_normalised(stored), _wanted(spec))
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
    task or in the sweep's process. The run is found by its configuration
    (:func:`find_run`); ``"run_dir"`` says where it is."""
    run_dir = find_run(spec, Path(sweep_dir))
    run_dir.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as held:
        try:
            held.enter_context(run_lock(run_dir))
        except RunBusy as err:
            return {"sweep": BUSY, "busy": str(err)}
        # everything below, from reading the run's state on, happens under the lock
        return {**_execute_locked(spec, run_dir), "run_dir": str(run_dir)}


def _execute_locked(spec: RunSpec, run_dir: Path) -> dict[str, Any]:
    from ..training.trainer import Trainer

    check_reusable(spec, run_dir)
    state = run_state(run_dir)
    if state == "done":
        return {**json.loads((run_dir / SUMMARY_NAME).read_text()), "sweep": "skipped"}
    remove_stray_temps(run_dir)  # a writer killed mid-write left them; we hold the lock
    options = {"record": spec.record, "log_every": spec.log_every, "progress": False}
    if state == "partial":
        trainer = Trainer.resume(run_dir, **options)
    else:
        scenario, cfg = spec.resolve()
        write_config(run_dir, scenario, cfg, spec.command(run_dir), spec.preset)
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
