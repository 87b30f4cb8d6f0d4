"""The training loop of one run: :class:`Trainer` (env, model, learner, checkpoints, log).

One trainer for both algorithms; only the model differs (``make_model``: one critic for
A2CM, N for A2C). Each update collects ``batch_size`` steps (``batch_size / num_envs`` per
game) and takes one learner step per team (:mod:`a2cm_phys.training.teams`: the pursuers, and a
learned evader when the scenario has one). The command line over it is
:mod:`a2cm_phys.train`.

The trainer takes a resolved config (:func:`~a2cm_phys.config.resolve_train`, where the
options were checked). Its rooms, in the order a run passes through them: its
construction (teams, :mod:`.selfplay`), each update (the rollout, then
:mod:`.update`), a session's loop with its stops, checkpoints and summary
(:mod:`.session`), the state a checkpoint holds (:mod:`.run_state`) and where a resumed run
starts (:mod:`.resume`).

``Trainer.resume`` continues bit for bit in grid mode (an interrupted and resumed run
ends with the same weights and episode statistics as an uninterrupted one). In physics
mode the games running at the checkpoint are restarted on resume unless the physics core
can save its state (see :meth:`a2cm_phys.envs.vector.VectorEnv.state`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from ..config import Scenario, Train
from ..envs.vector import VectorEnv
from .episode_stats import EpisodeStats
from .loggers import MetricsLogger, make_loggers
from .opponents import LATEST, Pairing
from .resume import resume_point
from .rollout import StepHook, collect
from .run_state import capture, restore
from .seeding import policy_rng
from .selfplay import make_descent, make_pool
from .session import run_session, save_checkpoint
from .signals import StopSignals
from .state import IDLE, LEARN, RunState, SessionClock, UpdateBoundary
from .summary import run_summary
from .teams import make_teams
from .update import learn, players

if TYPE_CHECKING:
    from .live import LiveView

__all__ = ["Trainer"]


class Trainer(RunState):
    """Owns one run: env, model, learner, sampling rng, episode tallies and the run directory
    (its state, :class:`~.state.RunState`), and drives it update by update.

    Args:
        scenario: the game to train on.
        cfg: training settings, resolved for ``scenario`` by
            :func:`~a2cm_phys.config.resolve_train` (which checked them).
        run_dir: where checkpoints, summary and logs go (must exist).
        record: write the MCAP episode log (``episodes.mcap``) when the recorder exists.
        log_every, scene_every: passed to the episode recorder.
        progress: report progress on stderr (:mod:`.progress`: a bar on a terminal, a
            plain line every 30 s elsewhere).
        checkpoint_seconds: save a checkpoint at least this often (wall time).
        checkpoint_every: also save every this many updates (0: time-based only).
        live: the live view to stream to (``train --live``).
        loggers: the other views of the run's numbers, which each session starts and
            closes: ``train --logger`` names (``tensorboard``, ``wandb``, ``csv``; a
            library not installed is a ``UserError``) or loggers. They change nothing of
            the run.
    """

    def __init__(
        self,
        scenario: Scenario,
        cfg: Train,
        run_dir: str | Path,
        *,
        record: bool = True,
        log_every: int = 1,
        scene_every: int = 0,
        progress: bool = False,
        checkpoint_seconds: float = 30.0,
        checkpoint_every: int = 0,
        live: LiveView | None = None,
        loggers: Sequence[str | MetricsLogger] = (),
    ) -> None:
        torch.set_num_threads(cfg.threads)
        self.live = live
        self.scenario, self.cfg, self.run_dir = scenario, cfg, Path(run_dir)
        self.loggers = make_loggers(loggers, self.run_dir, cfg)  # before the games start
        self.record, self.log_every, self.scene_every = record, log_every, scene_every
        self.progress = progress
        self.checkpoint_seconds, self.checkpoint_every = checkpoint_seconds, checkpoint_every
        self.env = VectorEnv(scenario, cfg.num_envs, workers=cfg.workers)
        self.pursuers, self.evader = make_teams(scenario, cfg)
        self.rng = policy_rng(cfg.seed)
        self.pool = make_pool(cfg, self.model, self.evader)  # None: simultaneous self-play
        self.pairing: Pairing = LATEST
        self.descent = make_descent(scenario, cfg, self.model, self.evader)
        self.stats = EpisodeStats()
        self.update = 0
        self.last_metrics: dict[str, float] = {}
        self.obs = self.env.reset(cfg.seed)
        self.clock = SessionClock()
        self.saved_update = -1  # update of the checkpoint on disk (-1: none yet)
        self.stop_reason = ""
        self.stop_signal: int | None = None  # the signal that stopped an interrupted run
        self.last_summary: dict[str, Any] = {}
        self.last_save = time.perf_counter()
        self.boundary = UpdateBoundary()
        self.recorder: Any = None  # the episode recorder while run() records
        self.open_episodes: dict | None = None  # set by resume(): running episodes carried
        self.signals: StopSignals | None = None  # the stop signals while run() runs
        self.resume_note: str | None = None  # set by resume() when it fell back

    def checkpoint_state(self) -> dict[str, Any]:
        """Everything a resume needs (:func:`.run_state.capture`)."""
        return capture(self)

    def load_checkpoint_state(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`checkpoint_state` (same scenario and num_envs)."""
        restore(self, state)

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        updates: int | None = None,
        *,
        record: bool | None = None,
        log_every: int | None = None,
        scene_every: int | None = None,
        **kwargs: Any,
    ) -> Trainer:
        """A trainer continuing the run in ``run_dir``, optionally extended to ``updates``,
        from where :func:`.resume.resume_point` says (:attr:`resume_note` says so when it
        fell back to the previous checkpoint); ``kwargs`` go to the constructor."""
        at = resume_point(
            run_dir, updates, record=record, log_every=log_every, scene_every=scene_every
        )
        trainer = cls(at.scenario, at.cfg, at.run_dir, **at.log, **kwargs)
        if at.state is not None:
            trainer.load_checkpoint_state(at.state)
        trainer.resume_note = at.note
        return trainer

    def save_checkpoint(self, state: dict[str, Any] | None = None) -> None:
        """Write the checkpoint from ``state`` or the current state, after making the log
        durable up to it (:func:`.session.save_checkpoint`)."""
        save_checkpoint(self, state)

    def run(self) -> str:
        """Train up to ``cfg.updates``; return ``"done"``, ``"interrupted"``, ``"nonfinite"``,
        ``"worker_died"`` or ``"no_space"``: how the session ended, and what each leaves on
        disk, is :func:`.session.run_session`'s. :attr:`stop_reason` names what stopped it
        (the file, the worker, the loss), :attr:`stop_signal` the signal."""
        return run_session(self, self._one_update)

    def _one_update(self, on_step: StepHook | None) -> None:
        """One update: the rollout of ``batch_size`` steps, the teams' learner steps, then
        the tallies (tests wrap this method to stop a run at a chosen update)."""
        pool = self.pool
        self.boundary.enter_rollout(self.env, self.rng, pool)  # a stop mid-rollout rewinds
        self.pairing = pairing = LATEST if pool is None else pool.draw()
        pursuers, evader = players(self, pairing)
        obs, episodes = collect(self.env, pursuers, self.obs, self.rng, self.batch, on_step, evader)
        self.boundary.phase = LEARN
        self.last_metrics = {}
        learn(self, pairing, self.last_metrics)
        self.obs = obs
        self.stats.add(episodes)
        self.update += 1
        if pool is not None and self.update % self.cfg.pool_every == 0:
            pool.add(self.update)
        self.clock.steps += self.cfg.batch_size
        self.boundary.phase = IDLE

    def close(self) -> None:
        """Release the environment (stops physics worker processes, if any)."""
        self.env.close()

    def summary(self, status: str = "done") -> dict[str, Any]:
        """Run statistics (:func:`.summary.run_summary`)."""
        return run_summary(self, status)
