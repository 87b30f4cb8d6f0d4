"""Stream a finished run's episodes to Foxglove (``replay RUN --serve``): the Foxglove SDK's
WebSocket server plays the chosen logged episodes' scenes on ``/scene``, each state at its
simulated time divided by ``speed`` (1: real time), and each episode's summary (from the
log's summaries) as a point of ``/plot/episodes`` when it ends.

The stream's clock starts at 0 and the episodes follow one another (a pause of two steps
between them), as in ``--export-foxglove``'s file, so the scenes play in order whatever
episodes were chosen. Frames are sent as they fall due; a client that falls behind loses
its oldest ones (the SDK drops them), never the stream's pace.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from .curve import EpisodeCurve
from .runlog import RunLog
from .scene import episode_frames
from .schemas import EPISODE_POINT_SCHEMA, PLOT_EPISODES_TOPIC
from .sdk import DEFAULT_HOST, DEFAULT_PORT, FoxgloveServer

SERVE_SCENE_TOPIC = "/scene"
"""The topic of the served scenes (the live view's and the export's too)."""


def serve_episodes(
    log: RunLog,
    episodes: Iterable[int],
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    speed: float = 1.0,
    wait: float | None = None,
    ready: Callable[[str], None] | None = None,
    sleep: Callable[[float], None] = time.sleep,
    linger: float = 1.0,
) -> int:
    """Serve the logged ``episodes`` of ``log`` on ``host:port`` (see the module docs)
    and return how many were played (an episode the log holds no trajectory of is a
    ``KeyError``: check them first). ``ready(url)`` is called once the server
    listens; the first frame waits for a client to subscribe to the scenes, up to
    ``wait`` seconds (``None``: as long as it takes). A port that cannot be had is a
    :class:`~a2cm_phys.base.errors.UserError` naming it. ``speed`` must be positive. The
    server stays up ``linger`` seconds after the last frame, for the clients to get it."""
    if not speed > 0:
        raise ValueError("speed must be positive")
    server = FoxgloveServer(host, port, "a2cm_phys replay")
    try:
        scenes = server.scene_channel(SERVE_SCENE_TOPIC)
        points = server.json_channel(PLOT_EPISODES_TOPIC, EPISODE_POINT_SCHEMA)
        if ready is not None:
            ready(server.url)
        _wait_for_client(scenes.has_sinks, wait, sleep)
        count = _play(log, episodes, scenes, points, speed, sleep)
        sleep(linger)
        return count
    finally:
        server.close()


def _wait_for_client(
    subscribed: Callable[[], bool], wait: float | None, sleep: Callable[[float], None]
) -> None:
    """Return once ``subscribed()``, or after ``wait`` seconds."""
    deadline = None if wait is None else time.monotonic() + wait
    while not subscribed() and (deadline is None or time.monotonic() < deadline):
        sleep(0.05)


def _play(
    log: RunLog,
    episodes: Iterable[int],
    scenes: Any,
    points: Any,
    speed: float,
    sleep: Callable[[float], None],
) -> int:
    """Send every frame when it falls due (wall clock from the first frame on), and a
    curve point after each episode."""
    scenario = log.scenario
    curve = EpisodeCurve(scenario, 1, "evader_return" in log.episodes)
    clock, count, origin = 0.0, 0, time.monotonic()
    for episode in episodes:
        traj = dataclasses.replace(log.trajectory(episode), t0=clock)
        for time_ns, frame in episode_frames(scenario, traj):
            delay = origin + time_ns / 1e9 / speed - time.monotonic()
            if delay > 0:
                sleep(delay)
            scenes.log(frame, log_time=time_ns)
        end_ns = round((clock + traj.length * traj.dt) * 1e9)
        for time_ns, data in curve.add(np.array([count]), np.array([end_ns]), **_row(log, episode)):
            points.log(data, log_time=time_ns)
        clock += (traj.length + 2) * traj.dt
        count += 1
    return count


def _row(log: RunLog, episode: int) -> dict[str, np.ndarray]:
    """The curve columns of one episode's summary."""
    j = int(np.searchsorted(log.episodes["episode"], episode))
    names = (
        "length",
        "return",
        "captured",
        "collision_terminated",
        "truncated",
        "collisions",
        "wall_contacts",
        "evader_return",
    )
    return {k: log.episodes[k][j : j + 1] for k in names if k in log.episodes}
