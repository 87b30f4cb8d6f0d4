"""A run's ``summary.json``: episode counts, recent means, collisions, captures, speed."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .rundir import SUMMARY_NAME, write_atomic

if TYPE_CHECKING:
    from .trainer import Trainer


def run_summary(trainer: Trainer, status: str = "done") -> dict[str, Any]:
    """Run statistics: episodes, mean length (last 1,000), collisions, captures, speed."""
    s, cfg = trainer.stats, trainer.cfg
    wall = trainer.wall_time()
    steps = trainer.update * cfg.batch_size
    per_episode = s.collisions / s.episodes if s.episodes else math.nan
    return {
        "status": status,
        "run_dir": str(trainer.run_dir),
        "scenario": trainer.scenario.name,
        "algo": cfg.algo,
        "seed": cfg.seed,
        "num_envs": cfg.num_envs,
        "updates": trainer.update,
        "steps": steps,
        "episodes": s.episodes,
        "mean_length_last_1000": s.recent_mean(0),
        "mean_return_last_1000": s.recent_mean(1),
        **(
            {
                "evader_mean_return_last_1000": s.recent_mean(3),
                "opponents": opponents(trainer),
            }
            if trainer.evader is not None
            else {}
        ),
        **({"descent_value": trainer.descent.last_value} if trainer.descent is not None else {}),
        **(
            {"evader_descent_value": trainer.descent.last_evader_value}
            if trainer.evader_descends()
            else {}
        ),
        "captures": s.captures,
        "capture_rate": s.captures / s.episodes if s.episodes else math.nan,
        "truncations": s.truncations,
        "collision_terminations": s.collision_ends,
        "collisions": s.collisions,
        "collisions_per_episode": per_episode,
        "wall_time_s": wall,
        "steps_per_s": steps / wall if wall > 0 else math.nan,
        "last_checkpoint_update": trainer.saved_update,
    }


def opponents(trainer: Trainer) -> str:
    """How the teams of a self-play run met their opponents, for the summary."""
    cfg = trainer.cfg
    text = "simultaneous" if trainer.pool is None else trainer.pool.describe(cfg.pool_every)
    if trainer.descent is None:
        return text
    descent = f"exploitability descent every {cfg.descent_every} updates"
    if trainer.evader_descends():
        return f"both teams: {descent}"
    return f"pursuers: {descent}; evader: {text}"


def write_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    """Write ``summary.json`` atomically (NaN, e.g. no episode yet, is not JSON: null)."""
    strict = {
        k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in summary.items()
    }
    write_atomic(run_dir / SUMMARY_NAME, json.dumps(strict, indent=2) + "\n")
