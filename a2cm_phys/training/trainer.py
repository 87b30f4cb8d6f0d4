"""The training loop of one run: :class:`Trainer` (env, model, learner, checkpoints, log).

One trainer for both algorithms; only the model differs (``make_model``: one critic for
A2CM, N for A2C). Each update collects ``batch_size`` steps (``batch_size / num_envs`` per
game) and takes one learner step per team (:mod:`a2cm_phys.training.teams`: the pursuers, and a
learned evader when the scenario has one). The command line over it is
:mod:`a2cm_phys.train`.

``Trainer.resume`` continues bit for bit in grid mode (an interrupted and resumed run
ends with the same weights and episode statistics as an uninterrupted one). In physics
mode the games running at the checkpoint are restarted on resume unless the physics core
can save its state (see :meth:`a2cm_phys.envs.vector.VectorEnv.state`).
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import torch
from threadpoolctl import threadpool_limits

from ..algos import NonFiniteLoss
from ..base.exitcodes import OUT_OF_SPACE
from ..config import (
    ConfigError,
    Scenario,
    Train,
    build,
    load_train,
    resolve_train,
    stored_train,
    to_dict,
)
from ..envs.vector import VectorEnv
from . import checkpoint
from .descent import ExploitabilityDescent, check_descent
from .episode_stats import EpisodeStats
from .exploitability import exploitability, solvable
from .opponents import LATEST, PAIRING_CODES, OpponentPool, Pairing, check_pool
from .progress import ProgressBar
from .recording import open_recorder
from .rollout import StepHook, collect
from .rundir import CONFIG_NAME, read_config
from .seeding import policy_rng
from .signals import ShieldedLog, StopSignals, signals_deferred
from .summary import run_summary, write_summary
from .teams import make_teams

_ROLLOUT, _LEARN, _IDLE = "rollout", "learn", "idle"


def check_seed(cfg: Train) -> None:
    """Seeds seed numpy generators, which need ``seed >= 0``: a :class:`ConfigError` if not."""
    if cfg.seed < 0:
        raise ConfigError(f"training options: key 'seed': must be >= 0, got {cfg.seed}")


def check_workers(scenario: Scenario, cfg: Train) -> None:
    """A physics run splits its games across ``workers`` processes, so it needs at least as
    many games: a :class:`ConfigError` if not (grid mode ignores ``workers``)."""
    if scenario.mode == "physics" and cfg.workers > cfg.num_envs:
        raise ConfigError(
            f"training options: key 'workers': {cfg.workers} processes for num_envs="
            f"{cfg.num_envs} games; use at most num_envs workers (or more --num-envs)"
        )


def check_run(scenario: Scenario, cfg: Train) -> None:
    """Every check of training options against the scenario, before anything is built: a
    :class:`ConfigError` naming the first key at fault."""
    check_seed(cfg)
    check_workers(scenario, cfg)
    check_pool(scenario, cfg)
    check_descent(scenario, cfg)


class Trainer:
    """Owns one run: env, model, learner, sampling rng, episode tallies and the run directory.

    Args:
        scenario: the game to train on.
        cfg: training settings (validated :class:`~a2cm_phys.config.Train`).
        run_dir: where checkpoints, summary and logs go (must exist).
        record: write the MCAP episode log (``episodes.mcap``) when the recorder exists.
        log_every, scene_every: passed to the episode recorder.
        progress: show a tqdm bar on stderr.
        checkpoint_seconds: save a checkpoint at least this often (wall time).
        checkpoint_every: also save every this many updates (0: time-based only).
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
    ) -> None:
        cfg = resolve_train(scenario, cfg)
        check_run(scenario, cfg)
        torch.set_num_threads(cfg.threads)
        self.scenario, self.cfg, self.run_dir = scenario, cfg, Path(run_dir)
        self.record, self.log_every, self.scene_every = record, log_every, scene_every
        self.progress = progress
        self.checkpoint_seconds, self.checkpoint_every = checkpoint_seconds, checkpoint_every
        self.env = VectorEnv(scenario, cfg.num_envs, workers=cfg.workers)
        self.pursuers, self.evader = make_teams(scenario, cfg)
        self.model, self.learner = self.pursuers.model, self.pursuers.learner
        self.batch = self.pursuers.batch
        self.rng = policy_rng(cfg.seed)
        self.pool = (  # fictitious self-play (a2cm_phys.training.opponents); None: simultaneous
            OpponentPool(self.model, self.evader.model, cfg.pool_size, cfg.pool_latest, cfg.seed)
            if cfg.pool_every and self.evader is not None
            else None
        )
        self.pairing: Pairing = LATEST
        self.descent = (  # grid self-play against the exact best response (training/descent.py)
            ExploitabilityDescent(
                scenario,
                cfg,
                self.model,
                cfg.seed,
                None if self.evader is None else self.evader.model,
            )
            if cfg.descent_every
            else None
        )
        self.stats = EpisodeStats()
        self.update = 0
        self.last_metrics: dict[str, float] = {}
        self.obs = self.env.reset(cfg.seed)
        self._wall_before = 0.0  # wall time of earlier sessions of this run
        self._session_start = time.perf_counter()
        self._session_steps = 0
        self.saved_update = -1  # update of the checkpoint on disk (-1: none yet)
        self.stop_reason = ""
        self.last_summary: dict[str, Any] = {}
        self._last_save = time.perf_counter()
        self._phase = _IDLE
        self._log: Any = None  # the episode recorder while run() records
        self._signals: StopSignals | None = None  # the stop signals while run() runs
        self.resume_note: str | None = None  # set by resume() when it fell back

    # ------------------------------------------------------------------ state
    def checkpoint_state(self) -> dict[str, Any]:
        """Everything a resume needs, as a dict for :func:`a2cm_phys.training.checkpoint.save`."""
        return {
            "scenario": to_dict(self.scenario),
            "train": to_dict(self.cfg),
            "update": self.update,
            "learner": self.learner.state_dict(),
            "evader_learner": None if self.evader is None else self.evader.learner.state_dict(),
            "rng": self.rng.bit_generator.state,
            "pool": None if self.pool is None else self.pool.state_dict(),
            "descent": None if self.descent is None else self.descent.state_dict(),
            "env": self.env.state(),
            "stats": self.stats.state(),
            "wall_time": self.wall_time(),
            # the log is durable up to this episode count when the checkpoint is written
            "log": {
                "record": self.record,
                "log_every": self.log_every,
                "scene_every": self.scene_every,
                "part": None if self._log is None else self._log.path.name,
                "episodes": self.stats.episodes,
            },
        }

    def load_checkpoint_state(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`checkpoint_state` (same scenario and num_envs)."""
        self.learner.load_state_dict(state["learner"])
        if self.evader is not None:
            self.evader.learner.load_state_dict(state["evader_learner"])
        self.rng.bit_generator.state = state["rng"]
        if self.pool is not None:
            self.pool.load_state_dict(state["pool"])
        if self.descent is not None:
            self.descent.load_state_dict(state["descent"])
        self.obs = self.env.load_state(state["env"])
        self.stats = EpisodeStats.from_state(state["stats"])
        self.update = self.saved_update = int(state["update"])
        self._wall_before = float(state["wall_time"])
        self._session_start = time.perf_counter()

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
        """A trainer continuing the run in ``run_dir``, optionally extended to ``updates``.

        It continues from the latest good checkpoint (the previous one if the latest is
        damaged: :attr:`resume_note` then says so), or from update 0 with the run's
        ``config.json`` if the run never saved one. ``record``, ``log_every`` and
        ``scene_every`` left ``None`` keep the run's own; a run that logs cannot be
        resumed without its log (that would lose episodes).
        """
        run_dir = Path(run_dir)
        if run_dir.is_file():  # the checkpoint itself was given
            run_dir = run_dir.parent
        try:
            state, note = checkpoint.load_latest(run_dir)
        except FileNotFoundError as err:
            state, note = None, None
            if not (run_dir / CONFIG_NAME).is_file():
                raise ConfigError(f"--resume: {err}") from None
        except (OSError, ValueError) as err:
            raise ConfigError(f"--resume: {err}") from None
        stored, where = _stored_run(run_dir, state)
        scenario = build(Scenario, stored["scenario"], where)
        train = stored_train(stored["train"])  # written before some options existed?
        at = 0 if state is None else state["update"]
        if updates is not None:
            if updates < at:
                raise ConfigError(f"--updates {updates}: the run is at update {at} already")
            train["updates"] = updates
        cfg = load_train(train, where)
        log = (state or {}).get("log") or {}
        was_recording = bool(log.get("record", True))
        if record is False and was_recording:
            raise ConfigError(
                f"--no-record: {run_dir} logs its episodes; a session without its log would"
                " lose them (resume it without --no-record)"
            )
        kwargs.update(
            record=was_recording if record is None else record and was_recording,
            log_every=log.get("log_every", 1) if log_every is None else log_every,
            scene_every=log.get("scene_every", 0) if scene_every is None else scene_every,
        )
        trainer = cls(scenario, cfg, run_dir, **kwargs)
        if state is not None:
            trainer.load_checkpoint_state(state)
        trainer.resume_note = note
        return trainer

    def close(self) -> None:
        """Release the environment (stops physics worker processes, if any)."""
        self.env.close()

    def wall_time(self) -> float:
        """Seconds spent training in this run, over all sessions."""
        return self._wall_before + time.perf_counter() - self._session_start

    @property
    def finished(self) -> bool:
        """Whether the run has taken all its updates."""
        return self.update >= self.cfg.updates

    def save_checkpoint(self, state: dict[str, Any] | None = None) -> None:
        """Write the checkpoint (atomically) from ``state`` or the current state, after
        making the log durable up to it: every episode the checkpoint counts is on disk
        before the checkpoint is (see ``docs/design.md``, the run's invariant)."""
        state = state if state is not None else self.checkpoint_state()
        signals = self._signals
        if signals is not None:  # a second Ctrl-C waits for the end of the save
            signals.in_log = True
        try:
            if self._log is not None:
                self._log.flush(durable=True)
            checkpoint.save(self.run_dir / checkpoint.CHECKPOINT_NAME, state)
            self.saved_update = int(state["update"])
            self._last_save = time.perf_counter()
        finally:
            if signals is not None:
                signals.after_log()

    # ------------------------------------------------------------------ training
    def run(self) -> str:
        """Train up to ``cfg.updates``; return ``"done"``, ``"interrupted"``, ``"nonfinite"``,
        ``"worker_died"`` or ``"no_space"`` (a write failed for want of space: the last good
        checkpoint is kept, consistent with the log; :attr:`stop_reason` names the file).

        The first Ctrl-C or SIGTERM stops at the end of the current update (a second one
        stops at once, but never in the middle of writing the log); either way the
        checkpoint holds the state after the last whole update. Once stopping, while the
        checkpoint, the log and the summary are written, further signals are ignored. A
        non-finite loss stops the run without overwriting the last good checkpoint. A
        physics worker that dies stops the run with the checkpoint at the last whole update
        (:attr:`stop_reason` names the worker). :attr:`stop_signal` is the signal that
        stopped an interrupted run. The run directory is created if it does not exist.
        """
        self.run_dir.mkdir(parents=True, exist_ok=True)
        status = "done"
        # numpy's BLAS too gets the run's threads (it starts one per core otherwise: two
        # runs on two cores would then run four threads)
        with threadpool_limits(limits=self.cfg.threads), signals_deferred() as signals:
            self._signals = signals
            try:
                if not (self.run_dir / checkpoint.CHECKPOINT_NAME).exists():
                    self.save_checkpoint()  # so there is always a last good checkpoint
                self._last_save = time.perf_counter()
                status = self._train(signals)
            except OSError as err:
                if err.errno not in OUT_OF_SPACE:
                    raise
                signals.shield()
                status, self.stop_reason = "no_space", _os_error_text(err)
            self.stop_signal = signals.received
            try:
                self.last_summary = self.summary(status)
                write_summary(self.run_dir, self.last_summary)
            except OSError as err:
                if err.errno not in OUT_OF_SPACE:
                    raise
                status = "no_space"
                self.stop_reason = self.stop_reason or _os_error_text(err)
            finally:
                self._signals = None
        return status

    def _train(self, signals: StopSignals) -> str:
        """The loop of :meth:`run` with the log open; the status it stopped with."""
        dead_worker = _worker_error(self.scenario)
        status, save = "done", None
        with self._recorder() as recorder, self._bar() as bar:
            self._log = recorder
            log = ShieldedLog(recorder, signals) if recorder is not None else None
            on_step = log.record_step if log is not None else None
            try:
                while self.update < self.cfg.updates:
                    if signals.stop_requested:
                        raise KeyboardInterrupt
                    self._one_update(on_step)
                    if log is not None:
                        log.record_update(self.update, self.last_metrics)
                    bar.tick()
                    self._maybe_save()
            except KeyboardInterrupt:
                status = "interrupted"
                if self._phase != _LEARN:  # mid-update weights could be half-stepped
                    save = self._state_at_last_update()
            except NonFiniteLoss as err:
                status, self.stop_reason = "nonfinite", str(err)
            except dead_worker as err:
                status, self.stop_reason = "worker_died", str(err).splitlines()[0]
                save = self._state_at_last_update()
            except OSError as err:
                if err.errno not in OUT_OF_SPACE:
                    raise
                status, self.stop_reason = "no_space", _os_error_text(err)
            else:  # (a finished run resumed for nothing keeps its checkpoints as they are)
                save = self.checkpoint_state() if self.update != self.saved_update else None
            signals.shield()
            try:
                if save is not None:
                    self.save_checkpoint(save)
            except OSError as err:
                if err.errno not in OUT_OF_SPACE:
                    raise
                status, self.stop_reason = "no_space", _os_error_text(err)
            finally:
                self._log = None
            if status == "no_space" and recorder is not None:
                recorder.abandon()  # writing more would fail too; the checkpoint's part is durable
        return status

    def _one_update(self, on_step: StepHook | None) -> None:
        # Snapshot so that an interrupt inside the rollout can rewind to the update boundary.
        pool = self.pool
        self._boundary = (
            self.env.state(),
            self.rng.bit_generator.state,
            None if pool is None else pool.state_dict(),
        )
        self._phase = _ROLLOUT
        self.pairing = pairing = LATEST if pool is None else pool.draw()
        pursuers = self.model if pool is None else pool.player("pursuers", pairing)
        evader = None
        if self.evader is not None:
            player = self.evader.model if pool is None else pool.player("evader", pairing)
            evader = (player.act, self.evader.batch)
        obs, episodes = collect(
            self.env, pursuers.act, self.obs, self.rng, self.batch, on_step, evader
        )
        self._phase = _LEARN
        progress = self.update / self.cfg.updates
        self.last_metrics = {}
        if pairing.learns("pursuers") and self.descent is None:  # else: by descent, below
            self.last_metrics = self.learner.update(self.batch, progress)
        if self.evader is not None and pairing.learns("evader") and not self.evader_descends():
            evader_metrics = self.evader.learner.update(self.evader.batch, progress)
            self.last_metrics.update({f"evader_{k}": v for k, v in evader_metrics.items()})
        if pool is not None:  # who played: see a2cm_phys.training.opponents.PAIRING_CODES
            self.last_metrics["pool_pairing"] = PAIRING_CODES[pairing.kind]
            self.last_metrics["pool_snapshot_update"] = pairing.taken_at
        every = self.cfg.descent_every
        if self.descent is not None and (self.update + 1) % every == 0:
            self.last_metrics.update(self.descent.step())
        every = self.cfg.exploit_every
        if every and (self.update + 1) % every == 0 and solvable(self.scenario):
            assert self.evader is not None
            self.last_metrics.update(exploitability(self.scenario, self.model, self.evader.model))
        self.obs = obs
        self.stats.add(episodes)
        self.update += 1
        if pool is not None and self.update % self.cfg.pool_every == 0:
            pool.add(self.update)
        self._session_steps += self.cfg.batch_size
        self._phase = _IDLE

    def _state_at_last_update(self) -> dict[str, Any]:
        state = self.checkpoint_state()
        if self._phase == _ROLLOUT:
            state["env"], state["rng"], state["pool"] = self._boundary
        return state

    def _maybe_save(self) -> None:
        every = self.checkpoint_every
        due = every and self.update % every == 0
        if due or time.perf_counter() - self._last_save >= self.checkpoint_seconds:
            self.save_checkpoint()

    def _recorder(self) -> Any:
        """The MCAP episode recorder, or a null context when the run does not record (or
        has nothing left to train: a finished run gets no new, empty part)."""
        recorder = open_recorder(self) if self.record and not self.finished else None
        return recorder if recorder is not None else nullcontext()

    def _bar(self) -> ProgressBar:
        return ProgressBar(self) if self.progress else ProgressBar(None)

    def summary(self, status: str = "done") -> dict[str, Any]:
        """Run statistics (:func:`.summary.run_summary`)."""
        return run_summary(self, status)

    def session_speed(self, now: float) -> float:
        """Environment steps per second of wall time in this session, up to ``now``."""
        return self._session_steps / max(now - self._session_start, 1e-9)

    def evader_descends(self) -> bool:
        """Whether the learned evader learns by exploitability descent (not its rollouts)."""
        return self.descent is not None and self.descent.evader is not None


def _os_error_text(err: OSError) -> str:
    """``FILE: reason`` of a failed write."""
    where = f"{err.filename}: " if err.filename else ""
    return f"{where}{err.strerror or err}"


def _stored_run(run_dir: Path, state: dict[str, Any] | None) -> tuple[dict[str, Any], str]:
    """The scenario and training options to resume with, and where they come from: the
    checkpoint, or ``config.json`` for a run that never saved one."""
    if state is not None:
        return state, f"{run_dir} (checkpoint)"
    try:
        return read_config(run_dir), str(run_dir / CONFIG_NAME)
    except ConfigError as err:
        raise ConfigError(f"--resume: no checkpoint, and {err}") from None


def _worker_error(scenario: Scenario) -> type[Exception]:
    """The exception of a dead physics worker (a class never raised in grid mode, so that
    grid runs do not import the physics engine)."""
    if scenario.mode != "physics":
        return _NeverRaised
    from ..envs.workers import WorkerError

    return WorkerError


class _NeverRaised(Exception):
    pass
