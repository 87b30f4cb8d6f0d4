"""A run's running tallies of finished episodes, kept by the trainer and its checkpoint."""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..envs.tallies import EpisodeBatch


class EpisodeStats:
    """Running tallies of finished episodes plus a window of the most recent ones.

    The tallies count every episode of a run; means "over the last k" read the window
    (``window`` episodes, 1,000 by default). :meth:`state` / :meth:`from_state` round-trip
    it through a checkpoint.
    """

    def __init__(self, window: int = 1000) -> None:
        self.window = window
        self.episodes = 0
        self.captures = 0
        self.truncations = 0
        self.collision_ends = 0
        self.collisions = 0
        # (length, return, collisions, a learned evader's return or NaN)
        self.recent: deque[tuple[int, float, int, float]] = deque(maxlen=window)

    def add(self, episodes: EpisodeBatch) -> None:
        """Count finished episodes (in the order they finished)."""
        self.episodes += len(episodes)
        self.captures += int(np.count_nonzero(episodes.captured))
        self.truncations += int(np.count_nonzero(episodes.truncated))
        self.collision_ends += int(np.count_nonzero(episodes.collision_terminated))
        self.collisions += int(episodes.collisions.sum())
        last = slice(-self.window, None)  # only the window's worth can stay in it
        lengths, collisions = episodes.length[last].tolist(), episodes.collisions[last].tolist()
        evader = episodes.evader_ret
        evader = evader[last].tolist() if evader is not None else [math.nan] * len(lengths)
        returns = episodes.ret[last].tolist()
        self.recent.extend(zip(lengths, returns, collisions, evader, strict=True))

    def recent_mean(self, column: int, last: int | None = None) -> float:
        """Mean of column 0 (length), 1 (return), 2 (collisions) or 3 (a learned evader's
        return) over the last episodes."""
        rows = list(self.recent)[-last:] if last else self.recent
        return float(np.mean([r[column] for r in rows])) if rows else float("nan")

    def state(self) -> dict[str, Any]:
        """A plain dict of the tallies and the window (for checkpoints)."""
        rows = np.array(self.recent, dtype=np.float64).reshape(-1, 4)
        counts = ("episodes", "captures", "truncations", "collision_ends", "collisions")
        return {"window": self.window, "recent": rows, **{k: getattr(self, k) for k in counts}}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> EpisodeStats:
        """Rebuild what :meth:`state` returned."""
        stats = cls(int(state["window"]))
        for key in ("episodes", "captures", "truncations", "collision_ends", "collisions"):
            setattr(stats, key, int(state[key]))
        rows = np.asarray(state["recent"], dtype=np.float64)
        if rows.shape[-1] == 3:  # checkpoints from before the learned evader
            rows = np.concatenate([rows, np.full((len(rows), 1), math.nan)], axis=-1)
        stats.recent.extend(
            (int(n), float(r), int(c), math.nan if math.isnan(e) else float(e))
            for n, r, c, e in rows
        )
        return stats
