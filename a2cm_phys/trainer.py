"""The training loop of one run: :class:`Trainer` (env, model, learner, checkpoints, log).

One trainer for both algorithms; only the model differs (``make_model``: one critic for
A2CM, N for A2C). Each update collects ``batch_size`` steps (``batch_size / num_envs`` per
game) and takes one learner step. The command line over it is :mod:`a2cm_phys.train`.

``Trainer.resume`` continues bit for bit in grid mode (an interrupted and resumed run
ends with the same weights and episode statistics as an uninterrupted one). In physics
mode the games running at the checkpoint are restarted on resume unless the physics core
can save its state (see :meth:`a2cm_phys.envs.vector.VectorEnv.state`).
"""

from __future__ import annotations

import json
import math
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from . import checkpoint
from .algos import Learner, NonFiniteLoss, make_model
from .config import (
    ConfigError,
    Scenario,
    Train,
    build,
    load_train,
    to_dict,
)
from .envs.vector import VectorEnv
from .rollout import StepHook, allocate_batch, collect
from .stats import EpisodeStats

EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (a checkpoint was saved; the run can be resumed)."""

EXIT_NONFINITE = 3
"""Exit status when the loss became NaN/inf (the last good checkpoint is kept)."""

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


def policy_rng(seed: int) -> np.random.Generator:
    """The action-sampling generator of a run, independent of the env's seed stream."""
    return np.random.default_rng([seed, 1])


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
        check_seed(cfg)
        check_workers(scenario, cfg)
        torch.set_num_threads(cfg.threads)
        self.scenario, self.cfg, self.run_dir = scenario, cfg, Path(run_dir)
        self.record, self.log_every, self.scene_every = record, log_every, scene_every
        self.progress = progress
        self.checkpoint_seconds, self.checkpoint_every = checkpoint_seconds, checkpoint_every
        self.env = VectorEnv(scenario, cfg.num_envs, workers=cfg.workers)
        self.model = make_model(cfg, scenario)
        self.learner = Learner(self.model, cfg)
        self.rng = policy_rng(cfg.seed)
        self.batch = allocate_batch(
            cfg.steps_per_env, cfg.num_envs, scenario.obs_dim, scenario.pursuers
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
        self._stop_requested = False
        self._phase = _IDLE

    # ------------------------------------------------------------------ state
    def checkpoint_state(self) -> dict[str, Any]:
        """Everything a resume needs, as a dict for :func:`a2cm_phys.checkpoint.save`."""
        return {
            "scenario": to_dict(self.scenario),
            "train": to_dict(self.cfg),
            "update": self.update,
            "learner": self.learner.state_dict(),
            "rng": self.rng.bit_generator.state,
            "env": self.env.state(),
            "stats": self.stats.state(),
            "wall_time": self.wall_time(),
        }

    def load_checkpoint_state(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`checkpoint_state` (same scenario and num_envs)."""
        self.learner.load_state_dict(state["learner"])
        self.rng.bit_generator.state = state["rng"]
        self.obs = self.env.load_state(state["env"])
        self.stats = EpisodeStats.from_state(state["stats"])
        self.update = self.saved_update = int(state["update"])
        self._wall_before = float(state["wall_time"])
        self._session_start = time.perf_counter()

    @classmethod
    def resume(cls, run_dir: str | Path, updates: int | None = None, **kwargs: Any) -> Trainer:
        """A trainer continuing the run in ``run_dir``, optionally extended to ``updates``."""
        try:
            state = checkpoint.load(run_dir)
        except (OSError, ValueError) as err:
            raise ConfigError(f"--resume: {err}") from None
        run_dir = Path(run_dir)
        if run_dir.is_file():  # the checkpoint itself was given
            run_dir = run_dir.parent
        scenario = build(Scenario, state["scenario"], f"{run_dir} (checkpoint)")
        train = dict(state["train"])
        if updates is not None:
            train["updates"] = updates
        cfg = load_train(train, f"{run_dir} (checkpoint)")
        trainer = cls(scenario, cfg, run_dir, **kwargs)
        trainer.load_checkpoint_state(state)
        return trainer

    def close(self) -> None:
        """Release the environment (stops physics worker processes, if any)."""
        self.env.close()

    def wall_time(self) -> float:
        """Seconds spent training in this run, over all sessions."""
        return self._wall_before + time.perf_counter() - self._session_start

    def save_checkpoint(self, state: dict[str, Any] | None = None) -> None:
        """Write the checkpoint (atomically) from ``state`` or the current state."""
        state = state if state is not None else self.checkpoint_state()
        checkpoint.save(self.run_dir / checkpoint.CHECKPOINT_NAME, state)
        self.saved_update = int(state["update"])
        self._last_save = time.perf_counter()

    # ------------------------------------------------------------------ training
    def run(self) -> str:
        """Train up to ``cfg.updates``; return ``"done"``, ``"interrupted"`` or ``"nonfinite"``.

        The first Ctrl-C stops at the end of the current update (a second one stops at
        once); either way the checkpoint holds the state after the last whole update. A
        non-finite loss stops the run without overwriting the last good checkpoint.
        """
        if not (self.run_dir / checkpoint.CHECKPOINT_NAME).exists():
            self.save_checkpoint()  # so there is always a last good checkpoint
        self._last_save = time.perf_counter()
        status = "done"
        with self._sigint_deferred(), self._recorder() as recorder, self._bar() as bar:
            on_step = recorder.record_step if recorder is not None else None
            try:
                while self.update < self.cfg.updates:
                    if self._stop_requested:
                        raise KeyboardInterrupt
                    self._one_update(on_step)
                    if recorder is not None:
                        recorder.record_update(self.update, self.last_metrics)
                    bar.tick()
                    self._maybe_save()
            except KeyboardInterrupt:
                status = "interrupted"
                if self._phase != _LEARN:  # mid-update weights could be half-stepped
                    self.save_checkpoint(self._state_at_last_update())
            except NonFiniteLoss as err:
                status = "nonfinite"
                self.stop_reason = str(err)
            else:
                self.save_checkpoint()
        self._write_summary(status)
        return status

    def _one_update(self, on_step: StepHook | None) -> None:
        # Snapshot so that an interrupt inside the rollout can rewind to the update boundary.
        self._boundary = (self.env.state(), self.rng.bit_generator.state)
        self._phase = _ROLLOUT
        obs, episodes = collect(self.env, self.model.act, self.obs, self.rng, self.batch, on_step)
        self._phase = _LEARN
        self.last_metrics = self.learner.update(self.batch)
        self.obs = obs
        self.stats.add(episodes)
        self.update += 1
        self._session_steps += self.cfg.batch_size
        self._phase = _IDLE

    def _state_at_last_update(self) -> dict[str, Any]:
        state = self.checkpoint_state()
        if self._phase == _ROLLOUT:
            state["env"], state["rng"] = self._boundary
        return state

    def _maybe_save(self) -> None:
        every = self.checkpoint_every
        due = every and self.update % every == 0
        if due or time.perf_counter() - self._last_save >= self.checkpoint_seconds:
            self.save_checkpoint()

    @contextmanager
    def _sigint_deferred(self) -> Iterator[None]:
        """First SIGINT: finish the update, then stop; the second raises KeyboardInterrupt."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return

        def handler(signum: int, frame: Any) -> None:
            if self._stop_requested:
                raise KeyboardInterrupt
            self._stop_requested = True
            print("\nstopping after this update (Ctrl-C again: at once)", file=sys.stderr)

        previous = signal.signal(signal.SIGINT, handler)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous if previous is not None else signal.SIG_DFL)

    def _recorder(self) -> Any:
        """The MCAP episode recorder, or a null context when it is not available."""
        recorder = open_recorder(self) if self.record else None
        return recorder if recorder is not None else nullcontext()

    def _bar(self) -> _Progress:
        return _Progress(self) if self.progress else _Progress(None)

    # ------------------------------------------------------------------ summary
    def summary(self, status: str = "done") -> dict[str, Any]:
        """Run statistics: episodes, mean length (last 1,000), collisions, captures, speed."""
        s, cfg = self.stats, self.cfg
        wall = self.wall_time()
        steps = self.update * cfg.batch_size
        per_episode = s.collisions / s.episodes if s.episodes else math.nan
        return {
            "status": status,
            "run_dir": str(self.run_dir),
            "scenario": self.scenario.name,
            "algo": cfg.algo,
            "seed": cfg.seed,
            "num_envs": cfg.num_envs,
            "updates": self.update,
            "steps": steps,
            "episodes": s.episodes,
            "mean_length_last_1000": s.recent_mean(0),
            "mean_return_last_1000": s.recent_mean(1),
            "captures": s.captures,
            "capture_rate": s.captures / s.episodes if s.episodes else math.nan,
            "truncations": s.truncations,
            "collision_terminations": s.collision_ends,
            "collisions": s.collisions,
            "collisions_per_episode": per_episode,
            "wall_time_s": wall,
            "steps_per_s": steps / wall if wall > 0 else math.nan,
            "last_checkpoint_update": self.saved_update,
        }

    def _write_summary(self, status: str) -> None:
        self.last_summary = self.summary(status)
        strict = {  # NaN (e.g. no episode yet) is not JSON: write null
            k: None if isinstance(v, float) and not math.isfinite(v) else v
            for k, v in self.last_summary.items()
        }
        (self.run_dir / "summary.json").write_text(json.dumps(strict, indent=2) + "\n")


def open_recorder(trainer: Trainer) -> Any:
    """The run's MCAP recorder (``episodes.mcap``), or ``None`` if it cannot record.

    The one call site of :mod:`a2cm_phys.record`: the recorder gets ``start(env, obs)``,
    ``record_step(actions, step)`` after every vector step and ``record_update(update,
    metrics)`` after every update.
    """
    try:
        from .record.writer import EpisodeRecorder
    except ImportError:  # the record package is optional for training
        return None
    # A resumed session continues the log in a file of its own (the first one was closed, or
    # cut short by a crash), on the same clock and episode ids; the games caught mid-episode
    # get a summary without a trajectory.
    name = f"episodes-from-{trainer.update:06d}.mcap" if trainer.update else "episodes.mcap"
    recorder = EpisodeRecorder(
        trainer.run_dir / name,
        trainer.scenario,
        {"train": to_dict(trainer.cfg)},
        log_every=trainer.log_every,
        scene_every=trainer.scene_every,
    )
    recorder.start(
        trainer.env,
        trainer.obs,
        step=trainer.update * trainer.cfg.steps_per_env,
        episode=trainer.stats.episodes,
    )
    return recorder


class _Progress:
    """A tqdm bar over updates showing episode statistics; a no-op without a trainer."""

    def __init__(self, trainer: Trainer | None) -> None:
        self.trainer = trainer
        self.bar = None
        self._next_postfix = 0.0

    def __enter__(self) -> _Progress:
        t = self.trainer
        if t is not None:
            self.bar = tqdm(total=t.cfg.updates, initial=t.update, unit="upd", dynamic_ncols=True)
        return self

    def tick(self) -> None:
        if self.bar is None:
            return
        self.bar.update(1)
        now = time.perf_counter()
        if now >= self._next_postfix:  # formatting the postfix costs ~50 µs
            self._next_postfix = now + 0.5
            t = self.trainer
            s = t.stats
            self.bar.set_postfix(
                episodes=s.episodes,
                len100=f"{s.recent_mean(0, 100):.2f}",
                ret100=f"{s.recent_mean(1, 100):.4g}",
                collisions=s.collisions,
                steps_s=f"{t._session_steps / (now - t._session_start):.0f}",
                refresh=False,
            )

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.close()
