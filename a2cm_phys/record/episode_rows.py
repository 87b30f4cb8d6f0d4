"""Where each game's episode lies in the recorder's step buffers, and the finished episodes
waiting to be written.

Each vector step takes the next buffer row (:mod:`.buffers`); the episodes that finish in
it are queued as a :class:`Finished` (their summaries and rows), and their games' next
episodes begin at that row. When the buffers are full, the rows older than every running episode
are dropped (after the queue has been written, since its episodes live in those rows).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..envs.tallies import EpisodeBatch
from ..envs.vector import VecStep, VectorEnv
from .buffers import StepBuffers


class Finished(NamedTuple):
    """The episodes one vector step finished, waiting to be written: their summaries, the
    buffer rows of their start states (``first``, per episode) and of the step (``last``),
    their contact events (per episode: physics, or grid games with some; else ``None``) and
    whether the log holds each from its start (``whole``)."""

    summaries: EpisodeBatch
    first: np.ndarray
    last: int
    events: list[list | None]
    whole: np.ndarray


class EpisodeRows:
    """The step buffers of ``vec_env``, the row where each game's running episode began,
    and the queue of finished episodes (see the module docs).

    The buffers start with room for two episodes of ``max_steps``, within bounds; an
    episode that fills them grows them, so memory follows the episodes that happen.
    ``base`` is the log's clock (vector steps) at buffer row 0; it moves on as old rows are
    dropped. Make it right after the env's reset (or at a resumed run's checkpoint).
    """

    def __init__(self, vec_env: VectorEnv, max_steps: int, base: int) -> None:
        self.buf = StepBuffers(vec_env, min(max(2048, 2 * (max_steps + 2)), 8192))
        self.base = base
        self._vec = vec_env
        b = vec_env.num_envs
        self._events: list[list] = [[] for _ in range(b)]
        self._begin = np.zeros(b, dtype=np.int64)  # buffer row of each game's episode start
        # Games already inside an episode (a resumed run): their first steps are not ours to
        # log, so those episodes get a summary but no trajectory.
        t = np.asarray(getattr(vec_env.core, "t", 0))
        self._partial = {int(i) for i in np.flatnonzero(t > 0)}
        self._row = 0  # last buffer row written
        self._queue: list[Finished] = []

    @property
    def full(self) -> bool:
        """Whether the buffers have no row left for the next step."""
        return self._row + 1 >= self.buf.rows

    def add(self, actions: np.ndarray, step: VecStep) -> None:
        """Copy one vector step into the next row and queue the episodes it finished."""
        r = self._row = self._row + 1
        buf = self.buf
        buf.write(r, actions, step)
        events = self._events
        out = step.outcome
        if out.events is not None:
            for i, game_events in enumerate(out.events):
                if game_events:
                    events[i].extend(game_events)
        eps = step.episodes
        if eps:
            buf.write_starts(r, self._vec)
            ev: list[list | None] = [None] * len(eps)
            if buf.vel is not None or out.events is not None or any(events):
                for j, g in enumerate(eps.env.tolist()):
                    if buf.vel is not None or events[g]:
                        ev[j], events[g] = events[g], []
            whole = np.ones(len(eps), dtype=bool)
            if self._partial:  # a resumed run's first episodes
                games = eps.env.tolist()
                whole[:] = [g not in self._partial for g in games]
                self._partial.difference_update(games)
            self._queue.append(Finished(eps, self._begin[eps.env], r, ev, whole))
            self._begin[eps.env] = r

    def take(self) -> list[Finished]:
        """The queued steps' episodes, in finishing order; the queue is left empty."""
        queue, self._queue = self._queue, []
        return queue

    def compact(self) -> None:
        """Drop the rows older than every running episode (the queue must be empty), and
        grow the buffers if an episode fills them on its own."""
        first = int(self._begin.min())
        self.buf.keep(first, self._row)
        self._begin -= first
        self._row -= first
        self.base += first
        if self._row + 1 >= self.buf.rows:  # an episode longer than the buffer: grow it
            self.buf.grow()
