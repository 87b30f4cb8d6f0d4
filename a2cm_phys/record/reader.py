"""Read a run log ``episodes.mcap``, cleanly closed or cut short by a crash.

The file is read in one pass with the ``mcap`` library's :class:`~mcap.stream_reader.StreamReader`
(CRCs checked), which needs no summary section. A run killed mid-write leaves a file that
ends in a partial record: reading stops there, everything in the complete chunks before it
is kept, and :attr:`~.runlog.RunLog.clean` is ``False``. The writer puts every message of an episode
in one chunk, so an episode is either recovered whole or not at all. Logs of every format
version up to :data:`~.schemas.FORMAT_VERSION` are read (see :mod:`.schemas`); a newer one
is a :class:`~.runlog.LogError`. What a log holds once read (:class:`~.runlog.RunLog`,
:class:`~.runlog.Trajectory`) is described in :mod:`.runlog`.
"""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Footer, Message, Metadata
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC

from .runlog import SUMMARY_FIELDS, LogError, RunLog
from .schemas import (
    FORMAT_VERSION,
    METADATA_NAME,
    SCENE_TOPIC_PREFIX,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    UPDATE_TOPIC,
)

# The log's data model lives in .runlog; it is also read from here, where it always was.
__all__ = ["read_file", "scene_topics"]


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
