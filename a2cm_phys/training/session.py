"""One session of a run (:meth:`.Trainer.run`): the updates with the log open, checkpoints
on time and on a stop, how the session ended (its status and stop reason), the summary;
and the run's clock across sessions (:class:`SessionClock`).

The order of writes keeps the run's invariant (``docs/design.md``): every checkpoint is
written after the log is durable up to it (:meth:`.Trainer.save_checkpoint`); when the
disk is full, no checkpoint follows a log that could not be written.
"""

from __future__ import annotations

import time
from contextlib import AbstractContextManager, nullcontext
from typing import TYPE_CHECKING, Any

from threadpoolctl import threadpool_limits

from ..algos import NonFiniteLoss
from ..base.exitcodes import OUT_OF_SPACE
from ..config import Scenario
from . import checkpoint
from .progress import ProgressBar
from .recording import open_recorder
from .run_state import LEARN, state_at_last_update
from .signals import ShieldedLog, StopSignals, signals_deferred
from .summary import write_summary

if TYPE_CHECKING:
    from .trainer import Trainer


class SessionClock:
    """The run's wall time over all its sessions, and this session's steps and speed."""

    def __init__(self) -> None:
        self.before = 0.0  # wall time of earlier sessions of this run
        self.start = time.perf_counter()
        self.steps = 0  # environment steps of this session

    def resume(self, before: float) -> None:
        """Continue a run that spent ``before`` seconds in earlier sessions, from now."""
        self.before, self.start = before, time.perf_counter()

    def wall_time(self) -> float:
        """Seconds spent training in this run, over all sessions."""
        return self.before + time.perf_counter() - self.start

    def speed(self, now: float) -> float:
        """Environment steps per second of wall time in this session, up to ``now``."""
        return self.steps / max(now - self.start, 1e-9)


def run_session(trainer: Trainer) -> str:
    """Train up to ``cfg.updates`` and write the summary; return ``"done"``,
    ``"interrupted"``, ``"nonfinite"``, ``"worker_died"`` or ``"no_space"`` (a write failed
    for want of space: the last good checkpoint is kept, consistent with the log;
    :attr:`.Trainer.stop_reason` names the file).

    The first Ctrl-C or SIGTERM stops at the end of the current update (a second one
    stops at once, but never in the middle of writing the log); either way the
    checkpoint holds the state after the last whole update. Once stopping, while the
    checkpoint, the log and the summary are written, further signals are ignored. A
    non-finite loss stops the run without overwriting the last good checkpoint. A
    physics worker that dies stops the run with the checkpoint at the last whole update
    (:attr:`.Trainer.stop_reason` names the worker). :attr:`.Trainer.stop_signal` is the
    signal that stopped an interrupted run. The run directory is created if it does not
    exist.
    """
    trainer.run_dir.mkdir(parents=True, exist_ok=True)
    status = "done"
    # numpy's BLAS too gets the run's threads (it starts one per core otherwise: two
    # runs on two cores would then run four threads)
    with threadpool_limits(limits=trainer.cfg.threads), signals_deferred() as signals:
        trainer.signals = signals
        try:
            if not (trainer.run_dir / checkpoint.CHECKPOINT_NAME).exists():
                trainer.save_checkpoint()  # so there is always a last good checkpoint
            trainer.last_save = time.perf_counter()
            status = _train(trainer, signals)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            signals.shield()
            status, trainer.stop_reason = "no_space", os_error_text(err)
        trainer.stop_signal = signals.received
        try:
            trainer.last_summary = trainer.summary(status)
            write_summary(trainer.run_dir, trainer.last_summary)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            status = "no_space"
            trainer.stop_reason = trainer.stop_reason or os_error_text(err)
        finally:
            trainer.signals = None
    return status


def save_checkpoint(trainer: Trainer, state: dict[str, Any] | None = None) -> None:
    """Write the checkpoint (atomically) from ``state`` or the trainer's current state,
    after making the log durable up to it: every episode the checkpoint counts is on disk
    before the checkpoint is (see ``docs/design.md``, the run's invariant)."""
    state = state if state is not None else trainer.checkpoint_state()
    signals = trainer.signals
    if signals is not None:  # a second Ctrl-C waits for the end of the save
        signals.in_log = True
    try:
        if trainer.recorder is not None:
            trainer.recorder.flush(durable=True)
        checkpoint.save(trainer.run_dir / checkpoint.CHECKPOINT_NAME, state)
        trainer.saved_update = int(state["update"])
        trainer.last_save = time.perf_counter()
    finally:
        if signals is not None:
            signals.after_log()


def _train(trainer: Trainer, signals: StopSignals) -> str:
    """The updates of a session with its log open, then its last checkpoint; the status it
    stopped with."""
    dead_worker = _worker_error(trainer.scenario)
    status, save = "done", None
    with _recorder(trainer) as recorder, _bar(trainer) as bar:
        trainer.recorder = recorder
        log = ShieldedLog(recorder, signals) if recorder is not None else None
        try:
            _updates(trainer, signals, log, bar)
        except KeyboardInterrupt:
            status = "interrupted"
            if trainer.boundary.phase != LEARN:  # mid-update weights could be half-stepped
                save = state_at_last_update(trainer)
        except NonFiniteLoss as err:
            status, trainer.stop_reason = "nonfinite", str(err)
        except dead_worker as err:
            status, trainer.stop_reason = "worker_died", str(err).splitlines()[0]
            save = state_at_last_update(trainer)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            status, trainer.stop_reason = "no_space", os_error_text(err)
        else:  # (a finished run resumed for nothing keeps its checkpoints as they are)
            save = trainer.checkpoint_state() if trainer.update != trainer.saved_update else None
        signals.shield()
        try:
            if save is not None:
                trainer.save_checkpoint(save)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            status, trainer.stop_reason = "no_space", os_error_text(err)
        finally:
            trainer.recorder = None
        if status == "no_space" and recorder is not None:
            recorder.abandon()  # writing more would fail too; the checkpoint's part is durable
    return status


def _updates(
    trainer: Trainer, signals: StopSignals, log: ShieldedLog | None, bar: ProgressBar
) -> None:
    """Update after update until the run is done or a stop is asked for (then a
    ``KeyboardInterrupt``), each logged, shown and checkpointed when one is due."""
    on_step = log.record_step if log is not None else None
    while trainer.update < trainer.cfg.updates:
        if signals.stop_requested:
            raise KeyboardInterrupt
        trainer._one_update(on_step)
        if log is not None:
            log.record_update(trainer.update, trainer.last_metrics)
        bar.tick()
        if _checkpoint_due(trainer):
            trainer.save_checkpoint()


def _checkpoint_due(trainer: Trainer) -> bool:
    """Whether a checkpoint is due: every ``checkpoint_every`` updates, and at least every
    ``checkpoint_seconds``."""
    every = trainer.checkpoint_every
    due = every and trainer.update % every == 0
    return bool(due or time.perf_counter() - trainer.last_save >= trainer.checkpoint_seconds)


def _recorder(trainer: Trainer) -> AbstractContextManager[Any]:
    """The MCAP episode recorder, or a null context when the run does not record (or
    has nothing left to train: a finished run gets no new, empty part)."""
    recorder = open_recorder(trainer) if trainer.record and not trainer.finished else None
    return recorder if recorder is not None else nullcontext()


def _bar(trainer: Trainer) -> ProgressBar:
    """The progress bar, or one that shows nothing."""
    return ProgressBar(trainer) if trainer.progress else ProgressBar(None)


def os_error_text(err: OSError) -> str:
    """``FILE: reason`` of a failed write."""
    where = f"{err.filename}: " if err.filename else ""
    return f"{where}{err.strerror or err}"


def _worker_error(scenario: Scenario) -> type[Exception]:
    """The exception of a dead physics worker (a class never raised in grid mode, so that
    grid runs do not import the physics engine)."""
    if scenario.mode != "physics":
        return _NeverRaised
    from ..envs.workers import WorkerError

    return WorkerError


class _NeverRaised(Exception):
    pass
