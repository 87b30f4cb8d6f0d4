"""What a run holds while it trains (:class:`RunState`), with its clock across sessions
(:class:`SessionClock`) and the boundary of the update under way (:class:`UpdateBoundary`).

:class:`~.trainer.Trainer` builds a run's state and drives it; the modules of an update
and a session (:mod:`.update`, :mod:`.session`, :mod:`.run_state`, :mod:`.summary`,
:mod:`.progress`, :mod:`.recording`) read and advance it, and know nothing of the trainer.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from ..algos import ActorCritic, Learner
    from ..config import Scenario, Train
    from ..envs.vector import VectorEnv
    from .descent import ExploitabilityDescent
    from .episode_stats import EpisodeStats
    from .live import LiveView
    from .loggers import MetricsLogger
    from .opponents import OpponentPool, Pairing
    from .signals import StopSignals
    from .teams import Team

ROLLOUT, LEARN, IDLE = "rollout", "learn", "idle"
"""The phases of an update (:attr:`UpdateBoundary.phase`)."""


class SessionClock:
    """The run's wall time over all its sessions, and this session's steps and speed."""

    def __init__(self) -> None:
        self.before = 0.0  # wall time of earlier sessions of this run
        self.start = time.perf_counter()
        self.steps = 0  # environment steps of this session

    def resume(self, before: float) -> None:
        """Continue a run that spent ``before`` seconds in earlier sessions, from now."""
        self.before, self.start = before, time.perf_counter()

    def wall_time(self) -> float:
        """Seconds spent training in this run, over all sessions."""
        return self.before + time.perf_counter() - self.start

    def speed(self, now: float) -> float:
        """Environment steps per second of wall time in this session, up to ``now``."""
        return self.steps / max(now - self.start, 1e-9)


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


class RunState:
    """One run's state while it trains: its settings, games, teams, self-play machinery,
    episode tallies, clock, and where its checkpoints and log stand."""

    scenario: Scenario
    cfg: Train
    """The resolved training settings (:func:`~a2cm_phys.config.resolve_train`)."""
    run_dir: Path
    record: bool
    """Whether the run writes its MCAP episode log."""
    log_every: int
    scene_every: int
    progress: bool
    """Whether a progress bar shows on stderr."""
    checkpoint_seconds: float
    checkpoint_every: int
    env: VectorEnv
    pursuers: Team
    evader: Team | None
    """The learned evader's team (``None``: the scenario's evader is scripted)."""
    rng: np.random.Generator
    """The rollouts' action sampling."""
    pool: OpponentPool | None
    pairing: Pairing
    """Who plays the update under way (latest against latest without a pool)."""
    descent: ExploitabilityDescent | None
    stats: EpisodeStats
    update: int
    """Updates taken."""
    last_metrics: dict[str, float]
    obs: np.ndarray
    """The games' observations after the last step."""
    clock: SessionClock
    saved_update: int
    """The update of the checkpoint on disk (-1: none yet)."""
    stop_reason: str
    stop_signal: int | None
    """The signal that stopped an interrupted session."""
    last_summary: dict[str, Any]
    last_save: float
    boundary: UpdateBoundary
    recorder: Any
    """The episode recorder while a session records (``None`` otherwise)."""
    open_episodes: dict | None
    """The episodes a resumed checkpoint carried, running, with their steps so far (for the
    recorder: :meth:`~a2cm_phys.record.writer.EpisodeRecorder.open_episodes`)."""
    signals: StopSignals | None
    """The stop signals while a session runs."""
    resume_note: str | None
    """Why a resume fell back to the previous checkpoint, if it did."""
    live: LiveView | None
    """The live view the run streams to (``train --live``), or ``None``."""
    loggers: list[MetricsLogger]
    """The other views of its numbers (``train --logger``): each session starts them and
    closes them at its end."""

    @property
    def model(self) -> ActorCritic:
        """The pursuers' actor–critic."""
        return self.pursuers.model

    @property
    def learner(self) -> Learner:
        """The pursuers' learner."""
        return self.pursuers.learner

    @property
    def batch(self) -> dict[str, np.ndarray]:
        """The pursuers' rollout batch."""
        return self.pursuers.batch

    @property
    def finished(self) -> bool:
        """Whether the run has taken all its updates."""
        return self.update >= self.cfg.updates

    def wall_time(self) -> float:
        """Seconds spent training in this run, over all sessions."""
        return self.clock.wall_time()

    def session_speed(self, now: float) -> float:
        """Environment steps per second of wall time in this session, up to ``now``."""
        return self.clock.speed(now)

    def evader_descends(self) -> bool:
        """Whether the learned evader learns by exploitability descent (not its rollouts)."""
        return self.descent is not None and self.descent.evader is not None
