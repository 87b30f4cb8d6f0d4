"""The trainer's episode log: one new part of the run's MCAP log per session."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..config import to_dict
from ..record.parts import new_part, part_files
from ..record.writer import EpisodeRecorder

if TYPE_CHECKING:
    from .trainer import Trainer


def open_recorder(trainer: Trainer) -> EpisodeRecorder:
    """The run's MCAP recorder for this session (a new part of its log).

    The one call site of :mod:`a2cm_phys.record`: the recorder gets ``start(env, obs)``,
    ``record_step(actions, step)`` after every vector step and ``record_update(update,
    metrics)`` after every update.
    """
    # A resumed session continues the log in a file of its own (an earlier one may have been
    # cut short by a crash, or got ahead of the checkpoint), on the same clock and episode
    # ids; readers let each part supersede what earlier parts logged from its start on. The
    # games caught mid-episode get a summary without a trajectory.
    step = trainer.update * trainer.cfg.steps_per_env
    path, session = new_part(trainer.run_dir, trainer.update)
    part = {
        "session": session,
        "update": trainer.update,
        "episode": trainer.stats.episodes,
        "step": step,
        "after": [p.name for p in part_files(trainer.run_dir)],
    }
    recorder = EpisodeRecorder(
        path,
        trainer.scenario,
        {"train": to_dict(trainer.cfg), "part": part},
        log_every=trainer.log_every,
        scene_every=trainer.scene_every,
    )
    recorder.start(trainer.env, trainer.obs, step=step, episode=trainer.stats.episodes)
    return recorder
