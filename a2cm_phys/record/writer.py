"""``EpisodeRecorder``: the trainer's run log ``RUN_DIR/episodes.mcap`` (zstd chunks).

Cheap by construction, because a grid step costs only a few microseconds per game:

- each vector step is copied into time-major numpy buffers, one slice assignment per field
  whatever the number of games; a finished episode only queues ``(summary, first row)``;
- the queue is encoded in *blocks* — when the buffer is full, at each flush and at close —
  with one gather per field and a vectorised JSON text encoder (no per-episode or per-step
  Python work), as one trajectory message and one summary message per block (columnar:
  arrays over the block's episodes; :mod:`.reader` splits them again);
- a block's messages go into one chunk, and a chunk is closed at least every
  ``flush_seconds`` and whenever it holds ``chunk_bytes``, so a killed run loses only the
  last few seconds and never half an episode.

Topics, schemas and the time base are described in :mod:`.schemas`.
"""

from __future__ import annotations

import datetime
import json
import math
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer

from ..config import Scenario, to_dict
from ..envs.vector import EpisodeSummary, VecStep, VectorEnv
from .reader import Trajectory
from .scene import episode_scenes
from .schemas import (
    FORMAT,
    METADATA_NAME,
    SCENE_SCHEMA,
    SCHEMAS,
    STEP_SECONDS,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    UPDATE_TOPIC,
    scene_topic,
    schema_bytes,
)

_NS = 1_000_000_000


def _num(x: float) -> str:
    """A JSON number (exact: Python's shortest round-trip repr), ``null`` if not finite."""
    x = float(x)
    return repr(x) if math.isfinite(x) else "null"


def _chars(x: np.ndarray) -> np.ndarray | None:
    """Each value of ``x`` ``(T, K)`` as a right-aligned fixed-width JSON token ``(T, K, w)``
    of ASCII codes, built in numpy; ``None`` if that is not possible (physics floats)."""
    if x.dtype.kind == "f" and np.all(np.abs(x) < 2**53) and np.all(x == np.floor(x)):
        x = x.astype(np.int64)  # integral floats (times, most rewards) print as integers
    if x.dtype.kind in "iu":
        lo, hi = int(x.min()), int(x.max())
        if lo >= 0 and hi <= 9:  # one digit: the common case on the grid
            return (x.astype(np.uint8) + 48)[..., None]
        if lo >= 0 and hi > 1024:
            width = len(str(hi))
            powers = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
            digits = x.astype(np.int64)[..., None] // powers
            chars = (digits % 10 + 48).astype(np.uint8)
            chars[(digits == 0) & (powers > 1)] = 32  # leading zeros -> spaces
            return chars
    if x.dtype == bool:
        tokens, index = ["false", "true"], x.view(np.uint8)
    elif x.dtype.kind in "iu" and hi - lo <= 1024:
        tokens, index = [str(v) for v in range(lo, hi + 1)], x - lo
    else:
        uniq, index = np.unique(x, return_inverse=True)
        if len(uniq) > 1024:
            return None
        fmt = _num if x.dtype.kind == "f" else str
        tokens, index = [fmt(u) for u in uniq.tolist()], index.reshape(x.shape)
    width = max(map(len, tokens))
    table = np.frombuffer("".join(t.rjust(width) for t in tokens).encode(), dtype=np.uint8)
    return table.reshape(len(tokens), width)[index]


def _text(x: np.ndarray, sep: bytes, nested: bool) -> bytes:
    """JSON text of the rows of ``x`` ``(T, K)``: values joined by commas, rows by ``sep``,
    in brackets (``[[…],[…]]`` if ``nested``, else ``[…]``).

    Numpy writes the text when it can (every grid field, times, rewards, flags): each token
    padded with spaces (valid JSON) to one width, so there is no per-value Python work.
    Otherwise (physics floats) it is ``json.dumps``; exact either way.
    """
    chars = _chars(x)
    if chars is None:
        return json.dumps((x if nested else x[:, 0]).tolist(), separators=(",", ":")).encode()
    rows, cols, width = chars.shape
    cell = cols * (width + 1)
    out = np.empty((rows, cell - 1 + len(sep)), dtype=np.uint8)
    view = out[:, :cell].reshape(rows, cols, width + 1)
    view[:, :, :width] = chars
    view[:, :, width] = ord(",")
    out[:, cell - 1 :] = np.frombuffer(sep, dtype=np.uint8)
    body = memoryview(out.reshape(-1))[: -len(sep)]
    return b"".join((b"[[" if nested else b"[", body, b"]]" if nested else b"]"))


def json_array(values: np.ndarray) -> bytes:
    """A 1-D array as JSON text (uint64 as decimal strings: exact in any JSON reader)."""
    if len(values) == 0:
        return b"[]"
    if values.dtype == np.uint64:
        return json.dumps([str(v) for v in values.tolist()], separators=(",", ":")).encode()
    return _text(values.reshape(-1, 1), b",", nested=False)


def json_rows(matrix: np.ndarray) -> bytes:
    """A 2-D array as JSON text: an array of rows."""
    if len(matrix) == 0:
        return b"[]"
    return _text(matrix, b"],[", nested=True)


def _object(**fields: bytes) -> bytes:
    """A JSON object from already-encoded JSON values, in the given key order."""
    return b"{" + b",".join(b'"%s":%s' % (k.encode(), v) for k, v in fields.items()) + b"}"


def _json_value(value: Any) -> Any:
    """A metric as a JSON value: numpy/torch scalars unwrapped, non-finite floats as null."""
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    value = float(value)
    return value if math.isfinite(value) else None


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(s, s + n)`` for each start ``s`` and length ``n``."""
    offsets = np.cumsum(lengths) - lengths
    return np.arange(int(lengths.sum())) - np.repeat(offsets - starts, lengths)


class EpisodeRecorder:
    """Write a run's episodes, updates and scenes to an MCAP file (see the module docs).

    Use: ``rec = EpisodeRecorder(run_dir / "episodes.mcap", scenario, {"train": to_dict(cfg)})``;
    ``rec.start(vec_env)`` after ``vec_env.reset(seed)``; ``rec.record_step(actions, step)``
    after each ``vec_env.step(actions)``; ``rec.record_update(update, metrics)`` after each
    learner update; ``rec.close()`` at the end (or use ``with``). ``log_every = k`` logs the
    trajectory of every k-th episode (0: none); summaries are always logged.
    ``scene_every = k`` draws every k-th episode as ``foxglove.SceneUpdate`` frames (0: none).
    ``metadata`` (JSON-able values) is stored with the scenario, package version and command
    line; put the training config under ``"train"``. Episodes still running at ``close``
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
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        from .. import __version__

        self._writer = Writer(self._fh, chunk_size=1 << 62, compression=CompressionType.ZSTD)
        self._writer.start(library=f"a2cm_phys {__version__}")
        self._writer.add_metadata(METADATA_NAME, self._metadata(dict(metadata or {}), __version__))
        self._fh.flush()
        self._channels = {
            topic: self._writer.register_channel(
                topic,
                "json",
                self._writer.register_schema(schema["title"], "jsonschema", schema_bytes(schema)),
            )
            for topic, schema in SCHEMAS.items()
        }
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
            "step_seconds": STEP_SECONDS,
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
        pos, vel = core.positions(), core.velocities()
        b, agents = vec_env.num_envs, vec_env.n_agents + 1
        # Room for two whole episodes, up to a bound: longer ones grow it (see _make_room),
        # so memory follows the episodes that happen, not max_steps.
        self._cap = min(max(2048, 2 * (self.scenario.max_steps + 2)), 8192)
        shape = (self._cap, b)
        self._pos = np.zeros((*shape, agents, 2), dtype=pos.dtype)
        self._spos = np.zeros_like(self._pos)  # positions after auto-reset (episode starts)
        self._vel = None if vel is None else np.zeros((*shape, agents, 2), dtype=vel.dtype)
        self._svel = None if vel is None else np.zeros_like(self._vel)
        self._act = np.zeros((*shape, agents), dtype=np.int64)
        self._rew = np.zeros(shape, dtype=np.float64)
        self._captured = np.zeros(shape, dtype=bool)
        self._col = np.zeros(shape, dtype=np.int64)
        self._wall = np.zeros(shape, dtype=np.int64)
        self._pos[0] = self._spos[0] = pos
        if vel is not None:
            self._vel[0] = self._svel[0] = vel
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
        """Record one vector step: ``actions`` ``(B, N)`` as passed to ``vec_env.step`` and the
        :class:`VecStep` it returned. (``episode_seeds_before`` is accepted but not needed:
        each finished episode's summary carries its seed.)"""
        if self._vec is None or self._closed:
            raise RuntimeError("EpisodeRecorder.record_step before start() or after close()")
        if self._row + 1 >= self._cap:
            self._make_room()
        r = self._row = self._row + 1
        out = step.outcome
        act = self._act[r]
        act[:, :-1] = actions
        act[:, -1] = out.evader_action
        self._pos[r] = step.positions
        self._rew[r] = out.reward
        self._captured[r] = out.captured
        self._col[r] = out.collisions
        self._wall[r] = out.wall_contacts
        if self._vel is not None:
            self._vel[r] = step.velocities
        if out.events is not None:
            for i, events in enumerate(out.events):
                if events:
                    self._events[i].extend(events)
        self._steps += 1
        if step.episodes:
            core = self._vec.core
            self._spos[r] = core.positions()
            if self._svel is not None:
                self._svel[r] = core.velocities()
            begin, pending, events = self._begin, self._pending, self._events
            physics = self._vel is not None
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

    def record_update(self, update: int, metrics: dict[str, Any]) -> None:
        """Log one learner update's ``metrics`` (e.g. ``policy_loss``, ``value_loss``,
        ``entropy``, ``mean_advantage``, ``grad_norm``, ``steps_per_s``) at the current time,
        with the counters ``update``, ``env_steps`` and ``episodes``; ``steps_per_s`` (wall
        clock, since the previous update) is added unless ``metrics`` has it."""
        if self._closed:
            raise RuntimeError("EpisodeRecorder.record_update after close()")
        b = self._vec.num_envs if self._vec is not None else 0
        doc = {k: _json_value(v) for k, v in metrics.items()}
        if self._vec is not None:
            now, (then, steps) = time.perf_counter(), self._rate_mark
            if "steps_per_s" not in doc and now > then:
                doc["steps_per_s"] = (self._steps - steps) * b / (now - then)
            self._rate_mark = (now, self._steps)
        doc.update(update=int(update), env_steps=self._steps * b, episodes=self._finished)
        self._write(
            self._channels[UPDATE_TOPIC],
            self._steps * _NS,
            json.dumps(doc, separators=(",", ":")).encode(),
        )
        if time.monotonic() >= self._deadline:
            self.flush()

    def flush(self) -> None:
        """Write the finished episodes and close the chunk, so a crash cannot lose them."""
        self._encode_pending()
        self._writer.flush()
        self._unflushed = 0
        self._deadline = time.monotonic() + self.flush_seconds

    def close(self) -> None:
        """Write the remaining finished episodes, the MCAP summary and footer; idempotent."""
        if self._closed:
            return
        self._encode_pending()
        self._writer.finish()
        self._fh.close()
        self._closed = True

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
        keep = self._row + 1 - first
        names = ("_pos", "_spos", "_vel", "_svel", "_act", "_rew", "_captured", "_col", "_wall")
        for name in names:
            a = getattr(self, name)
            if a is not None:
                a[:keep] = a[first : self._row + 1]
        self._begin = [b - first for b in self._begin]
        self._row -= first
        self._base += first
        if self._row + 1 >= self._cap:  # an episode longer than the buffer: grow it
            for name in names:
                a = getattr(self, name)
                if a is not None:
                    setattr(self, name, np.concatenate([a, np.zeros_like(a)]))
            self._cap *= 2

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
        t0, t1 = (self._base + end - length) * STEP_SECONDS, (self._base + end) * STEP_SECONDS
        log_time = int(end.max() + self._base) * _NS
        logged = whole & (ids % max(self.log_every, 1) == 0) & (self.log_every > 0)
        if logged.any():
            sel = np.flatnonzero(logged)
            events = [pending[i][3] for i in sel]
            block = _Block(self, ids[sel], env[sel], seed[sel], begin[sel], length[sel], events)
            self._write(self._channels[TRAJECTORY_TOPIC], log_time, block.json(t0[sel]))
        if self.scene_every:
            for i in np.flatnonzero(whole & (ids % self.scene_every == 0)):
                one = _Block(
                    self,
                    ids[i : i + 1],
                    env[i : i + 1],
                    seed[i : i + 1],
                    begin[i : i + 1],
                    length[i : i + 1],
                    [pending[i][3]],
                )
                self._write_scenes(one.trajectory(float(t0[i])))
        flags = ints[:, 4:7].astype(bool)
        summary = _object(
            episode=json_array(ids),
            env=json_array(env),
            seed=json_array(seed),
            length=json_array(length),
            **{"return": json_array(np.array([e.ret for e in eps], dtype=np.float64))},
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


def _take(buffer: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Rows of a ``(rows, games, …)`` buffer at flat indices ``row · games + game``."""
    return np.take(buffer.reshape(-1, *buffer.shape[2:]), flat, axis=0)


class _Block:
    """Some queued episodes gathered from the recorder's buffers, all fields at once."""

    def __init__(
        self,
        rec: EpisodeRecorder,
        ids: np.ndarray,
        env: np.ndarray,
        seed: np.ndarray,
        begin: np.ndarray,
        length: np.ndarray,
        events: list[list | None],
    ) -> None:
        self.ids, self.env, self.seed, self.length, self.events = ids, env, seed, length, events
        # States: each episode's start (from the reset buffer), then the row after each step.
        games = rec._pos.shape[1]
        rows = _ranges(begin, length + 1)
        flat = rows * games + np.repeat(env, length + 1)
        starts = np.cumsum(length + 1) - (length + 1)
        self.state_offset = rows - np.repeat(begin, length + 1)  # steps since the start
        first = begin * games + env
        self.pos = _take(rec._pos, flat)
        self.pos[starts] = _take(rec._spos, first)
        self.vel = None
        if rec._vel is not None:
            self.vel = _take(rec._vel, flat)
            self.vel[starts] = _take(rec._svel, first)
        flat = _ranges(begin + 1, length) * games + np.repeat(env, length)
        self.act = _take(rec._act, flat)
        self.rew = _take(rec._rew, flat)
        self.captured = _take(rec._captured, flat)
        self.col = _take(rec._col, flat)
        self.wall = _take(rec._wall, flat)

    def json(self, t0: np.ndarray) -> bytes:
        """The ``/episodes/trajectories`` message of these episodes (columnar, see schemas)."""
        n = len(self.pos)
        fields = {
            "episode": json_array(self.ids),
            "env": json_array(self.env),
            "seed": json_array(self.seed),
            "length": json_array(self.length),
            "t0": json_array(t0),
            "dt": _num(STEP_SECONDS).encode(),
            "time": json_array(self.state_offset * STEP_SECONDS),
            "positions": json_rows(self.pos.reshape(n, -1)),
            "actions": json_rows(self.act),
            "reward": json_array(self.rew),
            "captured": json_array(self.captured),
            "collisions": json_array(self.col),
            "wall_contacts": json_array(self.wall),
        }
        if self.vel is not None:
            fields["velocities"] = json_rows(self.vel.reshape(n, -1))
        if any(e is not None for e in self.events):
            fields["events"] = json.dumps(
                [e or [] for e in self.events], separators=(",", ":"), default=_json_value
            ).encode()
        return _object(**fields)

    def trajectory(self, t0: float) -> Trajectory:
        """The first episode of the block as a :class:`Trajectory` (for scene frames)."""
        length = int(self.length[0])
        return Trajectory(
            episode=int(self.ids[0]),
            env=int(self.env[0]),
            seed=int(self.seed[0]),
            t0=t0,
            dt=STEP_SECONDS,
            positions=self.pos[: length + 1],
            actions=self.act[:length],
            reward=self.rew[:length],
            captured=self.captured[:length],
            collisions=self.col[:length],
            wall_contacts=self.wall[:length],
            velocities=None if self.vel is None else self.vel[: length + 1],
            events=None if self.events[0] is None else [tuple(e) for e in self.events[0]],
        )
