"""The trainer's episode log, one new part of the run's MCAP log per session, its live
view (``train --live``) and its other views (``train --logger``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..config import to_dict
from ..record.parts import new_part, part_files
from ..record.writer import EpisodeRecorder
from .state import RunState

if TYPE_CHECKING:
    from .live import LiveView


def open_recorder(run: RunState) -> EpisodeRecorder:
    """The run's MCAP recorder for this session (a new part of its log).

    The one call site of :mod:`a2cm_phys.record`: the recorder gets ``start(env, obs)``,
    ``record_step(actions, step)`` after every vector step and ``record_update(update,
    metrics)`` after every update.
    """
    # A resumed session continues the log in a file of its own (an earlier one may have been
    # cut short by a crash, or got ahead of the checkpoint), on the same clock and episode
    # ids; readers let each part supersede what earlier parts logged from its start on. The
    # episodes running at the checkpoint continue from the steps it carried.
    step = run.update * run.cfg.steps_per_env
    path, session = new_part(run.run_dir, run.update)
    part = {
        "session": session,
        "update": run.update,
        "episode": run.stats.episodes,
        "step": step,
        "after": [p.name for p in part_files(run.run_dir)],
    }
    recorder = EpisodeRecorder(
        path,
        run.scenario,
        {"train": to_dict(run.cfg), "part": part},
        log_every=run.log_every,
        scene_every=run.scene_every,
    )
    recorder.start(
        run.env, run.obs, step=step, episode=run.stats.episodes, carried=run.open_episodes
    )
    return recorder


def open_live(run: RunState, host: str, port: int) -> LiveView:
    """A live view serving on ``host:port`` (see :mod:`.live`), started on the run's env and
    clocks (:func:`start_live`). A port that cannot be had is a ``UserError`` naming it."""
    from .live import LiveView  # the Foxglove SDK, loaded only for a live view

    live = LiveView.open(run.scenario, host, port)
    try:
        start_live(run, live)
    except BaseException:
        live.close()
        raise
    return live


def start_live(run: RunState, live: LiveView) -> None:
    """Start ``live`` (opened before the run, e.g. by the train command, so that a busy port
    fails before anything is written) on this session's env and clocks, as the recorder
    starts: it then gets ``step(actions, step)`` after every vector step and
    ``update(update, metrics)`` after every update."""
    live.start(run.env, step=run.update * run.cfg.steps_per_env, episode=run.stats.episodes)


def start_loggers(run: RunState) -> None:
    """Start the run's loggers (:mod:`.loggers`) on this session's env and clocks, as the
    recorder starts: they then get ``step(actions, step)`` after every vector step and
    ``update(update, metrics)`` after every update."""
    step = run.update * run.cfg.steps_per_env
    for logger in run.loggers:
        logger.start(run.env, step=step, episode=run.stats.episodes)
