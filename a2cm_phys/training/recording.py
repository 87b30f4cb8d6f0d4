"""The trainer's episode log: one new part of the run's MCAP log per session."""

from __future__ import annotations

from ..config import to_dict
from ..record.parts import new_part, part_files
from ..record.writer import EpisodeRecorder
from .state import RunState


def open_recorder(run: RunState) -> EpisodeRecorder:
    """The run's MCAP recorder for this session (a new part of its log).

    The one call site of :mod:`a2cm_phys.record`: the recorder gets ``start(env, obs)``,
    ``record_step(actions, step)`` after every vector step and ``record_update(update,
    metrics)`` after every update.
    """
    # A resumed session continues the log in a file of its own (an earlier one may have been
    # cut short by a crash, or got ahead of the checkpoint), on the same clock and episode
    # ids; readers let each part supersede what earlier parts logged from its start on. The
    # games caught mid-episode get a summary without a trajectory.
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
    recorder.start(run.env, run.obs, step=step, episode=run.stats.episodes)
    return recorder
