"""Summary statistics: seeded bootstrap confidence intervals and running episode tallies."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .envs.vector import EpisodeSummary

Statistic = Callable[[np.ndarray], np.ndarray]
"""Reduces resamples ``(R, n)`` along axis 1 to ``(R,)``."""

STATISTICS: dict[str, Statistic] = {
    "mean": lambda x: x.mean(axis=-1),
    "median": lambda x: np.median(x, axis=-1),
    "p95": lambda x: np.percentile(x, 95, axis=-1),
}
"""The statistics :func:`describe` reports, by name."""


def bootstrap_ci(
    values: np.ndarray,
    statistic: Statistic,
    *,
    resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of ``statistic`` over ``values``.

    Resampling is seeded, so the interval is reproducible. Memory stays bounded for large
    samples (resamples are drawn in chunks). An empty sample gives ``(nan, nan)``.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    if x.size == 0:
        return (float("nan"), float("nan"))
    rng = np.random.default_rng(seed)
    chunk = max(1, 2_000_000 // x.size)
    stats = []
    for start in range(0, resamples, chunk):
        idx = rng.integers(0, x.size, size=(min(chunk, resamples - start), x.size))
        stats.append(statistic(x[idx]))
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(np.concatenate(stats), [alpha, 1.0 - alpha])
    return (float(lo), float(hi))


def describe(
    values: np.ndarray,
    names: tuple[str, ...] = ("mean", "median", "p95"),
    *,
    resamples: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """``{name: {"value", "lo", "hi"}}`` for each statistic in ``names`` (:data:`STATISTICS`)."""
    x = np.asarray(values, dtype=np.float64).ravel()
    out = {}
    for name in names:
        fn = STATISTICS[name]
        value = float(fn(x[None])[0]) if x.size else float("nan")
        lo, hi = bootstrap_ci(x, fn, resamples=resamples, confidence=confidence, seed=seed)
        out[name] = {"value": value, "lo": lo, "hi": hi}
    return out


def mean_and_se(values: np.ndarray) -> tuple[float, float]:
    """Sample mean and its standard error (``nan`` SE for fewer than two values)."""
    x = np.asarray(values, dtype=np.float64).ravel()
    if x.size == 0:
        return (float("nan"), float("nan"))
    se = float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else float("nan")
    return (float(x.mean()), se)


# Two-sided 95% Student t quantiles t_{0.975, df} for df = 1..30 (beyond: the normal's 1.96
# plus the first Cornish-Fisher term, within 0.002).
_T975 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip


def t_interval(values: Iterable[float]) -> tuple[float, float]:
    """Mean and half-width of its Student t 95% confidence interval (few values: seeds).

    The half-width is ``nan`` for fewer than two values (and the mean too for none).
    """
    x = np.asarray(list(values), dtype=np.float64)
    if x.size < 2:
        return (float(x.mean()) if x.size else float("nan"), float("nan"))
    df = x.size - 1
    t = _T975[df - 1] if df <= len(_T975) else 1.96 + (1.96**3 + 1.96) / (4 * df)
    return (float(x.mean()), float(t * x.std(ddof=1) / np.sqrt(x.size)))


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

    def add(self, episodes: Iterable[EpisodeSummary]) -> None:
        """Count finished episodes (in the order they finished)."""
        for ep in episodes:
            self.episodes += 1
            self.captures += ep.captured
            self.truncations += ep.truncated
            self.collision_ends += ep.collision_terminated
            self.collisions += ep.collisions
            evader = ep.evader_ret if ep.evader_ret is not None else math.nan
            self.recent.append((ep.length, ep.ret, ep.collisions, evader))

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
