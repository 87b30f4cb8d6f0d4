"""A run's numbers in the standard tools (``train --logger tensorboard|wandb|csv``).

The MCAP log stays the run's source of truth; a :class:`MetricsLogger` is one more view
of the same numbers, on the same x axis, environment steps (all games):

- per update: the document the log's ``/train/update`` channel gets
  (:func:`~a2cm_phys.record.updates.update_document`: the trainer's metrics, the counters
  ``update``, ``env_steps``, ``episodes`` and ``steps_per_s``, the wall-clock rate each view
  measures for itself), at the update's ``env_steps``;
- per :data:`~a2cm_phys.record.schemas.PLOT_EVERY` episodes: the log's ``/plot/episodes``
  points (:class:`~a2cm_phys.record.curve.EpisodeCurve`), at the end of their last episode.

The backends: :class:`CsvLogger` (``RUN_DIR/metrics/updates.csv`` and ``episodes.csv``,
each a :class:`~.csv_table.CsvTable`),
:class:`TensorBoardLogger` (``RUN_DIR/tensorboard``, scalars ``update/KEY`` and
``episodes/KEY``) and :class:`WandbLogger` (an offline W&B run under ``RUN_DIR/wandb``
unless ``WANDB_MODE`` says otherwise). A resumed session continues each where the
checkpoint stands: whatever a killed session wrote past it (after ``env_steps`` of the
checkpoint) is dropped, from the CSV files and by TensorBoard's ``purge_step``.

A logger never stops or changes the run: a backend that fails to write says so once on
stderr and logs nothing more, while the run, its MCAP log and its checkpoints go on.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson

from ..base.errors import UserError
from ..config import Train, to_dict
from ..envs.tallies import EpisodeBatch
from ..record.curve import EpisodeCurve, episode_columns, update_point
from ..record.schemas import PLOT_EVERY
from ..record.updates import StepRate, update_document
from .csv_table import CsvTable
from .rundir import write_atomic

if TYPE_CHECKING:
    from ..envs.vector import VecStep, VectorEnv

LOGGERS = ("tensorboard", "wandb", "csv")
"""The names ``--logger`` takes."""
METRICS_DIR = "metrics"
"""The CSV logger's folder in the run directory."""
TENSORBOARD_DIR = "tensorboard"
"""The TensorBoard logger's folder in the run directory (``tensorboard --logdir`` it)."""
WANDB_PROJECT = "a2cm_phys"
"""The W&B project runs are logged to."""
WANDB_ID_NAME = "run-id"
"""The file under ``RUN_DIR/wandb`` holding the run's W&B id, so that a resume continues it."""


def make_logger(name: str, run_dir: str | Path, config: dict[str, Any]) -> MetricsLogger:
    """The ``--logger NAME`` backend for the run in ``run_dir`` (``config``: its resolved
    training config); a :class:`UserError` if its library is not installed."""
    backends = {"tensorboard": TensorBoardLogger, "wandb": WandbLogger, "csv": CsvLogger}
    if name not in backends:
        raise ValueError(f"unknown logger {name!r} (one of {', '.join(LOGGERS)})")
    return backends[name](run_dir, config)


def make_loggers(
    loggers: Iterable[str | MetricsLogger], run_dir: str | Path, cfg: Train
) -> list[MetricsLogger]:
    """Each of ``loggers`` once: a name made into its backend (:func:`make_logger`) for the
    run in ``run_dir`` trained with ``cfg``, a logger kept as it is."""
    config = to_dict(cfg)
    return [
        make_logger(x, run_dir, config) if isinstance(x, str) else x for x in dict.fromkeys(loggers)
    ]


class MetricsLogger:
    """A view of a run's numbers (see the module docs), called as the run's log is:
    :meth:`start` on the session's env and clocks, :meth:`step` after every vector step,
    :meth:`update` after every update, :meth:`close` at the session's end. Backends write
    the rows (:meth:`_open`, :meth:`_write_update`, :meth:`_write_points`, :meth:`_close`);
    a failure there disables the logger with a warning, and never raises."""

    name = ""
    """The ``--logger`` name."""

    def __init__(self, run_dir: str | Path, config: dict[str, Any]) -> None:
        self.run_dir, self.config = Path(run_dir), config
        self.failed = False
        """Whether a write failed (the logger then logs nothing more)."""
        self._opened = False
        self._games = self._steps = self._episodes = 0
        self._curve: EpisodeCurve | None = None
        self._pending: list[tuple[int, int, EpisodeBatch]] = []  # (first id, step, …)
        self._rate = StepRate(0)

    def start(self, vec_env: VectorEnv, step: int = 0, episode: int = 0) -> None:
        """Begin with ``vec_env`` right after its reset, or where a resumed run's checkpoint
        stands (``step`` vector steps and ``episode`` episodes done, as for the log)."""
        self._games, self._steps, self._episodes = vec_env.num_envs, int(step), int(episode)
        self._curve = EpisodeCurve(vec_env.scenario, PLOT_EVERY, vec_env.learned_evader)
        self._rate = StepRate(self._steps)
        self._opened = self._guarded(lambda: self._open(self._steps * self._games))

    def step(self, actions: np.ndarray, step: VecStep) -> None:
        """Take one vector step (a :data:`~.rollout.StepHook`: ``actions`` are not used)."""
        first = self._episodes
        self._steps += 1
        if step.episodes:
            self._episodes += len(step.episodes)
            if self._opened:  # (a failed logger keeps nothing)
                self._pending.append((first, self._steps, step.episodes))

    def update(self, update: int, metrics: dict[str, Any]) -> None:
        """Write the curve points completed since the last update, then the update."""
        if not self._opened:
            return
        env_steps = self._steps * self._games
        rate = self._rate.measure(self._steps, self._games)

        def write() -> None:
            self._write_points(self._points())
            doc = update_document(update, metrics, env_steps, self._episodes, rate)
            self._write_update(env_steps, doc)

        self._guarded(write)

    def close(self) -> None:
        """Write the points still owed (the open group too, as the log does at its end),
        then close the backend; idempotent."""
        if not self._opened:
            return
        self._opened = False
        if self._guarded(lambda: self._write_points(self._points(final=True))):
            self._guarded(self._close)

    def _points(self, final: bool = False) -> list[tuple[int, dict[str, Any]]]:
        """``(env_steps, point)`` of the curve points the pending episodes complete (with
        ``final``: the open one too)."""
        pending, self._pending = self._pending, []
        curve = self._curve
        if curve is None:
            return []
        out: list[tuple[int, bytes]] = []
        if pending:
            eps = EpisodeBatch.concat([e for _, _, e in pending])
            ids = np.arange(pending[0][0], pending[0][0] + len(eps))
            ends = np.repeat([s for _, s, _ in pending], [len(e) for _, _, e in pending])
            # the curve's clock is environment steps here (the x axis), not nanoseconds
            out += curve.add(ids, ends * self._games, **episode_columns(eps, curve.learned))
        if final:
            out += curve.rest()
        return [(t, orjson.loads(data)) for t, data in out]

    def _guarded(self, write: Callable[[], object]) -> bool:
        """Run a backend's ``write``; whether it succeeded (on a failure: one warning, the
        backend closed, nothing more logged)."""
        if self.failed:
            return False
        try:
            write()
            return True
        except Exception as err:  # a view must never stop the run, nor reach its log
            self.failed, self._opened = True, False
            print(
                f"warning: --logger {self.name}: {_error_text(err)}; it logs nothing more"
                " (the run and its MCAP log go on)",
                file=sys.stderr,
            )
        with contextlib.suppress(Exception):
            self._close()
        return False

    def _open(self, env_steps: int) -> None:
        """Open the backend at ``env_steps`` (0: a new run); what an earlier session wrote
        past it is dropped."""

    def _write_update(self, env_steps: int, doc: dict[str, Any]) -> None:
        """Write one update's document (``/train/update``'s) at ``env_steps``."""

    def _write_points(self, points: list[tuple[int, dict[str, Any]]]) -> None:
        """Write curve points, each ``(env_steps, point)`` (``/plot/episodes``'s)."""

    def _close(self) -> None:
        """Close the backend (also after a failure: it may be half open)."""


class CsvLogger(MetricsLogger):
    """``RUN_DIR/metrics/updates.csv`` (a row per update) and ``episodes.csv`` (a row per
    curve point, with its ``env_steps``), with the standard library's :mod:`csv`. A resumed
    session appends to them, after dropping the rows past its start."""

    name = "csv"

    def __init__(self, run_dir: str | Path, config: dict[str, Any]) -> None:
        super().__init__(run_dir, config)
        folder = self.run_dir / METRICS_DIR
        self.updates = CsvTable(folder / "updates.csv", ("update", "env_steps", "episodes"))
        self.episodes = CsvTable(folder / "episodes.csv", ("env_steps", "episode", "episodes"))

    def _open(self, env_steps: int) -> None:
        self.updates.path.parent.mkdir(parents=True, exist_ok=True)
        self.updates.open(env_steps)
        self.episodes.open(env_steps)

    def _write_update(self, env_steps: int, doc: dict[str, Any]) -> None:
        self.updates.write([doc])

    def _write_points(self, points: list[tuple[int, dict[str, Any]]]) -> None:
        if points:
            self.episodes.write([{"env_steps": t, **p} for t, p in points])

    def _close(self) -> None:
        self.updates.close()
        self.episodes.close()


class TensorBoardLogger(MetricsLogger):
    """Scalars ``update/KEY`` (each update's numbers) and ``episodes/KEY`` (the curve
    points) in ``RUN_DIR/tensorboard``, at ``global_step`` = environment steps, with
    ``torch.utils.tensorboard``. A resumed session purges what a killed one wrote past it."""

    name = "tensorboard"

    def __init__(self, run_dir: str | Path, config: dict[str, Any]) -> None:
        super().__init__(run_dir, config)
        try:  # imported only when asked for: an optional extra, the core install stays light
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            raise UserError(_missing("tensorboard")) from None
        self._writer_class = SummaryWriter
        self._writer: Any = None

    def _open(self, env_steps: int) -> None:
        # TensorBoard hides every event at or past purge_step: the checkpoint's own update,
        # at env_steps, stays
        purge = env_steps + 1 if env_steps else None
        log_dir = self.run_dir / TENSORBOARD_DIR
        _later_than_every_file(log_dir)
        self._writer = self._writer_class(log_dir=str(log_dir), purge_step=purge)

    def _write_update(self, env_steps: int, doc: dict[str, Any]) -> None:
        for key, value in orjson.loads(update_point(doc)).items():
            self._writer.add_scalar(f"update/{key}", value, env_steps)

    def _write_points(self, points: list[tuple[int, dict[str, Any]]]) -> None:
        for env_steps, point in points:
            for key, value in point.items():
                self._writer.add_scalar(f"episodes/{key}", value, env_steps)

    def _close(self) -> None:
        if self._writer is not None:
            self._writer, writer = None, self._writer
            writer.close()


def _later_than_every_file(folder: Path) -> None:
    """Wait, if need be, for a wall-clock second later than that of every event file in
    ``folder``: TensorBoard reads a run's files in name order, which begins with the second
    a file was made (then the host and pid), and a resumed session's must come last."""
    stamps = [p.name.split(".")[3] for p in folder.glob("events.out.tfevents.*")]
    newest = max((int(t) for t in stamps if t.isdigit()), default=None)
    if newest is not None and time.time() < newest + 1:
        time.sleep(newest + 1 - time.time())


class WandbLogger(MetricsLogger):
    """A Weights & Biases run (project :data:`WANDB_PROJECT`, named as the run folder,
    the training config as its config) under ``RUN_DIR/wandb``: offline unless the
    ``WANDB_MODE`` environment variable says otherwise (``wandb sync`` uploads it). Its id
    is kept in ``RUN_DIR/wandb/run-id``, so that a resumed session continues the same run.
    Rows are logged at ``step`` = environment steps: ``update/KEY`` and ``episodes/KEY``
    (two curve points ending at the same step share a row: the later one is kept)."""

    name = "wandb"

    def __init__(self, run_dir: str | Path, config: dict[str, Any]) -> None:
        super().__init__(run_dir, config)
        try:  # imported only when asked for: an optional extra, and slow to import
            import wandb
        except ImportError:
            raise UserError(_missing("wandb")) from None
        self._wandb = wandb
        self._run: Any = None
        # W&B ignores a row at a step below one it has: an update's row waits for the next
        # curve point at or past its step (the point of the group still open at a session's
        # end can come from before its last update)
        self._held: list[tuple[int, dict[str, Any]]] = []

    def _open(self, env_steps: int) -> None:
        folder = self.run_dir / "wandb"
        folder.mkdir(parents=True, exist_ok=True)
        self._run = self._wandb.init(
            mode=None if os.environ.get("WANDB_MODE") else "offline",
            dir=self.run_dir,
            project=WANDB_PROJECT,
            name=self.run_dir.name,
            config=self.config,
            id=_wandb_id(folder / WANDB_ID_NAME),
            resume="allow",
            allow_val_change=True,  # a resume may extend the run's updates
            # the trainer's stdout and stderr are left as they are (no capture)
            settings=self._wandb.Settings(console="off"),
        )

    def _write_update(self, env_steps: int, doc: dict[str, Any]) -> None:
        row = {f"update/{k}": v for k, v in orjson.loads(update_point(doc)).items()}
        self._held.append((env_steps, row))

    def _write_points(self, points: list[tuple[int, dict[str, Any]]]) -> None:
        for env_steps, point in points:
            self._log_held(env_steps)
            self._run.log({f"episodes/{k}": v for k, v in point.items()}, step=env_steps)

    def _log_held(self, until: int | None = None) -> None:
        """Log the held update rows up to step ``until`` (``None``: all of them)."""
        while self._held and (until is None or self._held[0][0] <= until):
            env_steps, row = self._held.pop(0)
            self._run.log(row, step=env_steps)

    def _close(self) -> None:
        if self._run is None:
            return
        try:
            if not self.failed:
                self._log_held()
        finally:
            self._run, run = None, self._run
            run.finish()


def _wandb_id(path: Path) -> str:
    """The run's W&B id, kept in ``path`` (made the first time)."""
    try:
        text = path.read_text(encoding="utf-8").strip()
    except FileNotFoundError:
        text = ""
    if text:
        return text
    run_id = secrets.token_hex(4)
    write_atomic(path, run_id + "\n")
    return run_id


def _missing(name: str) -> str:
    """The error of a logger whose library is not installed."""
    return f'--logger {name}: needs the {name} package (pip install "a2cm_phys[{name}]")'


def _error_text(err: Exception) -> str:
    """A failed write as one line: ``FILE: reason`` of an ``OSError``, else its type and text."""
    if isinstance(err, OSError) and err.strerror:
        return f"{err.filename}: {err.strerror}" if err.filename else err.strerror
    return f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
