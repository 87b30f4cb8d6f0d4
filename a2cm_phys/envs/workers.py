"""``ProcessCore``: the physics core with its games split across processes.

``workers`` processes step the games, each a contiguous slice: the caller's process steps
the first slice itself, and each other slice has a worker process that holds one
:class:`~.physics.PhysicsCore` and talks to the parent over a :func:`multiprocessing.Pipe`.
The numbers travel through shared memory (:class:`SharedBatch`): the parent writes every
game's actions, each process writes its games' step outcomes, positions and velocities,
and the pipe carries only the requests and the few contact events. A step is one round
trip: the parent asks every worker, steps its own slice, then collects the replies, so all
slices step in parallel. On two cores, ``workers=2`` is two busy processes and one
hand-off a step. A worker polls for its next request, and the parent for the replies, for
:data:`SPIN_SECONDS` before blocking, so that in a loop of steps neither waits on the
kernel to wake it (:func:`_spin`).

Resets cost no round trip of their own. The state of a freshly built world is known in
advance (bodies at rest at their start or placed positions), so ``reset`` writes it at
once, after validating placements here so that a bad one changes no game, and marks the
games in shared memory with their new seeds (placements, which are rare, wait to go with
the next request). Each process applies the marked resets of its slice just before its
next step, taking worlds it rebuilt in advance while it was waiting (see
:meth:`~.physics.PhysicsCore.build_spare`). Games are independent and their randomness is
per episode seed, so a ``ProcessCore`` gives exactly the trajectories of a single
``PhysicsCore`` of the same size.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Mapping, Sequence
from dataclasses import fields
from multiprocessing.connection import Connection
from multiprocessing.reduction import ForkingPickler
from typing import Any

import numpy as np

from ..config import Scenario
from .core import StepOutcome
from .evaders.learned import refuse_evader_actions, take_evader_actions
from .physics import PhysicsCore, StateViews, placed_positions, start_positions

_GC_THRESHOLD = 10_000
"""Allocations between a worker's young-generation collections (Python's default: 700)."""

_OUTCOME = tuple(f.name for f in fields(StepOutcome) if f.name != "events")
"""The fields of :class:`~.core.StepOutcome` that travel through shared memory (all but
the contact events)."""

Placement = Mapping[str, Sequence[float]] | None

_STEP = ForkingPickler.dumps(("step", {}))
"""A step request without placements, as :meth:`Connection.send` would pickle it."""


class WorkerError(RuntimeError):
    """A physics worker process died or failed; the message says which and why."""


class SharedBatch:
    """The arrays of a batch of ``num_envs`` physics games that the parent and its workers
    share, in one block of shared memory. The parent writes the pursuers' actions (and a
    learned evader's, ``evader_actions``) and marks games to reset (``reset``, with their
    ``seed``); the workers clear those marks and write each field of the step outcome but
    the events, and the state (positions, velocities). ``views(lo, hi)`` gives numpy views
    of games ``lo:hi``."""

    def __init__(self, scenario: Scenario, num_envs: int, ctx: Any) -> None:
        n = scenario.pursuers
        # continuous control: float64 (vx, vy) commands for the pursuers and the evader
        command = (np.dtype(np.float64), (2,)) if scenario.continuous else (np.dtype(np.int64), ())
        self.layout: list[tuple[str, np.dtype, tuple[int, ...]]] = [
            ("actions", command[0], (n, *command[1])),
            ("evader_actions", *command),  # read only with a learned evader
            ("seed", np.dtype(np.uint64), ()),
            ("state", np.dtype(np.float64), (2, n + 1, 2)),
            ("reward", np.dtype(np.float64), ()),
            ("collisions", np.dtype(np.int64), ()),
            ("wall_contacts", np.dtype(np.int64), ()),
            ("evader_action", *command),
            ("terminated", np.dtype(np.bool_), ()),
            ("truncated", np.dtype(np.bool_), ()),
            ("captured", np.dtype(np.bool_), ()),
            ("reset", np.dtype(np.bool_), ()),
        ]
        self.num_envs = num_envs
        size = sum(_bytes(dtype, num_envs, tail) for _, dtype, tail in self.layout)
        self.block = ctx.RawArray("b", size)

    def views(self, lo: int = 0, hi: int | None = None) -> dict[str, np.ndarray]:
        """Numpy views of every field for games ``lo:hi`` (default: all)."""
        out, offset = {}, 0
        for name, dtype, tail in self.layout:
            count = self.num_envs * int(np.prod(tail, dtype=np.int64))
            whole = np.frombuffer(self.block, dtype, count, offset).reshape(-1, *tail)
            out[name] = whole[lo:hi]
            offset += _bytes(dtype, self.num_envs, tail)
        return out


def _bytes(dtype: np.dtype, num_envs: int, tail: tuple[int, ...]) -> int:
    """Bytes of one field, rounded up to 8 so that every field stays aligned."""
    size = dtype.itemsize * num_envs * int(np.prod(tail, dtype=np.int64))
    return -(-size // 8) * 8


_PR_SET_PDEATHSIG = 1
"""Linux ``prctl`` option: the signal a process gets when its parent dies."""

SPIN_SECONDS = 5e-4
"""How long a worker polls for its next request after replying, and the parent for the
workers' replies after stepping its own slice, before either blocks (see :func:`_spin`)."""

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


def _serve(
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
            conn.send(("ok", _step_slice(core, mine, placed, learned)))
        except Exception as err:  # report to the parent, which re-raises
            _report(conn, err)
        _spin([conn], SPIN_SECONDS)


def _spin(conns: Sequence[Connection], seconds: float) -> None:
    """Poll ``conns`` until each has something to read, for at most ``seconds``.

    Between two steps of a loop a process should not sleep in the kernel: waking it costs
    about 50-100 us on a virtual machine, and a CPU that went idle comes back with its
    caches cold (measured here: the parent's own slice took 1.8x as long after it had
    blocked for a reply as after it had polled for one)."""
    deadline = time.perf_counter() + seconds
    for conn in conns:
        while not conn.poll(0) and time.perf_counter() < deadline:
            pass


def _step_slice(
    core: PhysicsCore,
    mine: dict[str, np.ndarray],
    placed: dict[int, Placement] | None,
    learned: bool,
) -> list[list]:
    """Step the games of ``core``, whose shared arrays are ``mine``: first the resets marked
    there (with their ``placed`` positions, by local index), then one step; write the
    outcome and the state to ``mine`` and return the contact events."""
    marked = mine["reset"]
    envs = np.flatnonzero(marked)
    if len(envs):
        where = [placed.get(env) for env in envs.tolist()] if placed else None
        core.reset(envs, mine["seed"][envs], where)
        marked[envs] = False
    outcome = core.step(mine["actions"], mine["evader_actions"] if learned else None)
    for name in _OUTCOME:
        mine[name][:] = getattr(outcome, name)
    mine["state"][:] = core._state
    return outcome.events


def _report(conn: Connection, err: Exception) -> None:
    """Send ``err`` and its traceback to the parent (as a ``RuntimeError`` if it won't pickle)."""
    text = traceback.format_exc()
    try:
        conn.send(("error", (err, text)))
    except Exception:
        conn.send(("error", (RuntimeError(f"{type(err).__name__}: {err}"), text)))


class ProcessCore(StateViews):
    """``num_envs`` physics games stepped by ``workers`` processes: this one and
    ``workers - 1`` worker processes (implements ``core.Core``).

    Call :meth:`close` (or use it as a context manager) to stop the workers; they also
    end when the parent process dies, whatever killed it. A worker that dies raises
    :class:`WorkerError` naming it (workers are numbered from 1: slice 0 is this process's)
    and its exit code at the next call, and so does one that is alive but has not answered
    for ``timeout`` seconds (``None``: wait for ever); either way the core is closed.
    ``start_method`` is multiprocessing's (default: the platform's; ``spawn`` and
    ``forkserver`` need the usual ``if __name__ == "__main__":`` guard in the calling
    script). ``spares`` is how many worlds each process rebuilds ahead while idle (default:
    a quarter of its games, plus one; see :meth:`PhysicsCore.build_spare`).
    """

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int,
        workers: int,
        start_method: str | None = None,
        spares: int | None = None,
        timeout: float | None = 120.0,
    ) -> None:
        if scenario.mode != "physics":
            raise ValueError(f"ProcessCore needs a physics scenario, got mode={scenario.mode!r}")
        if not 1 <= workers <= num_envs:
            raise ValueError(f"workers must be in [1, num_envs={num_envs}], got {workers}")
        if timeout is not None and not timeout > 0:
            raise ValueError(f"timeout must be positive seconds or None, got {timeout!r}")
        self.scenario = scenario
        self.num_envs = num_envs
        self.timeout = timeout
        self.t = np.zeros(num_envs, dtype=np.int64)
        self.episode_seed = np.zeros(num_envs, dtype=np.uint64)
        self._start = start_positions(scenario)
        ctx = mp.get_context(start_method)
        self._shared = SharedBatch(scenario, num_envs, ctx)
        self._views = self._shared.views()
        self._state = self._views["state"]  # as PhysicsCore's, written by the workers
        self._state[:, 0] = self._start
        slices = np.array_split(np.arange(num_envs), workers)
        self._bounds = np.cumsum([0] + [len(s) for s in slices])
        self._placed: list[dict[int, Placement]] = [{} for _ in range(workers)]
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        self._closed = False
        self._learned = scenario.evader == "learned"
        ahead = [len(games) // 4 + 1 if spares is None else spares for games in slices]
        for i, games in enumerate(slices[1:], start=1):
            parent, child = ctx.Pipe()
            proc = ctx.Process(
                target=_serve,
                args=(
                    child,
                    scenario,
                    self._shared,
                    (int(games[0]), int(games[-1]) + 1),
                    ahead[i],
                    os.getpid(),
                ),
                name=f"a2cm-physics-{i}",
                daemon=True,
            )
            proc.start()
            child.close()  # so that the parent sees EOF when the worker dies
            self._conns.append(parent)
            self._procs.append(proc)
        # The first slice is stepped here, in the caller's process, while the others step
        # theirs: on two cores, two busy processes and one hand-off a step, not three and
        # two. (Built after the workers start, which need not inherit its worlds.)
        try:
            self._own = PhysicsCore(scenario, len(slices[0]))
        except BaseException:
            self.close()
            raise
        self._own_spares = ahead[0]
        self._mine = self._shared.views(0, len(slices[0]))
        self._gather()  # each worker says it is ready

    # ------------------------------------------------------------------ Core

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Placement] | None = None,
    ) -> None:
        """Start new episodes in games ``envs`` (global indices); see the module docstring."""
        if self._closed:
            raise WorkerError("ProcessCore is closed")
        envs = np.atleast_1d(np.asarray(envs, dtype=np.int64))
        seeds = np.broadcast_to(np.asarray(seeds, dtype=np.uint64), envs.shape)
        placed = list(positions or ())[: len(envs)]
        # validate every placement before changing any game
        starts = {k: placed_positions(self.scenario, p) for k, p in enumerate(placed) if p}
        views = self._views
        views["seed"][envs] = seeds
        views["reset"][envs] = True
        self._state[envs, 0] = self._start
        self._state[envs, 1] = 0.0
        self.t[envs] = 0
        self.episode_seed[envs] = seeds
        if not starts and not any(self._placed):
            return
        for k, env in enumerate(envs.tolist()):  # a plain reset drops an earlier placement
            w = int(np.searchsorted(self._bounds, env, side="right")) - 1
            if k in starts:
                self._state[env, 0] = starts[k]
                self._placed[w][env - int(self._bounds[w])] = placed[k]
            elif self._placed[w]:
                self._placed[w].pop(env - int(self._bounds[w]), None)

    def step(self, actions: np.ndarray, evader_actions: np.ndarray | None = None) -> StepOutcome:
        """Advance every game one step; every process steps its slice in parallel.
        ``evader_actions`` are a learned evader's (required then, refused otherwise)."""
        if self._closed:
            raise WorkerError("ProcessCore is closed")
        actions = np.asarray(actions)
        if actions.shape[0] != self.num_envs:
            raise ValueError(f"expected actions for {self.num_envs} games, got {actions.shape}")
        if self.scenario.evader == "learned":  # checked here: a bad one changes no game
            taken = take_evader_actions(self.scenario, evader_actions, self.num_envs)
            self._views["evader_actions"][:] = taken
        elif evader_actions is not None:
            raise refuse_evader_actions(self.scenario)
        self._views["actions"][:] = actions  # before asking any worker
        for w, conn in enumerate(self._conns, start=1):
            try:
                if self._placed[w]:
                    conn.send(("step", self._placed[w]))
                else:  # the common request, pickled once
                    conn.send_bytes(_STEP)
            except (BrokenPipeError, ConnectionResetError, OSError):
                raise self._death(w) from None
            self._placed[w] = {}
        try:
            events = _step_slice(self._own, self._mine, self._placed[0], self._learned)
        except BaseException:
            self._gather(ready=False)  # no reply may stay in a pipe for the next step
            raise
        self._placed[0] = {}
        # Prepare worlds for this slice's resets while the workers finish theirs.
        while self._own.spare_worlds < self._own_spares and not all(c.poll(0) for c in self._conns):
            self._own.build_spare()
        events += [game for reply in self._gather() for game in reply]
        self.t += 1
        views = self._views
        return StepOutcome(
            **{name: views[name].copy() for name in _OUTCOME},
            events=events,
        )

    # ------------------------------------------------------------------ protocol

    def _gather(self, ready: bool = True) -> list[Any]:
        """Every worker's reply, in order; a worker's error is raised once all have replied,
        so that no reply is left in a pipe to be mistaken for the next one (``ready=False``:
        collect the replies and raise nothing of theirs, when the caller raises its own)."""
        replies, error = [], None
        _spin(self._conns, SPIN_SECONDS)
        for w, conn in enumerate(self._conns, start=1):
            try:  # a worker that dies closes its end of the pipe: recv raises EOFError
                if self.timeout is not None and not conn.poll(self.timeout):
                    raise self._silence(w)
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
        proc = self._procs[worker - 1]
        proc.join(timeout=1.0)
        self.close()
        return WorkerError(
            f"physics worker {worker} ({proc.name}, pid {proc.pid}) died with exit code "
            f"{proc.exitcode}; the ProcessCore is closed, make a new one"
        )

    def _silence(self, worker: int) -> WorkerError:
        proc = self._procs[worker - 1]
        self.close()
        return WorkerError(
            f"physics worker {worker} ({proc.name}, pid {proc.pid}) did not answer within "
            f"{self.timeout:g} s (the ProcessCore's timeout); it was stopped and the "
            "ProcessCore is closed, make a new one"
        )

    # ------------------------------------------------------------------ lifetime

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for conn in self._conns:
            with contextlib.suppress(BrokenPipeError, ConnectionResetError, OSError):
                conn.send(("close", None))
        for proc in self._procs:
            proc.join(timeout=2.0)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=1.0)
            if proc.is_alive():  # a stopped process keeps SIGTERM pending
                proc.kill()
                proc.join(timeout=1.0)
        for conn in self._conns:
            conn.close()

    def __enter__(self) -> ProcessCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            self.close()
