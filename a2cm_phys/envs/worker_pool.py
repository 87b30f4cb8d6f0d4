"""The parent's side of a :class:`~.workers.ProcessCore`'s worker processes: starting them,
the step requests and replies over their pipes, telling a dead or silent worker apart, and
stopping them (:class:`WorkerPool`)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from multiprocessing.connection import Connection
from multiprocessing.reduction import ForkingPickler
from typing import Any

from ..config import Scenario
from .shared import Placement, SharedBatch
from .worker_process import SPIN_SECONDS, serve, spin

_STEP = ForkingPickler.dumps(("step", {}))
"""A step request without placements, as :meth:`Connection.send` would pickle it."""


class WorkerError(RuntimeError):
    """A physics worker process died or failed; the message says which and why."""


class WorkerPool:
    """Worker processes stepping slices of a batch of games in ``shared``, each over a
    :func:`multiprocessing.Pipe`: one per ``(lo, hi)`` of ``games``, rebuilding up to its
    entry of ``spares`` worlds ahead while idle (see :func:`~.worker_process.serve`).

    Workers are numbered from 1 (slice 0 is the parent's own); ``procs[w - 1]`` is worker
    ``w``. Whatever goes wrong with one (a broken pipe, no answer in time) closes the pool,
    and the :class:`WorkerError` raised says which worker and why."""

    def __init__(
        self,
        ctx: Any,
        scenario: Scenario,
        shared: SharedBatch,
        games: Sequence[tuple[int, int]],
        spares: Sequence[int],
    ) -> None:
        self.conns: list[Connection] = []
        self.procs: list[Any] = []
        self.closed = False
        try:
            for i, (lo_hi, ahead) in enumerate(zip(games, spares, strict=True), start=1):
                parent, child = ctx.Pipe()
                proc = ctx.Process(
                    target=serve,
                    args=(child, scenario, shared, lo_hi, ahead, os.getpid()),
                    name=f"a2cm-physics-{i}",
                    daemon=True,
                )
                proc.start()
                child.close()  # so that the parent sees EOF when the worker dies
                self.conns.append(parent)
                self.procs.append(proc)
        except BaseException:
            self.close()
            raise

    def ask(self, worker: int, placed: dict[int, Placement]) -> None:
        """Ask ``worker`` to step its slice, first placing the games of its marked resets
        that ``placed`` names (by local index)."""
        conn = self.conns[worker - 1]
        try:
            if placed:
                conn.send(("step", placed))
            else:  # the common request, pickled once
                conn.send_bytes(_STEP)
        except (BrokenPipeError, ConnectionResetError, OSError):
            raise self._death(worker) from None

    def answered(self) -> bool:
        """Whether every worker's reply is waiting to be read."""
        return all(conn.poll(0) for conn in self.conns)

    def gather(self, timeout: float | None, ready: bool = True) -> list[Any]:
        """Every worker's reply, in order, waiting at most ``timeout`` seconds for each
        (``None``: for ever); a worker's error is raised once all have replied, so that no
        reply is left in a pipe to be mistaken for the next one (``ready=False``: collect
        the replies and raise nothing of theirs, when the caller raises its own)."""
        replies, error = [], None
        spin(self.conns, SPIN_SECONDS)
        for w, conn in enumerate(self.conns, start=1):
            try:  # a worker that dies closes its end of the pipe: recv raises EOFError
                if timeout is not None and not conn.poll(timeout):
                    raise self._silence(w, timeout)
                status, reply = conn.recv()
            except (EOFError, ConnectionResetError, OSError):
                raise self._death(w) from None
            if status == "error":
                err, text = reply
                err.__cause__ = WorkerError(f"physics worker {w} failed:\n{text}")
                error = error or err
            replies.append(reply)
        if error is not None and ready:
            raise error
        return replies

    def _death(self, worker: int) -> WorkerError:
        proc = self.procs[worker - 1]
        proc.join(timeout=1.0)
        self.close()
        return WorkerError(
            f"physics worker {worker} ({proc.name}, pid {proc.pid}) died with exit code "
            f"{proc.exitcode}; the ProcessCore is closed, make a new one"
        )

    def _silence(self, worker: int, timeout: float) -> WorkerError:
        proc = self.procs[worker - 1]
        self.close()
        return WorkerError(
            f"physics worker {worker} ({proc.name}, pid {proc.pid}) did not answer within "
            f"{timeout:g} s (the ProcessCore's timeout); it was stopped and the "
            "ProcessCore is closed, make a new one"
        )

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        if self.closed:
            return
        self.closed = True
        for conn in self.conns:
            with contextlib.suppress(BrokenPipeError, ConnectionResetError, OSError):
                conn.send(("close", None))
        for proc in self.procs:
            proc.join(timeout=2.0)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=1.0)
            if proc.is_alive():  # a stopped process keeps SIGTERM pending
                proc.kill()
                proc.join(timeout=1.0)
        for conn in self.conns:
            conn.close()
