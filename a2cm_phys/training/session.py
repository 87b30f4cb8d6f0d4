"""One session of a run (:meth:`.Trainer.run`): the updates with the log open, checkpoints
on time and on a stop, how the session ended (its status and stop reason), the summary.

The order of writes keeps the run's invariant (``docs/design.md``): every checkpoint is
written after the log is durable up to it (:func:`save_checkpoint`); when the
disk is full, no checkpoint follows a log that could not be written.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from typing import Any

from threadpoolctl import threadpool_limits

from ..algos import NonFiniteLoss
from ..base.exitcodes import OUT_OF_SPACE
from ..config import Scenario
from . import checkpoint
from .progress import ProgressBar
from .recording import open_recorder, start_live, start_loggers
from .rollout import StepHook
from .run_state import capture, state_at_last_update
from .signals import ShieldedLog, StopSignals, signals_deferred
from .state import LEARN, RunState
from .summary import run_summary, write_summary


def run_session(run: RunState, one_update: Callable[[StepHook | None], None]) -> str:
    """Train up to ``cfg.updates`` (``one_update(on_step)`` taking each) and write the
    summary; return ``"done"``,
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
    run.run_dir.mkdir(parents=True, exist_ok=True)
    status = "done"
    # numpy's BLAS too gets the run's threads (it starts one per core otherwise: two
    # runs on two cores would then run four threads)
    with threadpool_limits(limits=run.cfg.threads), signals_deferred() as signals:
        run.signals = signals
        try:
            if not (run.run_dir / checkpoint.CHECKPOINT_NAME).exists():
                save_checkpoint(run)  # so there is always a last good checkpoint
            run.last_save = time.perf_counter()
            status = _train(run, signals, one_update)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            signals.shield()
            status, run.stop_reason = "no_space", os_error_text(err)
        run.stop_signal = signals.received
        try:
            run.last_summary = run_summary(run, status)
            write_summary(run.run_dir, run.last_summary)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            status = "no_space"
            run.stop_reason = run.stop_reason or os_error_text(err)
        finally:
            run.signals = None
    return status


def save_checkpoint(run: RunState, state: dict[str, Any] | None = None) -> None:
    """Write the checkpoint (atomically) from ``state`` or the run's current state,
    after making the log durable up to it: every episode the checkpoint counts is on disk
    before the checkpoint is (see ``docs/design.md``, the run's invariant)."""
    state = state if state is not None else capture(run)
    signals = run.signals
    if signals is not None:  # a second Ctrl-C waits for the end of the save
        signals.in_log = True
    try:
        if run.recorder is not None:
            run.recorder.flush(durable=True)
        checkpoint.save(run.run_dir / checkpoint.CHECKPOINT_NAME, state)
        run.saved_update = int(state["update"])
        run.last_save = time.perf_counter()
    finally:
        if signals is not None:
            signals.after_log()


def _train(
    run: RunState, signals: StopSignals, one_update: Callable[[StepHook | None], None]
) -> str:
    """The updates of a session with its log open, then its last checkpoint; the status it
    stopped with. The loggers are closed last, however the session ends."""
    dead_worker = _worker_error(run.scenario)
    status, save = "done", None
    with _loggers(run), _recorder(run) as recorder, _bar(run) as bar:
        run.recorder = recorder
        if run.live is not None:
            start_live(run, run.live)
        log = ShieldedLog(recorder, signals) if recorder is not None else None
        try:
            _updates(run, signals, log, bar, one_update)
        except KeyboardInterrupt:
            status = "interrupted"
            if run.boundary.phase != LEARN:  # mid-update weights could be half-stepped
                save = state_at_last_update(run)
        except NonFiniteLoss as err:
            status, run.stop_reason = "nonfinite", str(err)
        except dead_worker as err:
            status, run.stop_reason = "worker_died", str(err).splitlines()[0]
            save = state_at_last_update(run)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            status, run.stop_reason = "no_space", os_error_text(err)
        else:  # (a finished run resumed for nothing keeps its checkpoints as they are)
            save = capture(run) if run.update != run.saved_update else None
        signals.shield()
        try:
            if save is not None:
                save_checkpoint(run, save)
        except OSError as err:
            if err.errno not in OUT_OF_SPACE:
                raise
            status, run.stop_reason = "no_space", os_error_text(err)
        finally:
            run.recorder = None
        if status == "no_space" and recorder is not None:
            recorder.abandon()  # writing more would fail too; the checkpoint's part is durable
    return status


def _updates(
    run: RunState,
    signals: StopSignals,
    log: ShieldedLog | None,
    bar: ProgressBar,
    one_update: Callable[[StepHook | None], None],
) -> None:
    """Update after update until the run is done or a stop is asked for (then a
    ``KeyboardInterrupt``), each logged, shown and checkpointed when one is due."""
    on_step = _step_hook(
        log.record_step if log is not None else None,
        run.live.step if run.live is not None else None,
        *(logger.step for logger in run.loggers),
    )
    while run.update < run.cfg.updates:
        if signals.stop_requested:
            raise KeyboardInterrupt
        one_update(on_step)
        if log is not None:
            log.record_update(run.update, run.last_metrics)
        if run.loggers:
            signals.in_log = True  # a second Ctrl-C waits for whole rows
            for logger in run.loggers:
                logger.update(run.update, run.last_metrics)
            signals.after_log()
        if run.live is not None:
            run.live.update(run.update, run.last_metrics)
        bar.tick()
        if _checkpoint_due(run):
            save_checkpoint(run)


def _step_hook(*hooks: StepHook | None) -> StepHook | None:
    """What sees every vector step: those of the log's recorder, the live view and the
    loggers there are (``None`` for one that is not), in that order; ``None`` if none."""
    there = [hook for hook in hooks if hook is not None]
    if len(there) <= 1:
        return there[0] if there else None

    def every(actions: Any, step: Any) -> None:
        for hook in there:
            hook(actions, step)

    return every


@contextmanager
def _loggers(run: RunState) -> Iterator[None]:
    """The run's loggers for the block: started on this session's env and clocks (before
    the log, whose first update's rate would count a W&B start; a finished run gets no new,
    empty views), closed when it ends, however it ends (a logger never raises)."""
    if not run.finished:
        start_loggers(run)
    try:
        yield
    finally:
        for logger in run.loggers:
            logger.close()


def _checkpoint_due(run: RunState) -> bool:
    """Whether a checkpoint is due: every ``checkpoint_every`` updates, and at least every
    ``checkpoint_seconds``."""
    every = run.checkpoint_every
    due = every and run.update % every == 0
    return bool(due or time.perf_counter() - run.last_save >= run.checkpoint_seconds)


def _recorder(run: RunState) -> AbstractContextManager[Any]:
    """The MCAP episode recorder, or a null context when the run does not record (or
    has nothing left to train: a finished run gets no new, empty part)."""
    recorder = open_recorder(run) if run.record and not run.finished else None
    return recorder if recorder is not None else nullcontext()


def _bar(run: RunState) -> ProgressBar:
    """The session's progress (a bar on a terminal, plain lines elsewhere), or one that
    shows nothing."""
    return ProgressBar(run) if run.progress else ProgressBar(None)


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
