"""Where each game's episode lies in the recorder's step buffers, and the finished episodes
waiting to be written.

Each vector step takes the next buffer row (:mod:`.buffers`); the episodes that finish in
it are queued as a :class:`Finished` (their summaries and rows), and their games' next
episodes begin at that row. When the buffers are full, the rows older than every running episode
are dropped (after the queue has been written, since its episodes live in those rows).

A resumed run's episodes that straddle the resume keep their whole trajectory: at every
update's end (:meth:`EpisodeRows.mark`) the rows remember where each running episode
began, the checkpoint carries those episodes' rows so far (:meth:`EpisodeRows.open_episodes`:
as of the last mark, the state the checkpoint holds, even when a stop mid-rollout rewinds
it), and the next session's rows start from them.
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
    ``base`` is the log's clock (vector steps) at the env's current state. Make it right
    after the env's reset, or at a resumed run's checkpoint with the ``carried``
    :meth:`open_episodes` the checkpoint holds (``None``: an older checkpoint, whose games
    caught mid-episode get a summary but no trajectory).
    """

    def __init__(
        self, vec_env: VectorEnv, max_steps: int, base: int, carried: dict | None = None
    ) -> None:
        rows = min(max(2048, 2 * (max_steps + 2)), 8192)
        if carried is not None and not _matches(carried, vec_env, base):
            carried = None
        if carried is not None:
            rows = max(rows, 2 * int(carried["rows"]["lengths"].max()))
        self.buf = StepBuffers(vec_env, rows)
        self._vec = vec_env
        b = vec_env.num_envs
        self._queue: list[Finished] = []
        if carried is None:
            self.base = base  # the log's clock at buffer row 0; moves on as rows are dropped
            self._events: list[list] = [[] for _ in range(b)]
            self._begin = np.zeros(b, dtype=np.int64)  # buffer row of each game's episode start
            self._row = 0  # last buffer row written
            # games already inside an episode whose first steps no checkpoint carried
            t = np.asarray(getattr(vec_env.core, "t", 0))
            self._partial = {int(i) for i in np.flatnonzero(t > 0)}
        else:
            self._begin = self.buf.place_open(carried["rows"])
            self._row = int(carried["rows"]["lengths"].max()) - 1
            self.base = base - self._row
            self._events = [list(e) for e in carried["events"]]
            self._partial = {int(g) for g in carried["partial"]}
        self.mark()

    def mark(self) -> None:
        """Remember the running episodes as they stand (at an update's end): what
        :meth:`open_episodes` returns until the next mark."""
        events = [(e, len(e)) for e in self._events]
        self._mark = (self._row, self._begin.copy(), events, frozenset(self._partial))

    def open_episodes(self) -> dict:
        """The running episodes as of the last :meth:`mark`, for a checkpoint: each game's
        rows since its episode's start (:meth:`StepBuffers.open_rows`), its contact events
        so far, the games whose episode started before the log did (``partial``), and the
        log's clock at the mark (``step``). Plain arrays, lists and numbers."""
        row, begin, events, partial = self._mark
        return {
            "rows": self.buf.open_rows(begin, row),
            "events": [[tuple(ev) for ev in e[:n]] for e, n in events],
            "partial": sorted(partial),
            "step": int(self.base + row),
        }

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
        row, begin, events, partial = self._mark  # the mark's episodes began no later
        first = int(begin.min())
        self.buf.keep(first, self._row)
        self._begin -= first
        self._row -= first
        self.base += first
        self._mark = (row - first, begin - first, events, partial)
        if self._row + 1 >= self.buf.rows:  # an episode longer than the buffer: grow it
            self.buf.grow()


def _matches(carried: dict, vec_env: VectorEnv, step: int) -> bool:
    """Whether ``carried`` open episodes end where ``vec_env`` stands at log clock ``step``
    (a checkpoint whose games all restarted carries none that match)."""
    rows = carried["rows"]
    lengths = rows["lengths"]
    if carried["step"] != step or len(lengths) != vec_env.num_envs:
        return False
    last = np.cumsum(lengths) - 1  # each game's last carried row
    now = np.where((lengths == 1)[:, None, None], rows["spos"][last], rows["pos"][last])
    return bool(np.array_equal(now, vec_env.core.positions()))
