"""``ProcessCore``: the physics core with its games split across worker processes.

Each worker holds one :class:`~.physics.PhysicsCore` for a contiguous slice of the games
and talks to the parent over a :func:`multiprocessing.Pipe`. A step is one round trip:
the parent sends every worker its slice of the actions before collecting any reply, so the
workers step in parallel, and each reply carries the step's outcome with the positions and
velocities (numpy arrays), so ``observe()`` and friends need no further round trip.

Resets cost no round trip of their own. The state of a freshly built world is known in
advance (bodies at rest at their start or placed positions), so ``reset`` updates the
parent's copy at once, after validating placements here so that a bad one changes no
game, and queues the request; the worker applies the queued resets just before its next
step, taking worlds it built in advance while it was waiting (see
:meth:`~.physics.PhysicsCore.build_spare`). Games are independent and their randomness is
per episode seed, so a ``ProcessCore`` gives exactly the trajectories of a single
``PhysicsCore`` of the same size.
"""

from __future__ import annotations

import contextlib
import gc
import multiprocessing as mp
import signal
import traceback
from collections.abc import Mapping, Sequence
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from ..config import Scenario
from .core import StepOutcome
from .physics import PhysicsCore, StateViews, placed_positions, start_positions

_TIMEOUT = 0.5
"""Seconds between liveness checks while waiting for a worker's reply."""

_GC_THRESHOLD = 10_000
"""Allocations between a worker's young-generation collections (Python's default: 700)."""

_FIELDS = ("reward", "terminated", "truncated", "captured", "collisions", "wall_contacts")

Placement = Mapping[str, Sequence[float]] | None


class WorkerError(RuntimeError):
    """A physics worker process died or failed; the message says which and why."""


def _serve(conn: Connection, scenario: Scenario, num_envs: int, spares: int) -> None:
    """A worker's loop: build a core, then apply queued resets and step on each request,
    building up to ``spares`` fresh worlds for later resets while it waits."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    try:
        core = PhysicsCore(scenario, num_envs)
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
        built = 0
        while built < spares and not conn.poll(0):  # idle: prepare worlds for resets
            built = core.build_spare()
        try:
            command, payload = conn.recv()
        except EOFError:  # the parent went away
            return
        if command == "close":
            conn.close()
            return
        try:
            resets, actions = payload
            for envs, seeds, placed in resets:
                core.reset(envs, seeds, placed)
            outcome = core.step(actions)
            conn.send(("ok", (outcome, core.positions(), core.velocities())))
        except Exception as err:  # report to the parent, which re-raises
            _report(conn, err)


def _report(conn: Connection, err: Exception) -> None:
    """Send ``err`` and its traceback to the parent (as a ``RuntimeError`` if it won't pickle)."""
    text = traceback.format_exc()
    try:
        conn.send(("error", (err, text)))
    except Exception:
        conn.send(("error", (RuntimeError(f"{type(err).__name__}: {err}"), text)))


class ProcessCore(StateViews):
    """``num_envs`` physics games stepped by ``workers`` processes (implements ``core.Core``).

    Call :meth:`close` (or use it as a context manager) to stop the workers; they are
    daemons, so they also end with the parent. A worker that dies raises
    :class:`WorkerError` naming it and its exit code at the next call. ``start_method`` is
    multiprocessing's (default: the platform's; ``spawn`` and ``forkserver`` need the
    usual ``if __name__ == "__main__":`` guard in the calling script). ``spares`` is how
    many fresh worlds each worker builds ahead while idle (default: a quarter of its games,
    plus one; see :meth:`PhysicsCore.build_spare`).
    """

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int,
        workers: int,
        start_method: str | None = None,
        spares: int | None = None,
    ) -> None:
        if scenario.mode != "physics":
            raise ValueError(f"ProcessCore needs a physics scenario, got mode={scenario.mode!r}")
        if not 1 <= workers <= num_envs:
            raise ValueError(f"workers must be in [1, num_envs={num_envs}], got {workers}")
        self.scenario = scenario
        self.num_envs = num_envs
        self.t = np.zeros(num_envs, dtype=np.int64)
        self.episode_seed = np.zeros(num_envs, dtype=np.uint64)
        self._start = start_positions(scenario)
        self._state = np.zeros((num_envs, 2, scenario.pursuers + 1, 2))  # as PhysicsCore's
        self._state[:, 0] = self._start
        self._slices = np.array_split(np.arange(num_envs), workers)
        self._bounds = np.cumsum([0] + [len(s) for s in self._slices])
        self._pending: list[list[tuple[np.ndarray, np.ndarray, list[Placement]]]] = [
            [] for _ in range(workers)
        ]
        ctx = mp.get_context(start_method)
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        self._closed = False
        for i, games in enumerate(self._slices):
            parent, child = ctx.Pipe()
            ahead = len(games) // 4 + 1 if spares is None else spares
            proc = ctx.Process(
                target=_serve,
                args=(child, scenario, len(games), ahead),
                name=f"a2cm-physics-{i}",
                daemon=True,
            )
            proc.start()
            child.close()  # so that the parent sees EOF when the worker dies
            self._conns.append(parent)
            self._procs.append(proc)
        self._gather(list(range(workers)))  # each worker says it is ready

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
        seeds = np.broadcast_to(np.asarray(seeds, dtype=np.uint64), envs.shape).copy()
        placed = list(positions or ())[: len(envs)]
        placed += [None] * (len(envs) - len(placed))
        starts = [placed_positions(self.scenario, p) if p else self._start for p in placed]
        owner = np.searchsorted(self._bounds, envs, side="right") - 1
        for w in np.unique(owner).tolist():
            mine = np.flatnonzero(owner == w)
            local = envs[mine] - self._bounds[w]
            self._pending[w].append((local, seeds[mine], [placed[k] for k in mine]))
        self._state[envs, 0] = starts
        self._state[envs, 1] = 0.0
        self.t[envs] = 0
        self.episode_seed[envs] = seeds

    def step(self, actions: np.ndarray) -> StepOutcome:
        """Advance every game one step; the workers step their slices in parallel."""
        if self._closed:
            raise WorkerError("ProcessCore is closed")
        actions = np.asarray(actions)
        if actions.shape[0] != self.num_envs:
            raise ValueError(f"expected actions for {self.num_envs} games, got {actions.shape}")
        slices = [actions[games] for games in self._slices]  # before sending anything
        for w, mine in enumerate(slices):
            try:
                self._conns[w].send(("step", (self._pending[w], mine)))
            except (BrokenPipeError, ConnectionResetError, OSError):
                raise self._death(w) from None
            self._pending[w] = []
        outcomes = []
        replies = self._gather(range(len(slices)))
        for w, (outcome, positions, velocities) in enumerate(replies):
            lo, hi = self._bounds[w], self._bounds[w + 1]
            self._state[lo:hi, 0], self._state[lo:hi, 1] = positions, velocities
            outcomes.append(outcome)
        self.t += 1
        merged = {f: np.concatenate([getattr(o, f) for o in outcomes]) for f in _FIELDS}
        return StepOutcome(
            **merged,
            evader_action=np.concatenate([o.evader_action for o in outcomes]),
            events=[game for o in outcomes for game in o.events],
        )

    # ------------------------------------------------------------------ protocol

    def _gather(self, workers: Sequence[int]) -> list[Any]:
        """Every worker's reply, in order; a worker's error is raised once all have replied,
        so that no reply is left in a pipe to be mistaken for the next one."""
        replies, error = [], None
        for w in workers:
            conn, proc = self._conns[w], self._procs[w]
            try:
                while not conn.poll(_TIMEOUT):
                    if not proc.is_alive():
                        raise self._death(w)
                status, reply = conn.recv()
            except (EOFError, ConnectionResetError, OSError):
                raise self._death(w) from None
            if status == "error":
                err, text = reply
                err.__cause__ = WorkerError(f"physics worker {w} failed:\n{text}")
                error = error or err
            replies.append(reply)
        if error is not None:
            raise error
        return replies

    def _death(self, worker: int) -> WorkerError:
        proc = self._procs[worker]
        proc.join(timeout=1.0)
        self.close()
        return WorkerError(
            f"physics worker {worker} ({proc.name}, pid {proc.pid}) died with exit code "
            f"{proc.exitcode}; the ProcessCore is closed, make a new one"
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
        for conn in self._conns:
            conn.close()

    def __enter__(self) -> ProcessCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            self.close()
