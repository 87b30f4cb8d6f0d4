"""What a physics worker process of a :class:`~.workers.ProcessCore` runs: its loop
(:func:`serve`: build a core for its slice of games, then step it on each request), ending
with its parent however the parent ends, and the short polls (:func:`spin`) that keep it
and the parent from sleeping in the kernel between steps."""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Sequence
from multiprocessing.connection import Connection

from ..config import Scenario
from .physics import PhysicsCore
from .shared import SharedBatch, step_slice

_GC_THRESHOLD = 10_000
"""Allocations between a worker's young-generation collections (Python's default: 700)."""


_PR_SET_PDEATHSIG = 1
"""Linux ``prctl`` option: the signal a process gets when its parent dies."""

SPIN_SECONDS = 5e-4
"""How long a worker polls for its next request after replying, and the parent for the
workers' replies after stepping its own slice, before either blocks (see :func:`spin`)."""

PARENT_POLL_SECONDS = 1.0
"""How often a worker checks that its parent is alive, where the kernel cannot tell it."""


def _die_with_parent(parent: int) -> None:
    """End this worker when process ``parent`` ends, however it ends (SIGKILL included).

    Waiting for the pipe's EOF is not enough: with ``fork``, every worker inherits the
    parent's ends of the pipes, so no pipe closes when the parent dies. On Linux the kernel
    sends SIGKILL when the parent dies (``PR_SET_PDEATHSIG``); everywhere, a daemon thread
    also polls whether the parent still exists (it is not our direct parent under
    ``forkserver``).
    """
    if sys.platform.startswith("linux") and os.getppid() == parent:
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    first_ppid = os.getppid()

    def orphaned() -> bool:
        if first_ppid == parent and os.getppid() != parent:  # re-parented: the parent died
            return True
        try:
            os.kill(parent, 0)
        except ProcessLookupError:
            return True
        except PermissionError:  # a process of someone else now has that pid
            return True
        return False

    if orphaned():  # it died before the kernel was told to watch it
        os._exit(1)

    def watch() -> None:
        while not orphaned():
            time.sleep(PARENT_POLL_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="a2cm-parent-watch", daemon=True).start()


def serve(
    conn: Connection,
    scenario: Scenario,
    shared: SharedBatch,
    games: tuple[int, int],
    spares: int,
    parent: int | None = None,
) -> None:
    """A worker's loop: build a core for games ``lo:hi``, then on each request apply the
    resets marked in ``shared`` and step, rebuilding up to ``spares`` worlds for later
    resets while it waits. It ends with process ``parent`` (see :func:`_die_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the handler a fork may inherit
    if parent is not None:
        _die_with_parent(parent)
    try:
        lo, hi = games
        core = PhysicsCore(scenario, hi - lo)
        mine = shared.views(lo, hi)
        learned = scenario.evader == "learned"
        # Every rebuild leaves a pymunk space, joints and handlers as cyclic garbage, and
        # allocation-triggered GC runs rescan everything alive. This process only steps
        # worlds: collect rarely, and never rescan what exists now.
        gc.collect()
        gc.freeze()
        gc.set_threshold(_GC_THRESHOLD, 10, 10)
        conn.send(("ok", None))
    except Exception as err:
        _report(conn, err)
        return
    while True:
        # Idle: prepare worlds for resets, up to ``spares`` waiting (not one more per step).
        while core.spare_worlds < spares and not conn.poll(0):
            core.build_spare()
        try:
            command, placed = conn.recv()
        except EOFError:  # the parent went away
            return
        if command == "close":
            conn.close()
            return
        try:
            conn.send(("ok", step_slice(core, mine, placed, learned)))
        except Exception as err:  # report to the parent, which re-raises
            _report(conn, err)
        spin([conn], SPIN_SECONDS)


def spin(conns: Sequence[Connection], seconds: float) -> None:
    """Poll ``conns`` until each has something to read, for at most ``seconds``.

    Between two steps of a loop a process should not sleep in the kernel: waking it costs
    about 50-100 us on a virtual machine, and a CPU that went idle comes back with its
    caches cold (measured here: the parent's own slice took 1.8x as long after it had
    blocked for a reply as after it had polled for one)."""
    deadline = time.perf_counter() + seconds
    for conn in conns:
        while not conn.poll(0) and time.perf_counter() < deadline:
            pass


def _report(conn: Connection, err: Exception) -> None:
    """Send ``err`` and its traceback to the parent (as a ``RuntimeError`` if it won't pickle)."""
    text = traceback.format_exc()
    try:
        conn.send(("error", (err, text)))
    except Exception:
        conn.send(("error", (RuntimeError(f"{type(err).__name__}: {err}"), text)))
