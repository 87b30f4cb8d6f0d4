"""``EpisodeRecorder``: the trainer's run log ``RUN_DIR/episodes.mcap`` (zstd chunks).

Cheap by construction, because a grid step costs only a few microseconds per game:

- each vector step is copied into time-major numpy buffers (:mod:`.buffers`), one slice
  assignment per field whatever the number of games; a finished episode only queues
  ``(summary, first row)`` (:mod:`.episode_rows`);
- the queue is encoded in *blocks* — when the buffer is full, at each flush and at close —
  with one gather per field (:mod:`.block`) and a vectorised JSON text encoder
  (:mod:`.jsontext`: no per-episode or per-step Python work on the grid), as one trajectory
  message and one summary message per block (columnar: arrays over the block's episodes;
  :mod:`.encoder` writes them, :mod:`.runlog` splits them again);
- a block's messages go into one chunk, and a chunk is closed at least every
  ``flush_seconds`` and whenever it holds ``chunk_bytes``, so a killed run loses only the
  last few seconds and never half an episode (the file itself: :mod:`.logfile`).

Topics, schemas and the time base are described in :mod:`.schemas`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..config import Scenario
from ..envs.vector import VecStep, VectorEnv
from .encoder import EpisodeEncoder
from .episode_rows import EpisodeRows
from .logfile import LogFile, log_metadata
from .schemas import PLOT_EVERY, schemas_for
from .updates import StepRate, update_messages


class EpisodeRecorder:
    """Write a run's episodes, updates and scenes to an MCAP file (see the module docs):
    ``start(vec_env)`` after ``vec_env.reset(seed)``, ``record_step(actions, step)`` after
    each vector step, ``record_update(update, metrics)`` after each update, ``close()`` (or
    ``with``). Logged: every summary; the trajectory of every ``log_every``-th episode, the
    ``foxglove.SceneUpdate`` frames of every ``scene_every``-th, a learning-curve point per
    ``plot_every`` (:data:`.schemas.PLOT_EVERY`) and each update's plot point (0: none).
    ``metadata`` (JSON-able, the training config under ``"train"``) is stored with the
    scenario, version and command line. Episodes running at ``close`` are carried by the
    checkpoint (:meth:`open_episodes`) into the resumed run's ``start(…, carried=…)``.
    """

    def __init__(
        self,
        path: str | Path,
        scenario: Scenario,
        metadata: dict[str, Any] | None = None,
        log_every: int = 1,
        scene_every: int = 0,
        flush_seconds: float = 2.0,
        chunk_bytes: int = 1 << 20,
        plot_every: int | None = None,
    ) -> None:
        plot_every = PLOT_EVERY if plot_every is None else plot_every
        if log_every < 0 or scene_every < 0 or plot_every < 0:
            raise ValueError("log_every, scene_every and plot_every must be >= 0")
        self.path = Path(path)
        self.scenario = scenario
        self.log_every, self.scene_every, self.plot_every = log_every, scene_every, plot_every
        self.flush_seconds, self.chunk_bytes = flush_seconds, chunk_bytes
        self._encoder = EpisodeEncoder(scenario, log_every, scene_every, plot_every)
        self.dt, self._step_ns = self._encoder.dt, self._encoder.step_ns
        user = {**(metadata or {}), "plot_every": plot_every}
        meta = log_metadata(scenario, user, log_every, scene_every, self.dt)
        self._file = LogFile(self.path, meta, chunk_bytes, flush_seconds, schemas_for(scenario))
        self._vec: VectorEnv | None = None
        self._rows: EpisodeRows | None = None  # the step buffers, from start() on
        self._finished = 0  # episodes queued so far (ids are given in finishing order)
        self._steps = 0  # vector steps so far: the log's clock

    def start(
        self, vec_env: VectorEnv, obs: Any = None, step: int = 0, episode: int = 0,
        carried: dict | None = None,
    ) -> None:  # fmt: skip
        """Begin recording ``vec_env`` right after its ``reset`` (``obs`` is not needed).
        ``step`` (vector steps) and ``episode`` (episodes finished) start the log's clock
        and ids where a resumed run's log stopped (0: a new run); ``carried``: the
        checkpoint's :meth:`open_episodes`, logged whole when they finish."""
        self._vec = vec_env
        self._steps, self._finished = int(step), int(episode)
        self._rows = EpisodeRows(vec_env, self.scenario.max_steps, self._steps, carried)
        self._encoder.start(self._finished, vec_env.learned_evader)
        self._rate = StepRate(self._steps)

    def record_step(self, actions: np.ndarray, step: VecStep) -> None:
        """Record one vector step: the pursuers' ``actions`` ``(B, N)`` (``(B, N, 2)``
        commands) as passed to ``vec_env.step`` and the :class:`VecStep` it returned, which
        holds the evader's actions, learned or scripted. A failed write raises an
        ``OSError`` naming the log's file."""
        rows = self._rows
        if rows is None or self._file.closed:
            raise RuntimeError("EpisodeRecorder.record_step before start() or after close()")
        try:  # a failed write (full disk) names the log's file
            if rows.full:  # write the queue, then drop the rows no running episode needs
                self._encode_pending()
                rows.compact()
            rows.add(actions, step)
            self._steps += 1
            self._finished += len(step.episodes)
            if self._file.due:
                self.flush()
        except OSError as err:
            raise self._file.named(err) from None

    def record_update(self, update: int, metrics: dict[str, Any]) -> None:
        """Log one learner update's ``metrics`` (``policy_loss``, ``entropy``, …) at the
        current time with the counters ``update``, ``env_steps`` and ``episodes``, and
        ``steps_per_s`` (since the previous update) unless given; keys may vary (sparse
        ones, :data:`.schemas.SPARSE_METRICS`, are logged where given)."""
        if self._file.closed:
            raise RuntimeError("EpisodeRecorder.record_update after close()")
        if self._rows is not None:
            self._rows.mark()  # an update's end: where a checkpoint (or a rewind) stands
        b = self._vec.num_envs if self._vec is not None else 0
        rate = self._rate.measure(self._steps, b) if self._vec is not None else None
        msgs = update_messages(update, metrics, self._steps * b, self._finished, rate)
        try:
            for topic, data in msgs[: 2 if self.plot_every else 1]:
                self._write(self._file.channels[topic], self._steps * self._step_ns, data)
        except OSError as err:
            raise self._file.named(err) from None
        if self._file.due:
            self.flush()

    def flush(self, durable: bool = False) -> None:
        """Write the finished episodes and close the chunk (a killed process cannot lose
        them); ``durable``: also ``fsync`` (the trainer's before each checkpoint)."""
        try:
            self._encode_pending()
            self._file.close_chunk(durable)
        except OSError as err:
            raise self._file.named(err) from None

    def close(self) -> None:
        """Write the remaining finished episodes, the MCAP summary and footer; idempotent."""
        if self._file.closed:
            return
        try:
            self._encode_pending(final=True)
            self._file.finish()
        except OSError as err:
            self._file.abandon()
            raise self._file.named(err) from None
        self._file.close()

    def abandon(self) -> None:
        """Close the file as it is, writing nothing more (after a failed write)."""
        self._file.abandon()

    def __enter__(self) -> EpisodeRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open_episodes(self) -> dict | None:
        """The episodes running at the last update's end, for a checkpoint (``None`` before
        :meth:`start`; see :mod:`.episode_rows`)."""
        return None if self._rows is None else self._rows.open_episodes()

    @property
    def episodes(self) -> int:
        """Episodes finished so far (including those of the log a resumed run follows)."""
        return self._finished

    def _write(self, channel: int, log_time: int, data: bytes) -> None:
        """Add one message: every write of the log goes through here."""
        self._file.add(channel, log_time, data)

    def _encode_pending(self, final: bool = False) -> None:
        """Write the queued episodes' messages (and with ``final``, the open curve point)."""
        finished = self._rows.take() if self._rows is not None else []
        channels = self._file.channels
        if finished:
            buf, base = self._rows.buf, self._rows.base
            for topic, log_time, data in self._encoder.messages(finished, buf, base):
                self._write(channels[topic], log_time, data)
        for topic, log_time, data in self._encoder.finish() if final else ():
            self._write(channels[topic], log_time, data)
        self._file.close_chunk_if_full()
