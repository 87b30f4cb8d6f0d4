"""``EpisodeRecorder``: the trainer's run log ``RUN_DIR/episodes.mcap`` (zstd chunks).

Cheap by construction, because a grid step costs only a few microseconds per game:

- each vector step is copied into time-major numpy buffers (:mod:`.buffers`), one slice
  assignment per field whatever the number of games; a finished episode only queues
  ``(summary, first row)``;
- the queue is encoded in *blocks* — when the buffer is full, at each flush and at close —
  with one gather per field (:mod:`.block`) and a vectorised JSON text encoder
  (:mod:`.jsontext`: no per-episode or per-step Python work on the grid), as one trajectory
  message and one summary message per block (columnar: arrays over the block's episodes;
  :mod:`.reader` splits them again);
- a block's messages go into one chunk, and a chunk is closed at least every
  ``flush_seconds`` and whenever it holds ``chunk_bytes``, so a killed run loses only the
  last few seconds and never half an episode.

Topics, schemas and the time base are described in :mod:`.schemas`.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import json
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer

from ..base.versions import __version__
from ..config import Scenario, to_dict
from ..envs.vector import EpisodeSummary, VecStep, VectorEnv
from .block import Block
from .buffers import StepBuffers
from .jsontext import json_array, json_object, json_value
from .reader import Trajectory
from .scene import episode_scenes
from .schemas import (
    FORMAT,
    METADATA_NAME,
    SCENE_SCHEMA,
    SCHEMAS,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    UPDATE_TOPIC,
    scene_topic,
    schema_bytes,
    step_seconds,
)

_NS = 1_000_000_000


class EpisodeRecorder:
    """Write a run's episodes, updates and scenes to an MCAP file (see the module docs).

    Use: ``rec = EpisodeRecorder(run_dir / "episodes.mcap", scenario, {"train": to_dict(cfg)})``;
    ``rec.start(vec_env)`` after ``vec_env.reset(seed)``; ``rec.record_step(actions, step)``
    after each ``vec_env.step(actions)``; ``rec.record_update(update, metrics)`` after each
    learner update; ``rec.close()`` at the end (or use ``with``). ``log_every = k`` logs the
    trajectory of every k-th episode (0: none); summaries are always logged.
    ``scene_every = k`` draws every k-th episode as ``foxglove.SceneUpdate`` frames (0: none).
    ``metadata`` (JSON-able values) is stored with the scenario, package version and command
    line; put the training config under ``"train"``. Actions are logged as given: moves, or
    continuous commands exactly (see :mod:`.schemas`); with a learned evader its actions
    (from ``step.outcome``) and its rewards and returns too. Episodes still running at ``close``
    are not logged. A resumed run passes ``start(…, step=…, episode=…)`` to continue the
    clocks of the log it follows.
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
    ) -> None:
        if log_every < 0 or scene_every < 0:
            raise ValueError("log_every and scene_every must be >= 0")
        self.path = Path(path)
        self.scenario = scenario
        self.log_every, self.scene_every = log_every, scene_every
        self.flush_seconds, self.chunk_bytes = flush_seconds, chunk_bytes
        self.dt = step_seconds(scenario)
        self._step_ns = round(self.dt * _NS)  # the clock in integer nanoseconds: exact
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        try:
            self._writer = Writer(self._fh, chunk_size=1 << 62, compression=CompressionType.ZSTD)
            self._writer.start(library=f"a2cm_phys {__version__}")
            meta = self._metadata(dict(metadata or {}), __version__)
            self._writer.add_metadata(METADATA_NAME, meta)
            self._channels = {
                topic: self._writer.register_channel(
                    topic,
                    "json",
                    self._writer.register_schema(
                        schema["title"], "jsonschema", schema_bytes(schema)
                    ),
                )
                for topic, schema in SCHEMAS.items()
            }
            self._durable()
        except OSError as err:  # e.g. a full disk: leave no unreadable part behind
            self._fh.close()
            self.path.unlink(missing_ok=True)
            raise self._named(err) from None
        self._scene_schema = 0
        self._scene_channels: dict[int, int] = {}
        self._vec: VectorEnv | None = None
        # (summary, first buffer row, last buffer row, contact events, whole trajectory?)
        self._pending: list[tuple[EpisodeSummary, int, int, list | None, bool]] = []
        self._finished = 0  # episodes queued so far (ids are given in finishing order)
        self._encoded = 0  # episodes written so far
        self._steps = 0  # vector steps so far: the log's clock
        self._unflushed = 0
        self._deadline = time.monotonic() + flush_seconds
        self._closed = False

    def _metadata(self, user: dict[str, Any], version: str) -> dict[str, str]:
        train = user.get("train") if isinstance(user.get("train"), dict) else {}
        meta: dict[str, Any] = {
            "command": shlex.join(getattr(sys, "orig_argv", sys.argv)),
            "seed": train.get("seed"),
            "algo": train.get("algo"),
            **user,
            "format": FORMAT,
            "scenario": to_dict(self.scenario),
            "version": version,
            "log_every": self.log_every,
            "scene_every": self.scene_every,
            "step_seconds": self.dt,
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "time_base": "log_time = run simulated time: vector step k at k * step_seconds",
        }
        return {k: json.dumps(v, default=str) for k, v in meta.items() if v is not None}

    # ------------------------------------------------------------------ recording

    def start(
        self, vec_env: VectorEnv, obs: np.ndarray | None = None, step: int = 0, episode: int = 0
    ) -> None:
        """Begin recording ``vec_env`` right after its ``reset`` (``obs`` is not needed).

        ``step`` (vector steps) and ``episode`` (episodes finished) start the log's clock
        and episode ids where a resumed run's previous log stopped; 0 for a new run.
        """
        self._vec = vec_env
        self._steps, self._finished = int(step), int(episode)
        self._encoded = self._finished
        core = vec_env.core
        b = vec_env.num_envs
        # Room for two whole episodes, up to a bound: longer ones grow it (see _make_room),
        # so memory follows the episodes that happen, not max_steps.
        self._buf = StepBuffers(vec_env, min(max(2048, 2 * (self.scenario.max_steps + 2)), 8192))
        self._learned = vec_env.learned_evader
        self._events: list[list] = [[] for _ in range(b)]
        self._begin = [0] * b  # buffer row of each game's episode start
        # Games already inside an episode (a resumed run): their first steps are not ours to
        # log, so those episodes get a summary but no trajectory.
        self._partial = {int(i) for i in np.flatnonzero(np.asarray(getattr(core, "t", 0)) > 0)}
        self._row = 0  # last buffer row written
        self._base = self._steps  # log clock (vector steps) of buffer row 0
        self._rate_mark = (time.perf_counter(), self._steps)  # for steps_per_s

    def record_step(
        self, actions: np.ndarray, step: VecStep, episode_seeds_before: np.ndarray | None = None
    ) -> None:
        """Record one vector step: the pursuers' ``actions`` ``(B, N)`` (``(B, N, 2)``
        commands) as passed to ``vec_env.step`` and the :class:`VecStep` it returned, which
        holds the evader's actions, learned or scripted. (``episode_seeds_before`` is
        accepted but not needed: each finished episode's summary carries its seed.) A failed
        write raises an ``OSError`` naming the log's file."""
        if self._vec is None or self._closed:
            raise RuntimeError("EpisodeRecorder.record_step before start() or after close()")
        try:  # a failed write (full disk) names the log's file
            buf = self._buf
            if self._row + 1 >= buf.rows:
                self._make_room()
            r = self._row = self._row + 1
            buf.write(r, actions, step)
            out = step.outcome
            if out.events is not None:
                for i, events in enumerate(out.events):
                    if events:
                        self._events[i].extend(events)
            self._steps += 1
            if step.episodes:
                buf.write_starts(r, self._vec)
                begin, pending, events = self._begin, self._pending, self._events
                physics = buf.vel is not None
                for e in step.episodes:
                    ev = None
                    if physics or events[e.env]:
                        ev, events[e.env] = events[e.env], []
                    whole = e.env not in self._partial
                    self._partial.discard(e.env)
                    pending.append((e, begin[e.env], r, ev, whole))
                    begin[e.env] = r
                self._finished += len(step.episodes)
            if time.monotonic() >= self._deadline:
                self.flush()
        except OSError as err:
            raise self._named(err) from None

    def record_update(self, update: int, metrics: dict[str, Any]) -> None:
        """Log one learner update's ``metrics`` (e.g. ``policy_loss``, ``value_loss``,
        ``entropy``, ``mean_advantage``, ``grad_norm``, ``steps_per_s``) at the current time,
        with the counters ``update``, ``env_steps`` and ``episodes``; ``steps_per_s`` (wall
        clock, since the previous update) is added unless ``metrics`` has it. Keys may vary
        from update to update: a metric computed every K updates only (such as
        ``exploit_worst_case``, see :data:`.schemas.SPARSE_METRICS`) is logged where given."""
        if self._closed:
            raise RuntimeError("EpisodeRecorder.record_update after close()")
        b = self._vec.num_envs if self._vec is not None else 0
        doc = {k: json_value(v) for k, v in metrics.items()}
        if self._vec is not None:
            now, (then, steps) = time.perf_counter(), self._rate_mark
            if "steps_per_s" not in doc and now > then:
                doc["steps_per_s"] = (self._steps - steps) * b / (now - then)
            self._rate_mark = (now, self._steps)
        doc.update(update=int(update), env_steps=self._steps * b, episodes=self._finished)
        try:
            self._write(
                self._channels[UPDATE_TOPIC],
                self._steps * self._step_ns,
                json.dumps(doc, separators=(",", ":")).encode(),
            )
        except OSError as err:
            raise self._named(err) from None
        if time.monotonic() >= self._deadline:
            self.flush()

    def flush(self, durable: bool = False) -> None:
        """Write the finished episodes and close the chunk, so that a killed process cannot
        lose them; with ``durable``, also ``fsync`` the file, so that a crash of the machine
        cannot either (the trainer does this before each checkpoint)."""
        try:
            self._encode_pending()
            self._writer.flush()
            if durable:
                self._durable()
        except OSError as err:
            raise self._named(err) from None
        self._unflushed = 0
        self._deadline = time.monotonic() + self.flush_seconds

    def close(self) -> None:
        """Write the remaining finished episodes, the MCAP summary and footer; idempotent."""
        if self._closed:
            return
        try:
            self._encode_pending()
            self._writer.finish()
            self._durable()
        except OSError as err:
            self.abandon()
            raise self._named(err) from None
        self._fh.close()
        self._closed = True

    def abandon(self) -> None:
        """Close the file as it is, without writing anything more (after a failed write:
        readers take every complete chunk before the failure)."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):  # what could not be written is lost; the rest stays
            self._fh.close()

    def _durable(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def _named(self, err: OSError) -> OSError:
        """``err`` with this log's file named (a failed ``write`` names none)."""
        if err.filename is not None:
            return err
        reason = err.strerror or os.strerror(err.errno or errno.EIO)
        return OSError(err.errno, reason, str(self.path))

    def __enter__(self) -> EpisodeRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def episodes(self) -> int:
        """Episodes finished so far (including those of the log a resumed run follows)."""
        return self._finished

    # ------------------------------------------------------------------ encoding

    def _write(self, channel: int, log_time: int, data: bytes) -> None:
        self._writer.add_message(channel, log_time, data, log_time)
        self._unflushed += len(data)

    def _make_room(self) -> None:
        """Write the queue, then drop buffer rows older than every running episode."""
        self._encode_pending()
        first = min(self._begin)
        self._buf.keep(first, self._row)
        self._begin = [b - first for b in self._begin]
        self._row -= first
        self._base += first
        if self._row + 1 >= self._buf.rows:  # an episode longer than the buffer: grow it
            self._buf.grow()

    def _encode_pending(self) -> None:
        """Write the queued episodes as one trajectory block, scenes, one summary block."""
        pending, self._pending = self._pending, []
        if not pending:
            return
        eps = [p[0] for p in pending]
        ints = np.array(
            [
                (
                    e.env,
                    e.length,
                    e.collisions,
                    e.wall_contacts,
                    e.captured,
                    e.truncated,
                    e.collision_terminated,
                    p[1],
                    p[2],
                    p[4],
                )
                for e, p in zip(eps, pending, strict=True)
            ],
            dtype=np.int64,
        ).reshape(-1, 10)
        env, length, begin, end = ints[:, 0], ints[:, 1], ints[:, 7], ints[:, 8]
        whole = ints[:, 9].astype(bool)
        ids = np.arange(self._encoded, self._encoded + len(pending))
        self._encoded += len(pending)
        bad = np.flatnonzero(whole & (end - begin != length))
        if len(bad):
            e = eps[bad[0]]
            raise RuntimeError(
                f"EpisodeRecorder out of sync: env {e.env}: an episode of length {e.length} "
                f"spans {end[bad[0]] - begin[bad[0]]} recorded steps (record_step every step?)"
            )
        seed = np.array([e.seed for e in eps], dtype=np.uint64)
        t0, t1 = (self._base + end - length) * self.dt, (self._base + end) * self.dt
        log_time = int(end.max() + self._base) * self._step_ns
        logged = whole & (ids % max(self.log_every, 1) == 0) & (self.log_every > 0)
        if logged.any():
            sel = np.flatnonzero(logged)
            events = [pending[i][3] for i in sel]
            block = Block(
                self._buf, ids[sel], env[sel], seed[sel], begin[sel], length[sel], events, self.dt
            )
            self._write(self._channels[TRAJECTORY_TOPIC], log_time, block.json(t0[sel]))
        if self.scene_every:
            for i in np.flatnonzero(whole & (ids % self.scene_every == 0)):
                one = Block(
                    self._buf,
                    ids[i : i + 1],
                    env[i : i + 1],
                    seed[i : i + 1],
                    begin[i : i + 1],
                    length[i : i + 1],
                    [pending[i][3]],
                    self.dt,
                )
                self._write_scenes(one.trajectory(float(t0[i])))
        flags = ints[:, 4:7].astype(bool)
        returns = {"return": json_array(np.array([e.ret for e in eps], dtype=np.float64))}
        if self._learned:
            evader = np.array([e.evader_ret for e in eps], dtype=np.float64)
            returns["evader_return"] = json_array(evader)
        summary = json_object(
            episode=json_array(ids),
            env=json_array(env),
            seed=json_array(seed),
            length=json_array(length),
            **returns,
            captured=json_array(flags[:, 0]),
            truncated=json_array(flags[:, 1]),
            collision_terminated=json_array(flags[:, 2]),
            collisions=json_array(ints[:, 2]),
            wall_contacts=json_array(ints[:, 3]),
            t0=json_array(t0),
            t1=json_array(t1),
            logged=json_array(logged),
        )
        self._write(self._channels[SUMMARY_TOPIC], log_time, summary)
        if self._unflushed >= self.chunk_bytes:
            self._writer.flush()
            self._unflushed = 0

    def _write_scenes(self, traj: Trajectory) -> None:
        if traj.env not in self._scene_channels:
            if not self._scene_schema:
                self._scene_schema = self._writer.register_schema(
                    SCENE_SCHEMA["title"], "jsonschema", schema_bytes(SCENE_SCHEMA)
                )
            self._scene_channels[traj.env] = self._writer.register_channel(
                scene_topic(traj.env), "json", self._scene_schema
            )
        channel = self._scene_channels[traj.env]
        for log_time, data in episode_scenes(self.scenario, traj):
            self._write(channel, log_time, data)
