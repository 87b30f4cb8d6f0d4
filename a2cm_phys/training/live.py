"""Watch a run live in Foxglove: the Foxglove SDK's WebSocket server inside the trainer.

:class:`LiveView` serves, while the run trains (Foxglove: *Open connection*, ``ws://HOST:PORT``):

- ``/scene``: one game's episodes as ``foxglove.SceneUpdate`` (the drawing of the run log's
  scenes, :mod:`a2cm_phys.record.scene`), whole episodes one after the other at a pace a
  person can watch: real time in physics (a state every ``dt``), four states a second on
  the grid; the episodes played meanwhile are dropped (:mod:`.live_game`);
- ``/plot/episodes``: the learning curve, a point per :data:`LIVE_PLOT_EVERY` episodes (sent
  twice a second), and ``/plot/update``: the updates' metrics (twenty updates a second at
  most); the messages of the run log's topics of the same names
  (:mod:`a2cm_phys.record.curve`), so that one Foxglove layout serves both.

Every message is stamped with the run's clock (vector step ``k`` at ``k · dt``, as in the
log), so a stream never goes back in time. Training never waits for a viewer: the SDK's
``log`` hands each message to the server's own threads, which drop a slow client's oldest
messages; and nothing is built for a channel no client subscribes to.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..config import Scenario
from ..envs.tallies import EpisodeBatch
from ..envs.vector import VecStep, VectorEnv
from ..record.curve import EpisodeCurve, episode_columns, update_point
from ..record.runlog import Trajectory
from ..record.scene import episode_frame
from ..record.schemas import (
    EPISODE_POINT_SCHEMA,
    PLOT_EPISODES_TOPIC,
    PLOT_EVERY,
    PLOT_UPDATE_TOPIC,
    UPDATE_POINT_SCHEMA,
    step_seconds,
)
from ..record.sdk import DEFAULT_HOST, DEFAULT_PORT, FoxgloveServer, address
from ..record.updates import StepRate, update_document
from .live_game import GamePlayer

LIVE_SCENE_TOPIC = "/scene"
"""The live scene's topic (``replay --serve`` and ``--export-foxglove`` use it too)."""
GRID_SPEED = 4.0
"""Simulated seconds shown per second on the grid (a step is 1 s): four states a second."""
LIVE_PLOT_EVERY = 10 * PLOT_EVERY
"""Episodes per live curve point: a tenth of the log's points, as many as a person can
follow (a training run finishes thousands of episodes a second) for a tenth of the cost."""
POINTS_SECONDS = 0.5
"""Wall-clock seconds between two sendings of curve points (in bulk: cheaper than one by one)."""
UPDATE_SECONDS = 0.05
"""Wall-clock seconds between two updates' points: twenty a second at most (a run makes
hundreds; the log keeps every one)."""


def live_address(text: str | None) -> tuple[str, int]:
    """``(host, port)`` of ``--live [[HOST:]PORT]`` (see :func:`~a2cm_phys.record.sdk.address`)."""
    return address(text, "--live")


class LiveView:
    """A live view of one run (see the module docs); make it with :meth:`open`, then
    :meth:`start` after the env's reset, :meth:`step` after each vector step,
    :meth:`update` after each learner update, :meth:`close` at the end (or ``with``)."""

    def __init__(
        self,
        server: FoxgloveServer,
        scenario: Scenario,
        speed: float | None,
        plot_every: int,
        game: int,
    ) -> None:
        self.server, self.scenario = server, scenario
        dt = step_seconds(scenario)
        speed = speed or (GRID_SPEED if scenario.mode == "grid" else 1.0)
        self._step_ns = round(dt * 1e9)
        self._scene = server.scene_channel(LIVE_SCENE_TOPIC)
        self._points = server.json_channel(PLOT_EPISODES_TOPIC, EPISODE_POINT_SCHEMA)
        self._updates = server.json_channel(PLOT_UPDATE_TOPIC, UPDATE_POINT_SCHEMA)
        self._player = GamePlayer(
            scenario, game, dt / speed, self._frame, self._scene.has_sinks, time.monotonic
        )
        self._plot_every = plot_every
        self._curve: EpisodeCurve | None = None
        self._pending: list[tuple[int, int, EpisodeBatch]] = []  # (first id, step, …)
        self._curve_watched, self._points_due, self._update_due = False, 0.0, 0.0
        self._vec: VectorEnv | None = None
        self._steps = self._episodes = 0
        self._rate = StepRate(0)

    @classmethod
    def open(
        cls,
        scenario: Scenario,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        speed: float | None = None,
        plot_every: int = LIVE_PLOT_EVERY,
        game: int = 0,
    ) -> LiveView:
        """Start the server on ``host:port`` (port 0: any free one; :attr:`url` says which)
        for a run of ``scenario``: game ``game`` shown at ``speed`` simulated seconds per
        second (default: real time in physics, :data:`GRID_SPEED` on the grid), a curve
        point per ``plot_every`` episodes. A port that cannot be had (busy, not ours) is a
        :class:`UserError` naming it."""
        server = FoxgloveServer(host, port, "a2cm_phys training")
        try:
            return cls(server, scenario, speed, plot_every, game)
        except BaseException:
            server.close()
            raise

    @property
    def url(self) -> str:
        """Where a Foxglove client connects: ``ws://HOST:PORT``."""
        return self.server.url

    def start(self, vec_env: VectorEnv, step: int = 0, episode: int = 0) -> None:
        """Begin with ``vec_env`` right after its reset (or at a resumed run's checkpoint:
        ``step`` vector steps and ``episode`` episodes done, as for the log)."""
        self._vec, self._steps, self._episodes = vec_env, int(step), int(episode)
        self._curve = EpisodeCurve(self.scenario, self._plot_every, vec_env.learned_evader)
        self._rate = StepRate(self._steps)
        self._player.begin(vec_env)

    def step(self, actions: np.ndarray, step: VecStep) -> None:
        """Take one vector step (a :data:`~.rollout.StepHook`: ``actions`` are not used)."""
        first = self._episodes
        self._steps += 1
        if step.episodes:
            self._episodes += len(step.episodes)
            if self._curve_watched:
                self._pending.append((first, self._steps, step.episodes))
        self._player.step(self._vec, step, first)

    def update(self, update: int, metrics: dict[str, Any]) -> None:
        """Send the update's metrics (at most every :data:`UPDATE_SECONDS`: the updates in
        between are dropped), and every :data:`POINTS_SECONDS` the curve points completed
        since the last were sent."""
        now = time.monotonic()
        if now >= self._update_due and self._updates.has_sinks():
            games = self._vec.num_envs if self._vec is not None else 0
            rate = self._rate.measure(self._steps, games)
            doc = update_document(update, metrics, self._steps * games, self._episodes, rate)
            self._updates.log(update_point(doc), log_time=self._steps * self._step_ns)
            self._update_due = now + UPDATE_SECONDS
        if now >= self._points_due:
            self._send_points()
            self._points_due = now + POINTS_SECONDS
            self._curve_watched = self._points.has_sinks()
        self._player.tick()

    def close(self) -> None:
        """Stop the server (clients are disconnected); idempotent."""
        self.server.close()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def episodes_shown(self) -> int:
        """Episodes shown whole on ``/scene`` so far."""
        return self._player.shown

    def _frame(self, traj: Trajectory, k: int) -> None:
        """Send state ``k`` of the shown episode, stamped with the run's clock now."""
        now = self._steps * self._step_ns
        self._scene.log(episode_frame(self.scenario, traj, k, now), log_time=now)

    def _send_points(self) -> None:
        """Send the curve points the pending episodes complete."""
        pending, self._pending = self._pending, []
        if not pending or self._curve is None:
            return
        eps = EpisodeBatch.concat([step_eps for _, _, step_eps in pending])
        ids = np.arange(pending[0][0], pending[0][0] + len(eps))  # all since the last sending
        ends = np.repeat([s for _, s, _ in pending], [len(e) for _, _, e in pending])
        columns = episode_columns(eps, self._curve.learned)
        for time_ns, data in self._curve.add(ids, ends * self._step_ns, **columns):
            self._points.log(data, log_time=time_ns)
