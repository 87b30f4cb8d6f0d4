"""The trainer's state as a checkpoint holds it: :func:`capture` (weights, optimisers, RNG
states, env states, episode tallies, wall time, log position) and :func:`restore`; and the
boundary of the update under way (:class:`UpdateBoundary`), which a stop rewinds to.

The keys and values are the checkpoint format (:mod:`a2cm_phys.training.checkpoint`):
checkpoints of earlier versions must keep loading.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..config import to_dict
from .episode_stats import EpisodeStats

if TYPE_CHECKING:
    import numpy as np

    from ..envs.vector import VectorEnv
    from .opponents import OpponentPool
    from .trainer import Trainer

ROLLOUT, LEARN, IDLE = "rollout", "learn", "idle"
"""The phases of an update (:attr:`UpdateBoundary.phase`)."""


def capture(trainer: Trainer) -> dict[str, Any]:
    """Everything a resume needs, as a dict for :func:`a2cm_phys.training.checkpoint.save`."""
    recorder = trainer.recorder
    return {
        "scenario": to_dict(trainer.scenario),
        "train": to_dict(trainer.cfg),
        "update": trainer.update,
        "learner": trainer.learner.state_dict(),
        "evader_learner": None if trainer.evader is None else trainer.evader.learner.state_dict(),
        "rng": trainer.rng.bit_generator.state,
        "pool": None if trainer.pool is None else trainer.pool.state_dict(),
        "descent": None if trainer.descent is None else trainer.descent.state_dict(),
        "env": trainer.env.state(),
        "stats": trainer.stats.state(),
        "wall_time": trainer.wall_time(),
        # the log is durable up to this episode count when the checkpoint is written
        "log": {
            "record": trainer.record,
            "log_every": trainer.log_every,
            "scene_every": trainer.scene_every,
            "part": None if recorder is None else recorder.path.name,
            "episodes": trainer.stats.episodes,
        },
    }


def restore(trainer: Trainer, state: dict[str, Any]) -> None:
    """Continue ``trainer`` from a :func:`capture` of the same scenario and num_envs."""
    trainer.learner.load_state_dict(state["learner"])
    if trainer.evader is not None:
        trainer.evader.learner.load_state_dict(state["evader_learner"])
    trainer.rng.bit_generator.state = state["rng"]
    if trainer.pool is not None:
        trainer.pool.load_state_dict(state["pool"])
    if trainer.descent is not None:
        trainer.descent.load_state_dict(state["descent"])
    trainer.obs = trainer.env.load_state(state["env"])
    trainer.stats = EpisodeStats.from_state(state["stats"])
    trainer.update = trainer.saved_update = int(state["update"])
    trainer.clock.resume(float(state["wall_time"]))


class UpdateBoundary:
    """Where the update under way stands (:attr:`phase`: rollout, learn or idle) and what
    its rollout changes, as it was at its start: a stop mid-rollout saves the state of the
    last whole update; a stop mid-learn saves nothing (the weights could be half-stepped)."""

    def __init__(self) -> None:
        self.phase = IDLE
        self.start: tuple[Any, ...] = ()  # env, rng and pool states at the update's start

    def enter_rollout(
        self, env: VectorEnv, rng: np.random.Generator, pool: OpponentPool | None
    ) -> None:
        """Note the states the rollout is about to change, then enter it."""
        pool_state = None if pool is None else pool.state_dict()
        self.start = (env.state(), rng.bit_generator.state, pool_state)
        self.phase = ROLLOUT


def state_at_last_update(trainer: Trainer) -> dict[str, Any]:
    """:func:`capture` as of the end of the last whole update (not mid-learn)."""
    state = capture(trainer)
    if trainer.boundary.phase == ROLLOUT:
        state["env"], state["rng"], state["pool"] = trainer.boundary.start
    return state
