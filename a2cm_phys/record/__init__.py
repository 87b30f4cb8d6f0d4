"""Run logs: the MCAP writer the trainer calls and the reader ``replay``/``plot`` use.

Writing (see :class:`EpisodeRecorder`)::

    with EpisodeRecorder(run_dir / "episodes.mcap", scenario, {"train": to_dict(cfg)}) as rec:
        rec.start(vec_env)                      # right after vec_env.reset(seed)
        ...
        step = vec_env.step(actions)
        rec.record_step(actions, step)          # after every vector step
        ...
        rec.record_update(update, metrics)      # after every learner update

Reading: ``log = read_run(run_dir)`` gives the metadata, the scenario, every episode's
summary (column-wise), the updates and the logged trajectories, also from a file cut short
by a crash (``log.clean`` is then ``False``). Topics and schemas: :mod:`.schemas`.
(The folder is not named ``logs/``: that is where runs land.)
"""

from __future__ import annotations

from .parts import read_run
from .runlog import LogError, RunLog, Trajectory
from .schemas import SUMMARY_TOPIC, TRAJECTORY_TOPIC, UPDATE_TOPIC, scene_topic
from .writer import EpisodeRecorder

__all__ = [
    "SUMMARY_TOPIC",
    "TRAJECTORY_TOPIC",
    "UPDATE_TOPIC",
    "EpisodeRecorder",
    "LogError",
    "RunLog",
    "Trajectory",
    "read_run",
    "scene_topic",
]
