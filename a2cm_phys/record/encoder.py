"""Finished episodes as the log's messages: one trajectory block of the logged ones, the
scenes of the drawn ones, one summary block of them all (columnar: arrays over the
block's episodes; see :mod:`.schemas`, and :mod:`.runlog` for how they are split again),
and the learning curve's points they complete (:mod:`.curve`).

Everything is gathered from the step buffers with one gather per field (:mod:`.block`) and
written by the vectorised JSON text encoder (:mod:`.jsontext`), with no per-episode or
per-step Python work on the grid.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from ..config import Scenario
from ..envs.tallies import EpisodeBatch
from .block import Block
from .buffers import StepBuffers
from .curve import EpisodeCurve
from .episode_rows import Finished
from .jsontext import json_array, json_object
from .schemas import (
    PLOT_EPISODES_TOPIC,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    scene_topic,
    step_seconds,
)

_NS = 1_000_000_000


class _Columns:
    """The fields of a queue of finished episodes as arrays, one row an episode; ids from
    ``first_id`` on; start and end times ``t0``/``t1`` on the log's clock (``base`` is the
    clock at buffer row 0)."""

    def __init__(self, finished: list[Finished], first_id: int, base: int, dt: float) -> None:
        self.events = [e for f in finished for e in f.events]
        eps = EpisodeBatch.concat([f.summaries for f in finished])
        self.evader_ret = eps.evader_ret
        self.ints = ints = np.column_stack(
            [
                eps.env,
                eps.length,
                eps.collisions,
                eps.wall_contacts,
                eps.captured,
                eps.truncated,
                eps.collision_terminated,
                np.concatenate([f.first for f in finished]),
                np.repeat([f.last for f in finished], [len(f.first) for f in finished]),
                np.concatenate([f.whole for f in finished]),
            ]
        ).astype(np.int64, copy=False)
        self.env, self.length, self.begin, self.end = ints[:, 0], ints[:, 1], ints[:, 7], ints[:, 8]
        self.whole = ints[:, 9].astype(bool)
        self.ids = np.arange(first_id, first_id + len(ints))
        self._check_in_sync()
        self.seed = np.asarray(eps.seed, dtype=np.uint64)
        self.returns = np.asarray(eps.ret, dtype=np.float64)
        self.t0 = (base + self.end - self.length) * dt
        self.t1 = (base + self.end) * dt

    def _check_in_sync(self) -> None:
        """A ``RuntimeError`` if a whole episode spans more or fewer rows than its steps."""
        bad = np.flatnonzero(self.whole & (self.end - self.begin != self.length))
        if len(bad):
            j = bad[0]
            raise RuntimeError(
                f"EpisodeRecorder out of sync: env {self.env[j]}: an episode of length "
                f"{self.length[j]} spans {self.end[j] - self.begin[j]} recorded steps "
                "(record_step every step?)"
            )

    def block(
        self, buf: StepBuffers, sel: np.ndarray, dt: float, scenario: Scenario | None = None
    ) -> Block:
        """The episodes at rows ``sel`` gathered from ``buf`` (with ``scenario``'s sensing
        masks, if it has sensing)."""
        events = [self.events[i] for i in sel]
        return Block(
            buf,
            self.ids[sel],
            self.env[sel],
            self.seed[sel],
            self.begin[sel],
            self.length[sel],
            events,
            dt,
            scenario,
        )


class EpisodeEncoder:
    """Encodes queues of finished episodes of ``scenario`` into messages (see the module
    docs): the trajectory of every ``log_every``-th episode (0: none), the scenes of every
    ``scene_every``-th (0: none), every summary, a learning-curve point per ``plot_every``
    episodes (0: none); with a learned evader, its returns. Episodes are numbered in the
    order they come, from the id given to :meth:`start`. ``dt`` is the simulated seconds
    per step, ``step_ns`` the same in integer nanoseconds."""

    def __init__(
        self, scenario: Scenario, log_every: int, scene_every: int, plot_every: int = 0
    ) -> None:
        self.scenario = scenario
        self.log_every, self.scene_every, self.plot_every = log_every, scene_every, plot_every
        self.dt = step_seconds(scenario)
        self.step_ns = round(self.dt * _NS)  # the clock in integer nanoseconds: exact
        self.learned = False
        self._next_id = 0
        self._curve: EpisodeCurve | None = None

    def start(self, first_id: int, learned: bool) -> None:
        """Number the next episode ``first_id``; ``learned``: the evader is learned."""
        self._next_id, self.learned = first_id, learned
        if self.plot_every:
            self._curve = EpisodeCurve(self.scenario, self.plot_every, learned)

    def messages(
        self, finished: list[Finished], buf: StepBuffers, base: int
    ) -> Iterator[tuple[str, int, bytes]]:
        """``(topic, log_time, data)`` of the messages of ``finished`` (gathered from
        ``buf``, whose row 0 is at ``base`` on the log's clock), made one by one as they
        are taken. A queue out of step with the buffers (``record_step`` not called every
        step) is a ``RuntimeError`` before the first."""
        cols = _Columns(finished, self._next_id, base, self.dt)
        self._next_id += len(cols.ids)
        log_time = int(cols.end.max() + base) * self.step_ns
        every = self.log_every
        logged = cols.whole & (cols.ids % max(every, 1) == 0) & (every > 0)
        if logged.any():
            sel = np.flatnonzero(logged)
            block = cols.block(buf, sel, self.dt, self.scenario)
            yield TRAJECTORY_TOPIC, log_time, block.json(cols.t0[sel])
        if self.scene_every:
            from .scene import episode_scenes  # the Foxglove SDK, loaded only to draw

            for i in np.flatnonzero(cols.whole & (cols.ids % self.scene_every == 0)):
                block = cols.block(buf, np.array([i]), self.dt, self.scenario)
                traj = block.trajectory(float(cols.t0[i]))
                topic = scene_topic(traj.env)
                for time_ns, data in episode_scenes(self.scenario, traj):
                    yield topic, time_ns, data
        yield SUMMARY_TOPIC, log_time, self._summary(cols, logged)
        if self._curve is not None:
            for time_ns, data in self._points(cols, base):
                yield PLOT_EPISODES_TOPIC, time_ns, data

    def finish(self) -> Iterator[tuple[str, int, bytes]]:
        """The messages still owed when writing stops: the learning curve's open point."""
        if self._curve is not None:
            for time_ns, data in self._curve.rest():
                yield PLOT_EPISODES_TOPIC, time_ns, data

    def _points(self, cols: _Columns, base: int) -> list[tuple[int, bytes]]:
        """The learning-curve points the block's episodes complete."""
        ints = cols.ints
        extra = {}
        if self.learned:
            extra["evader_return"] = np.asarray(cols.evader_ret, dtype=np.float64)
        return self._curve.add(
            cols.ids,
            (base + cols.end) * self.step_ns,
            length=cols.length,
            collisions=ints[:, 2],
            wall_contacts=ints[:, 3],
            captured=ints[:, 4],
            truncated=ints[:, 5],
            collision_terminated=ints[:, 6],
            **{"return": cols.returns},
            **extra,
        )

    def _summary(self, cols: _Columns, logged: np.ndarray) -> bytes:
        """The summary block: every episode's summary, column by column."""
        ints = cols.ints
        flags = ints[:, 4:7].astype(bool)
        returns = {"return": json_array(cols.returns)}
        if self.learned:
            evader = np.asarray(cols.evader_ret, dtype=np.float64)
            returns["evader_return"] = json_array(evader)
        return json_object(
            episode=json_array(cols.ids),
            env=json_array(cols.env),
            seed=json_array(cols.seed),
            length=json_array(cols.length),
            **returns,
            captured=json_array(flags[:, 0]),
            truncated=json_array(flags[:, 1]),
            collision_terminated=json_array(flags[:, 2]),
            collisions=json_array(ints[:, 2]),
            wall_contacts=json_array(ints[:, 3]),
            t0=json_array(cols.t0),
            t1=json_array(cols.t1),
            logged=json_array(logged),
        )
