"""Read a run log ``episodes.mcap``, cleanly closed or cut short by a crash.

The file is read in one pass with the ``mcap`` library's :class:`~mcap.stream_reader.StreamReader`
(CRCs checked), which needs no summary section. A run killed mid-write leaves a file that
ends in a partial record: reading stops there, everything in the complete chunks before it
is kept, and :attr:`RunLog.clean` is ``False``. The writer puts every message of an episode
in one chunk, so an episode is either recovered whole or not at all. Logs of every format
version up to :data:`~.schemas.FORMAT_VERSION` are read (see :mod:`.schemas`); a newer one
is a :class:`LogError`.
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Footer, Message, Metadata
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC

from ..base.errors import UserError
from ..config import ConfigError, Scenario, build
from .schemas import (
    FORMAT_VERSION,
    METADATA_NAME,
    SCENE_TOPIC_PREFIX,
    SUMMARY_SCHEMA,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    UPDATE_TOPIC,
)


class LogError(UserError):
    """A run log cannot be read (missing, not an MCAP, not ours); the message says why."""


@dataclass
class Trajectory:
    """One episode as logged: ``positions``/``velocities`` have ``length + 1`` rows (row 0
    is the start), the per-step arrays ``length`` rows. Agents: pursuers, then the evader.

    ``actions`` are ``(L, N + 1)`` int64 moves, or with continuous control ``(L, N + 1, 2)``
    float64 commands, exactly as given to the env (before clipping). ``dt`` is the simulated
    seconds per step (the control period). ``evader_reward`` is a learned evader's reward
    per step (``None`` with a scripted evader, or in a log older than format 2)."""

    episode: int
    env: int
    seed: int
    t0: float
    dt: float
    positions: np.ndarray  # (L + 1, N + 1, 2)
    actions: np.ndarray  # (L, N + 1) int64 or (L, N + 1, 2) float64: pursuers, then evader
    reward: np.ndarray  # (L,) float64
    captured: np.ndarray  # (L,) bool
    collisions: np.ndarray  # (L,) int64
    wall_contacts: np.ndarray  # (L,) int64
    velocities: np.ndarray | None = None  # (L + 1, N + 1, 2), physics only
    events: list[tuple[str, str, str, int]] | None = None  # physics only
    evader_reward: np.ndarray | None = None  # (L,) float64, learned evader only

    @property
    def continuous(self) -> bool:
        """Whether the actions are continuous commands (float vectors)."""
        return self.actions.ndim == 3

    @property
    def length(self) -> int:
        """Steps taken."""
        return len(self.reward)

    @staticmethod
    def from_block(doc: dict[str, Any]) -> list[Trajectory]:
        """Split one ``/episodes/trajectories`` message into its episodes."""
        lengths = np.asarray(doc["length"], dtype=np.int64)
        states = np.cumsum(lengths + 1)
        steps = np.cumsum(lengths)
        pos = np.asarray(doc["positions"])
        agents = pos.shape[1] // 2 if pos.ndim == 2 else 0
        pos = pos.reshape(len(pos), agents, 2)
        vel = doc.get("velocities")
        vel = None if vel is None else np.asarray(vel, dtype=np.float64).reshape(pos.shape)
        act = _actions(doc["actions"], agents)
        evader_reward = doc.get("evader_reward")
        if evader_reward is not None:
            evader_reward = np.asarray(evader_reward, dtype=np.float64)
        reward = np.asarray(doc["reward"], dtype=np.float64)
        captured = np.asarray(doc["captured"], dtype=bool)
        collisions = np.asarray(doc["collisions"], dtype=np.int64)
        walls = np.asarray(doc["wall_contacts"], dtype=np.int64)
        events = doc.get("events")
        out = []
        for j, length in enumerate(lengths.tolist()):
            a, b = states[j] - length - 1, states[j]
            c, d = steps[j] - length, steps[j]
            out.append(
                Trajectory(
                    episode=int(doc["episode"][j]),
                    env=int(doc["env"][j]),
                    seed=int(doc["seed"][j]),
                    t0=float(doc["t0"][j]),
                    dt=float(doc["dt"]),
                    positions=pos[a:b],
                    actions=act[c:d],
                    reward=reward[c:d],
                    captured=captured[c:d],
                    collisions=collisions[c:d],
                    wall_contacts=walls[c:d],
                    velocities=None if vel is None else vel[a:b],
                    events=None if events is None else [tuple(e) for e in events[j]],
                    evader_reward=None if evader_reward is None else evader_reward[c:d],
                )
            )
        return out


def _actions(rows: list[list[Any]], agents: int) -> np.ndarray:
    """The ``actions`` rows of a block: ``agents`` moves a row (int64), or ``2 · agents``
    command components a row (float64 ``(steps, agents, 2)``; ``null`` reads as NaN)."""
    width = len(rows[0]) if rows else agents
    if width == 2 * agents:
        return np.asarray(rows, dtype=np.float64).reshape(-1, agents, 2)
    return np.asarray(rows, dtype=np.int64).reshape(-1, agents)


SUMMARY_FIELDS = tuple(k for k in SUMMARY_SCHEMA["required"] if k != "seed")
"""Columns of :attr:`RunLog.episodes` besides ``seed`` (plus ``evader_return`` in logs of
learned-evader runs)."""


@dataclass
class RunLog:
    """Everything read from one run log.

    ``episodes`` holds the summaries column-wise (numpy arrays keyed by
    :data:`SUMMARY_FIELDS` and ``seed``, and ``evader_return`` if the log has it), in
    episode order. ``updates`` is the list of update
    messages. ``metadata`` the run's metadata (values decoded from JSON).
    """

    path: Path
    metadata: dict[str, Any]
    episodes: dict[str, np.ndarray]
    updates: list[dict[str, Any]]
    clean: bool
    error: str | None = None
    damaged: bool = False  # closed cleanly, but a record fails its checks (not a crash)
    parts: list[Path] = field(default_factory=list)  # the files read (a run folder: all parts)
    topic_counts: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)  # parts unreadable, damaged or missing
    _blocks: list[bytes] = field(default_factory=list, repr=False)
    _where: dict[int, int] = field(default_factory=dict, repr=False)
    _cache: tuple[int, dict[int, Trajectory]] | None = field(default=None, repr=False)

    @property
    def n_episodes(self) -> int:
        """Episodes recovered (one summary each)."""
        return len(self.episodes["episode"])

    @property
    def scenario(self) -> Scenario:
        """The run's resolved scenario, rebuilt from the metadata (validated)."""
        data = self.metadata.get("scenario")
        if not isinstance(data, dict):
            raise LogError(f"{self.path}: the metadata holds no scenario")
        try:
            return build(Scenario, data, f"{self.path} metadata")
        except ConfigError as err:
            raise LogError(str(err)) from None

    @property
    def label(self) -> str:
        """A short name for plots: metadata ``label``, else the algorithm, else the file."""
        train = self.metadata.get("train")
        algo = self.metadata.get("algo") or (train.get("algo") if isinstance(train, dict) else None)
        return str(self.metadata.get("label") or (algo.upper() if algo else self.path.parent.name))

    @property
    def logged_episodes(self) -> list[int]:
        """Ids of the episodes whose trajectory is in the log, ascending."""
        return sorted(self._where)

    def trajectory(self, episode: int) -> Trajectory:
        """The logged trajectory of ``episode``; ``KeyError`` if it is not in the log."""
        block = self._where[episode]
        if self._cache is None or self._cache[0] != block:
            trajs = Trajectory.from_block(json.loads(self._blocks[block]))
            self._cache = (block, {t.episode: t for t in trajs})
        return self._cache[1][episode]

    def trajectories(self) -> Iterator[Trajectory]:
        """Every logged trajectory of the run once, in the order they were written (in a run
        of several parts, not those a later part superseded)."""
        for block, data in enumerate(self._blocks):
            for traj in Trajectory.from_block(json.loads(data)):
                if self._where.get(traj.episode) == block:
                    yield traj


def _decode_metadata(data: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in data.items():
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


_TRUNCATION_ERRORS = (McapError, struct.error, ValueError, zstandard.ZstdError, EOFError)


class _Collector:
    """What :func:`read_file` gathers from a log's records."""

    def __init__(self) -> None:
        self.metadata: dict[str, Any] = {}
        self.summaries: list[dict[str, Any]] = []
        self.updates: list[dict[str, Any]] = []
        self.blocks: list[bytes] = []
        self.where: dict[int, int] = {}
        self.counts: dict[str, int] = {}
        self.topics: dict[int, str] = {}
        self.footer = False
        self.repeated: list[int] = []  # episodes whose trajectory came twice

    def take(self, record: Any) -> None:
        if isinstance(record, Message):
            topic = self.topics[record.channel_id]
            self.counts[topic] = self.counts.get(topic, 0) + 1
            if topic == SUMMARY_TOPIC:
                self.summaries.append(json.loads(record.data))
            elif topic == TRAJECTORY_TOPIC:
                for episode in _episode_ids(record.data):
                    if episode in self.where:
                        self.repeated.append(episode)
                    self.where[episode] = len(self.blocks)
                self.blocks.append(record.data)
            elif topic == UPDATE_TOPIC:
                self.updates.append(json.loads(record.data))
        elif isinstance(record, Channel):
            self.topics[record.id] = record.topic
        elif isinstance(record, Metadata) and record.name == METADATA_NAME:
            self.metadata = _decode_metadata(record.metadata)
        elif isinstance(record, Footer):
            self.footer = True


def read_file(path: str | Path) -> RunLog:
    """Read one log file (see :func:`.parts.read_run`)."""
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: no such file")
    got = _Collector()
    error, damaged = None, False
    with open(path, "rb") as fh:
        try:
            for record in StreamReader(fh, validate_crcs=True).records:
                got.take(record)
        except InvalidMagic:
            raise LogError(f"{path}: not an MCAP file") from None
        except _TRUNCATION_ERRORS as err:
            if not got.topics and not got.metadata:
                raise LogError(
                    f"{path}: not an MCAP run log, or cut before its metadata ({_describe(err)})"
                ) from None
            error = f"{_describe(err)} near byte {fh.tell():,}"
            got.footer = False  # a footer without the closing magic is not a clean end
            damaged = _ends_with_magic(fh)
            if damaged:  # closed cleanly: its index lets us read around the damage
                error, got = _read_around_damage(fh, got, error)
    if not got.metadata:
        raise LogError(f"{path}: not an a2cm_phys run log (no '{METADATA_NAME}' metadata)")
    _check_format(path, got.metadata.get("format"))
    return RunLog(
        path=path,
        metadata=got.metadata,
        episodes=_columns(got.summaries),
        updates=got.updates,
        clean=got.footer and not damaged,
        error=error,
        damaged=damaged,
        parts=[path],
        topic_counts=got.counts,
        problems=[f"{path.name}: episode {e}'s trajectory is logged twice" for e in got.repeated],
        _blocks=got.blocks,
        _where=got.where,
    )


def _read_around_damage(fh: Any, first: _Collector, error: str) -> tuple[str, _Collector]:
    """Read a damaged but closed file chunk by chunk through its summary's chunk index,
    skipping the chunks that fail their checks; ``(error, collector)``, or the first
    reading's if the index itself is unreadable."""
    try:
        fh.seek(0)  # the reader takes the current position as the file's start
        summary = SeekingReader(fh, validate_crcs=True).get_summary()
    except _TRUNCATION_ERRORS:
        return error, first
    if summary is None or not summary.chunk_indexes:
        return error, first
    got = _Collector()
    got.metadata, got.topics = first.metadata, {c.id: c.topic for c in summary.channels.values()}
    bad = []
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        fh.seek(index.chunk_start_offset)
        data = fh.read(index.chunk_length)
        chunk = _Collector()
        chunk.topics = got.topics
        try:
            for record in StreamReader(
                io.BytesIO(data), skip_magic=True, validate_crcs=True
            ).records:
                chunk.take(record)
        except EndOfFile:  # the chunk was read whole; nothing follows it in this buffer
            pass
        except _TRUNCATION_ERRORS:
            bad.append(index.chunk_start_offset)
            continue
        for block in chunk.blocks:  # keep block numbers global
            for episode in _episode_ids(block):
                got.where[episode] = len(got.blocks)
            got.blocks.append(block)
        got.summaries += chunk.summaries
        got.updates += chunk.updates
        for topic, n in chunk.counts.items():
            got.counts[topic] = got.counts.get(topic, 0) + n
    if not bad:
        return f"damage outside the chunks, all {len(summary.chunk_indexes)} read: {error}", got
    where = ", ".join(f"byte {b:,}" for b in bad[:3]) + (" …" if len(bad) > 3 else "")
    return f"{len(bad)} damaged chunk(s) skipped (at {where}): {error}", got


def _ends_with_magic(fh: Any) -> bool:
    """Whether the file ends as a closed MCAP file does: then a read error is damage."""
    fh.seek(0, 2)
    if fh.tell() < 2 * len(MCAP0_MAGIC):
        return False
    fh.seek(-len(MCAP0_MAGIC), 2)
    return fh.read() == MCAP0_MAGIC


def _episode_ids(data: bytes) -> list[int]:
    """The ``episode`` array of a trajectory block, read without decoding the whole block."""
    prefix = b'{"episode":'
    if data.startswith(prefix):
        return json.loads(data[len(prefix) : data.index(b"]") + 1])
    return json.loads(data)["episode"]


def _check_format(path: Path, tag: object) -> None:
    """A :class:`LogError` if the log was written in a newer format than this package reads."""
    if not isinstance(tag, str) or "/" not in tag:
        return
    version = tag.rsplit("/", 1)[1]
    if version.isdigit() and int(version) > FORMAT_VERSION:
        raise LogError(
            f"{path}: log format {tag} is newer than this a2cm_phys reads "
            f"(up to version {FORMAT_VERSION}); upgrade a2cm_phys"
        )


def _describe(err: BaseException) -> str:
    name = type(err).__name__
    text = str(err)
    return f"{name}: {text}" if text else name


def _columns(blocks: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    dtypes = {
        "return": np.float64,
        "t0": np.float64,
        "t1": np.float64,
        "captured": bool,
        "truncated": bool,
        "collision_terminated": bool,
        "logged": bool,
    }
    cols = {
        k: np.array([v for b in blocks for v in b[k]], dtype=dtypes.get(k, np.int64))
        for k in SUMMARY_FIELDS
    }
    cols["seed"] = np.array([int(v) for b in blocks for v in b["seed"]], dtype=np.uint64)
    if blocks and all("evader_return" in b for b in blocks):
        cols["evader_return"] = np.array(
            [v for b in blocks for v in b["evader_return"]], dtype=np.float64
        )
    return cols


def scene_topics(log: RunLog) -> list[str]:
    """The SceneUpdate topics present in ``log``."""
    return sorted(t for t in log.topic_counts if t.startswith(SCENE_TOPIC_PREFIX))
