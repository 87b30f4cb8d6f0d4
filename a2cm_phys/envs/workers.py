"""``ProcessCore``: the physics core with its games split across processes.

``workers`` processes step the games, each a contiguous slice: the caller's process steps
the first slice itself, and each other slice has a worker process that holds one
:class:`~.physics.PhysicsCore` and talks to the parent over a :func:`multiprocessing.Pipe`.
The numbers travel through shared memory (:class:`~.shared.SharedBatch`): the parent writes
every game's actions, each process writes its games' step outcomes, positions and
velocities, and the pipe carries only the requests and the few contact events. A step is
one round trip: the parent asks every worker, steps its own slice, then collects the
replies, so all slices step in parallel. On two cores, ``workers=2`` is two busy processes
and one hand-off a step. A worker polls for its next request, and the parent for the
replies, for :data:`~.worker_process.SPIN_SECONDS` before blocking, so that in a loop of
steps neither waits on the kernel to wake it (:func:`~.worker_process.spin`).

The worker processes' own loop is :mod:`.worker_process`, the parent's side of their pipes
:mod:`.worker_pool`, the shared arrays :mod:`.shared`.

Resets cost no round trip of their own. The state of a freshly built world is known in
advance (bodies at rest at their start, their random start drawn from the seed, or placed
positions; differential-drive pursuers at heading 0), so ``reset`` writes it at
once, after validating placements here so that a bad one changes no game, and marks the
games in shared memory with their new seeds (placements, which are rare, wait to go with
the next request). Each process applies the marked resets of its slice just before its
next step, taking worlds it rebuilt in advance while it was waiting (see
:meth:`~.physics.PhysicsCore.build_spare`). Games are independent and their randomness is
per episode seed, so a ``ProcessCore`` gives exactly the trajectories of a single
``PhysicsCore`` of the same size.
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Sequence

import numpy as np

from ..config import Scenario
from .core import StepOutcome
from .evaders.learned import refuse_evader_actions, take_evader_actions
from .physics import PhysicsCore, StateViews, placed_positions, rest_headings, start_positions
from .shared import Placement, SharedBatch, step_slice
from .starts import random_starts
from .worker_pool import WorkerError, WorkerPool


def _check_arguments(
    scenario: Scenario, num_envs: int, workers: int, timeout: float | None
) -> None:
    """Raise ``ValueError`` naming a :class:`ProcessCore` argument it cannot take."""
    if scenario.mode != "physics":
        raise ValueError(f"ProcessCore needs a physics scenario, got mode={scenario.mode!r}")
    if not 1 <= workers <= num_envs:
        raise ValueError(f"workers must be in [1, num_envs={num_envs}], got {workers}")
    if timeout is not None and not timeout > 0:
        raise ValueError(f"timeout must be positive seconds or None, got {timeout!r}")


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
    a quarter of its games, plus one; see :meth:`PhysicsCore.build_spare`)."""

    def __init__(
        self,
        scenario: Scenario,
        num_envs: int,
        workers: int,
        start_method: str | None = None,
        spares: int | None = None,
        timeout: float | None = 120.0,
    ) -> None:
        _check_arguments(scenario, num_envs, workers, timeout)
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
        self._random = scenario.start.random
        self._headings = self._views.get("headings")
        self._rest = rest_headings(scenario, 1)
        if self._headings is not None:
            self._headings[:] = self._rest
        slices = np.array_split(np.arange(num_envs), workers)
        self._bounds = np.cumsum([0] + [len(s) for s in slices])
        self._placed: list[dict[int, Placement]] = [{} for _ in range(workers)]
        self._learned = scenario.evader == "learned"
        ahead = [len(games) // 4 + 1 if spares is None else spares for games in slices]
        games = [(int(s[0]), int(s[-1]) + 1) for s in slices[1:]]
        self._pool = WorkerPool(ctx, scenario, self._shared, games, ahead[1:])
        self._procs = self._pool.procs  # worker w at w - 1 (tests and benchmarks read it)
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
        self._pool.gather(self.timeout)  # each worker says it is ready

    # ------------------------------------------------------------------ Core

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Placement] | None = None,
    ) -> None:
        """Start new episodes in games ``envs`` (global indices); see the module docstring."""
        if self._pool.closed:
            raise WorkerError("ProcessCore is closed")
        envs = np.atleast_1d(np.asarray(envs, dtype=np.int64))
        seeds = np.broadcast_to(np.asarray(seeds, dtype=np.uint64), envs.shape)
        placed = list(positions or ())[: len(envs)]
        # validate every placement before changing any game
        starts = {k: placed_positions(self.scenario, p) for k, p in enumerate(placed) if p}
        views = self._views
        views["seed"][envs] = seeds
        views["reset"][envs] = True
        # a random start is a pure function of the seed: the worker's core draws the same
        self._state[envs, 0] = random_starts(self.scenario, seeds) if self._random else self._start
        self._state[envs, 1] = 0.0
        if self._headings is not None:
            self._headings[envs] = self._rest
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
        if self._pool.closed:
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
        pool = self._pool
        for w in range(1, len(self._placed)):
            pool.ask(w, self._placed[w])
            self._placed[w] = {}
        try:
            events = step_slice(self._own, self._mine, self._placed[0], self._learned)
        except BaseException:  # no reply may stay in a pipe for the next step
            pool.gather(self.timeout, ready=False)
            raise
        self._placed[0] = {}
        # Prepare worlds for this slice's resets while the workers finish theirs.
        while self._own.spare_worlds < self._own_spares and not pool.answered():
            self._own.build_spare()
        events += [game for reply in pool.gather(self.timeout) for game in reply]
        self.t += 1
        views = self._views
        return StepOutcome(
            **{name: views[name].copy() for name in self._shared.outcome_fields},
            events=events,
        )

    # ------------------------------------------------------------------ lifetime

    def close(self) -> None:
        """Stop the workers (idempotent)."""
        self._pool.close()

    def __enter__(self) -> ProcessCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        pool = getattr(self, "_pool", None)
        if pool is not None and not pool.closed:
            self.close()
