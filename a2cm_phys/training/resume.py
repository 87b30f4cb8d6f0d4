"""Where a resumed run starts: :func:`resume_point` reads the run directory (the latest good
checkpoint, the previous one if the latest is damaged, or ``config.json`` for a run that
never saved one) into the scenario, options and state :meth:`.Trainer.resume` builds on."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..config import ConfigError, Scenario, Train, build, load_train, stored_train
from . import checkpoint
from .rundir import CONFIG_NAME, read_config


@dataclass(frozen=True)
class ResumePoint:
    """What a resumed run starts from.

    ``log`` holds the trainer's ``record``, ``log_every`` and ``scene_every``; ``state`` is
    the checkpoint's (``None``: the run starts at update 0 from ``config.json``) and
    ``note`` says when the previous checkpoint was taken instead of the latest.
    """

    run_dir: Path
    scenario: Scenario
    cfg: Train
    log: dict[str, Any]
    state: dict[str, Any] | None
    note: str | None


def resume_point(
    run_dir: str | Path,
    updates: int | None = None,
    *,
    record: bool | None = None,
    log_every: int | None = None,
    scene_every: int | None = None,
) -> ResumePoint:
    """Where the run in ``run_dir`` (or the run of the checkpoint file given) continues,
    optionally extended to ``updates``.

    It continues from the latest good checkpoint (the previous one if the latest is
    damaged: ``note`` then says so), or from update 0 with the run's ``config.json`` if the
    run never saved one. ``record``, ``log_every`` and ``scene_every`` left ``None`` keep
    the run's own; a run that logs cannot be resumed without its log (that would lose
    episodes). A :class:`ConfigError` if the run cannot be read, if ``updates`` is behind
    it, or if ``record`` is ``False`` for a run that logs.
    """
    run_dir = Path(run_dir)
    if run_dir.is_file():  # the checkpoint itself was given
        run_dir = run_dir.parent
    try:
        state, note = checkpoint.load_latest(run_dir)
    except FileNotFoundError as err:
        state, note = None, None
        if not (run_dir / CONFIG_NAME).is_file():
            raise ConfigError(f"--resume: {err}") from None
    except (OSError, ValueError) as err:
        raise ConfigError(f"--resume: {err}") from None
    stored, where = _stored_run(run_dir, state)
    scenario = build(Scenario, stored["scenario"], where)
    train = stored_train(stored["train"])  # written before some options existed?
    at = 0 if state is None else state["update"]
    if updates is not None:
        if updates < at:
            raise ConfigError(f"--updates {updates}: the run is at update {at} already")
        train["updates"] = updates
    cfg = load_train(train, where)
    log = (state or {}).get("log") or {}
    was_recording = bool(log.get("record", True))
    if record is False and was_recording:
        raise ConfigError(
            f"--no-record: {run_dir} logs its episodes; a session without its log would"
            " lose them (resume it without --no-record)"
        )
    settings = {
        "record": was_recording if record is None else record and was_recording,
        "log_every": log.get("log_every", 1) if log_every is None else log_every,
        "scene_every": log.get("scene_every", 0) if scene_every is None else scene_every,
    }
    return ResumePoint(run_dir, scenario, cfg, settings, state, note)


def _stored_run(run_dir: Path, state: dict[str, Any] | None) -> tuple[dict[str, Any], str]:
    """The scenario and training options to resume with, and where they come from: the
    checkpoint, or ``config.json`` for a run that never saved one."""
    if state is not None:
        return state, f"{run_dir} (checkpoint)"
    try:
        return read_config(run_dir), str(run_dir / CONFIG_NAME)
    except ConfigError as err:
        raise ConfigError(f"--resume: no checkpoint, and {err}") from None
