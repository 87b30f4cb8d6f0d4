"""One part of a run log on disk: the MCAP file the recorder writes, in zstd chunks.

A chunk is closed when the recorder asks (each flush) or when it holds ``chunk_bytes``; the
file is ``fsync``'d when it is opened, on a durable flush and when it is finished. A failed
write names the file (a full disk is reported as the log's, not as a nameless ``OSError``),
and a file that cannot even be begun is removed, so no unreadable part is left behind.
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

from mcap.writer import CompressionType, Writer

from ..base.versions import __version__
from ..config import Scenario, to_dict
from .channels import Channels
from .schemas import FORMAT, METADATA_NAME


def log_metadata(
    scenario: Scenario,
    user: dict[str, Any],
    log_every: int,
    scene_every: int,
    step_seconds: float,
) -> dict[str, str]:
    """The log's metadata record (values as JSON text): the command line, the seed and
    algorithm of the training config under ``user["train"]``, the ``user`` entries, then
    the format, scenario, package version, what is logged, the time base and the date."""
    train = user.get("train") if isinstance(user.get("train"), dict) else {}
    meta: dict[str, Any] = {
        "command": shlex.join(getattr(sys, "orig_argv", sys.argv)),
        "seed": train.get("seed"),
        "algo": train.get("algo"),
        **user,
        "format": FORMAT,
        "scenario": to_dict(scenario),
        "version": __version__,
        "log_every": log_every,
        "scene_every": scene_every,
        "step_seconds": step_seconds,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "time_base": "log_time = run simulated time: vector step k at k * step_seconds",
    }
    return {k: json.dumps(v, default=str) for k, v in meta.items() if v is not None}


class LogFile:
    """The MCAP file at ``path``, begun with ``metadata`` and every fixed channel (see the
    module docs; ``schemas``: the fixed channels' schemas, by default
    :data:`.schemas.SCHEMAS`). ``channels`` maps topics to channel ids; ``add`` writes a
    message; a chunk should be closed when it holds ``chunk_bytes`` and when it is ``due``,
    ``flush_seconds`` after the previous one was (or after the file was begun)."""

    def __init__(
        self,
        path: Path,
        metadata: dict[str, str],
        chunk_bytes: int,
        flush_seconds: float,
        schemas: dict[str, dict[str, Any]] | None = None,
    ) -> None:
        self.path, self.chunk_bytes, self.flush_seconds = path, chunk_bytes, flush_seconds
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "wb")  # noqa: SIM115 - closed in close() or abandon()
        try:
            self._writer = Writer(self._fh, chunk_size=1 << 62, compression=CompressionType.ZSTD)
            self._writer.start(library=f"a2cm_phys {__version__}")
            self._writer.add_metadata(METADATA_NAME, metadata)
            self.channels = Channels(self._writer, schemas)
            self.sync()
        except OSError as err:  # e.g. a full disk: leave no unreadable part behind
            self._fh.close()
            self.path.unlink(missing_ok=True)
            raise self.named(err) from None
        self.closed = False
        self._unflushed = 0  # message bytes in the open chunk
        self._deadline = time.monotonic() + flush_seconds

    @property
    def due(self) -> bool:
        """Whether ``flush_seconds`` have passed since the chunk was last closed on time."""
        return time.monotonic() >= self._deadline

    def add(self, channel: int, log_time: int, data: bytes) -> None:
        """Add one message at ``log_time`` (ns; also its publish time) to the open chunk."""
        self._writer.add_message(channel, log_time, data, log_time)
        self._unflushed += len(data)

    def close_chunk(self, durable: bool = False) -> None:
        """Close the open chunk, so that a killed process keeps its messages; with
        ``durable``, also ``fsync`` the file, so that a crash of the machine keeps them.
        The next chunk is ``due`` ``flush_seconds`` from now."""
        self._writer.flush()
        if durable:
            self.sync()
        self._unflushed = 0
        self._deadline = time.monotonic() + self.flush_seconds

    def close_chunk_if_full(self) -> None:
        """Close the open chunk if it holds ``chunk_bytes`` of messages."""
        if self._unflushed >= self.chunk_bytes:
            self._writer.flush()
            self._unflushed = 0

    def finish(self) -> None:
        """Write the MCAP summary and footer and ``fsync`` the file (then :meth:`close`)."""
        self._writer.finish()
        self.sync()

    def close(self) -> None:
        """Close the file (after :meth:`finish`)."""
        self._fh.close()
        self.closed = True

    def abandon(self) -> None:
        """Close the file as it is, without writing anything more (after a failed write:
        readers take every complete chunk before the failure)."""
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(OSError):  # what could not be written is lost; the rest stays
            self._fh.close()

    def sync(self) -> None:
        """Hand what was written to the disk (``flush``, then ``fsync``)."""
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def named(self, err: OSError) -> OSError:
        """``err`` with this log's file named (a failed ``write`` names none)."""
        if err.filename is not None:
            return err
        reason = err.strerror or os.strerror(err.errno or errno.EIO)
        return OSError(err.errno, reason, str(self.path))
