"""A run's ``summary.json``: episode counts, recent means, collisions, captures, speed."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from .rundir import SUMMARY_NAME, write_atomic
from .state import RunState


def run_summary(run: RunState, status: str = "done") -> dict[str, Any]:
    """Run statistics: episodes, mean length (last 1,000), collisions, captures, speed."""
    s, cfg = run.stats, run.cfg
    wall = run.wall_time()
    steps = run.update * cfg.batch_size
    per_episode = s.collisions / s.episodes if s.episodes else math.nan
    return {
        "status": status,
        "run_dir": str(run.run_dir),
        "scenario": run.scenario.name,
        "algo": cfg.algo,
        "seed": cfg.seed,
        "num_envs": cfg.num_envs,
        "updates": run.update,
        "steps": steps,
        "episodes": s.episodes,
        "mean_length_last_1000": s.recent_mean(0),
        "mean_return_last_1000": s.recent_mean(1),
        **(
            {
                "evader_mean_return_last_1000": s.recent_mean(3),
                "opponents": opponents(run),
            }
            if run.evader is not None
            else {}
        ),
        **({"descent_value": run.descent.last_value} if run.descent is not None else {}),
        **(
            {"evader_descent_value": run.descent.last_evader_value} if run.evader_descends() else {}
        ),
        "captures": s.captures,
        "capture_rate": s.captures / s.episodes if s.episodes else math.nan,
        "truncations": s.truncations,
        "collision_terminations": s.collision_ends,
        "collisions": s.collisions,
        "collisions_per_episode": per_episode,
        "wall_time_s": wall,
        "steps_per_s": steps / wall if wall > 0 else math.nan,
        "last_checkpoint_update": run.saved_update,
    }


def opponents(run: RunState) -> str:
    """How the teams of a self-play run met their opponents, for the summary."""
    cfg = run.cfg
    text = "simultaneous" if run.pool is None else run.pool.describe(cfg.pool_every)
    if run.descent is None:
        return text
    descent = f"exploitability descent every {cfg.descent_every} updates"
    if run.evader_descends():
        return f"both teams: {descent}"
    return f"pursuers: {descent}; evader: {text}"


def write_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    """Write ``summary.json`` atomically (NaN, e.g. no episode yet, is not JSON: null)."""
    strict = {
        k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in summary.items()
    }
    write_atomic(run_dir / SUMMARY_NAME, json.dumps(strict, indent=2) + "\n")
