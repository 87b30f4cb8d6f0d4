"""A run's state as a checkpoint holds it: :func:`capture` (weights, optimisers, RNG
states, env states, episode tallies, wall time, log position), :func:`restore`, and
:func:`state_at_last_update`, which rewinds a stop mid-rollout to the update's start.

The keys and values are the checkpoint format (:mod:`a2cm_phys.training.checkpoint`):
checkpoints of earlier versions must keep loading.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..config import to_dict
from .episode_stats import EpisodeStats
from .state import ROLLOUT, RunState


def capture(run: RunState) -> dict[str, Any]:
    """Everything a resume needs, as a dict for :func:`a2cm_phys.training.checkpoint.save`."""
    recorder = run.recorder
    env = run.env.state()
    # the episodes running now, with their steps so far, logged whole after a resume (none
    # where the env's games restart on resume: physics)
    carried = None if recorder is None or env.get("core") is None else recorder.open_episodes()
    return {
        "scenario": to_dict(run.scenario),
        "train": to_dict(run.cfg),
        "update": run.update,
        "learner": run.learner.state_dict(),
        "evader_learner": None if run.evader is None else run.evader.learner.state_dict(),
        "rng": run.rng.bit_generator.state,
        "pool": None if run.pool is None else run.pool.state_dict(),
        "descent": None if run.descent is None else run.descent.state_dict(),
        "env": env,
        "stats": run.stats.state(),
        "wall_time": run.wall_time(),
        "memory": _memories(run, lambda team: team.policy.start(len(team.batch["memory"]))),
        # the log is durable up to this episode count when the checkpoint is written
        "log": {
            "record": run.record,
            "log_every": run.log_every,
            "scene_every": run.scene_every,
            "part": None if recorder is None else recorder.path.name,
            "episodes": run.stats.episodes,
            "open": carried,
        },
    }


def restore(run: RunState, state: dict[str, Any]) -> None:
    """Continue ``run`` from a :func:`capture` of the same scenario and num_envs."""
    run.learner.load_state_dict(state["learner"])
    if run.evader is not None:
        run.evader.learner.load_state_dict(state["evader_learner"])
    run.rng.bit_generator.state = state["rng"]
    if run.pool is not None:
        run.pool.load_state_dict(state["pool"])
    if run.descent is not None:
        run.descent.load_state_dict(state["descent"])
    run.obs = run.env.load_state(state["env"])
    run.stats = EpisodeStats.from_state(state["stats"])
    run.update = run.saved_update = int(state["update"])
    run.clock.resume(float(state["wall_time"]))
    memory = state.get("memory") or {}
    fresh = state["env"].get("core") is None  # every game restarted: nothing to remember
    run.open_episodes = None if fresh else state.get("log", {}).get("open")
    for team in (run.pursuers, run.evader):
        if team is not None and team.model.recurrent:
            kept = np.asarray(memory[team.name], dtype=np.float32)
            team.policy.start(len(kept))[:] = 0.0 if fresh else kept


def _memories(run: RunState, of) -> dict[str, Any] | None:
    """Each recurrent team's memories, ``of(team)`` (``None`` without recurrent actors)."""
    teams = [t for t in (run.pursuers, run.evader) if t is not None and t.model.recurrent]
    return {team.name: np.array(of(team)) for team in teams} or None


def state_at_last_update(run: RunState) -> dict[str, Any]:
    """:func:`capture` as of the end of the last whole update (not mid-learn)."""
    state = capture(run)
    if run.boundary.phase == ROLLOUT:
        state["env"], state["rng"], state["pool"] = run.boundary.start
        state["memory"] = _memories(run, lambda team: team.batch["memory"])
    return state
