"""Summary statistics: seeded bootstrap confidence intervals, comparisons across seeds
(scipy's Welch t-test and bootstrap, rliable-style interquartile means and probabilities
of improvement with stratified bootstrap intervals, verdicts)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    pass

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


def t_interval(values: Iterable[float]) -> tuple[float, float]:
    """Mean and half-width of its Student t 95% confidence interval (few values: seeds).

    The half-width is ``nan`` for fewer than two values (and the mean too for none).
    """
    mean, lo, hi = mean_interval(values)
    return (mean, (hi - lo) / 2.0)


Interval = tuple[float, float, float]
"""``(value, lo, hi)``: a point estimate and its confidence interval (``nan`` if unknown)."""

NAN3: Interval = (float("nan"), float("nan"), float("nan"))


def mean_interval(
    values: Iterable[float],
    confidence: float = 0.95,
    floor: float | None = None,
    ceiling: float | None = None,
) -> Interval:
    """Mean and its Student t interval across seeds (scipy); ``nan`` bounds below 2 values.

    ``floor`` and ``ceiling``: the least and greatest values the quantity can take (0 for
    counts, rates and lengths; 1 for a rate). The interval is clipped there: a symmetric t
    interval of few skewed values can reach beyond them (0.1 ± 0.3 collisions per episode),
    and no value beyond them is plausible.
    """
    from scipy import stats as st

    x = np.asarray(list(values), dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return NAN3
    mean = float(x.mean())
    if x.size < 2:
        return (mean, float("nan"), float("nan"))
    half = float(st.t.ppf(0.5 + confidence / 2, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size))
    lo = mean - half if floor is None else max(mean - half, floor)
    hi = mean + half if ceiling is None else min(mean + half, ceiling)
    return (mean, lo, hi)


def welch_p(a: Iterable[float], b: Iterable[float], alternative: str = "greater") -> float:
    """One-sided p-value of Welch's t-test (scipy ``ttest_ind``, unequal variances) that
    ``mean(a)`` is greater (``alternative="greater"``) or less than ``mean(b)``; ``nan``
    with fewer than two finite values on a side (one seed against one decides nothing, even
    where they differ), or with equal values throughout; 0 or 1 where both sides have no
    variance and differ."""
    from scipy import stats as st

    x = np.asarray(list(a), dtype=np.float64)
    y = np.asarray(list(b), dtype=np.float64)
    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
    if x.size < 2 or y.size < 2:  # one sample a side has no spread: nothing to test
        return float("nan")
    if x.std() == 0 and y.std() == 0:  # repeated exactly: certain if they differ
        if x[0] == y[0]:
            return float("nan")
        return 0.0 if (x[0] > y[0]) == (alternative == "greater") else 1.0
    return float(st.ttest_ind(x, y, equal_var=False, alternative=alternative).pvalue)


def ratio_interval(
    a: Iterable[float],
    b: Iterable[float],
    *,
    confidence: float = 0.95,
    resamples: int = 4000,
    seed: int = 0,
) -> Interval:
    """``mean(a) / mean(b)`` with a percentile bootstrap interval (scipy ``bootstrap``, the
    two samples resampled independently); a side of one value is held fixed."""
    from scipy import stats as st

    x = np.asarray(list(a), dtype=np.float64)
    y = np.asarray(list(b), dtype=np.float64)
    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
    if x.size == 0 or y.size == 0 or y.mean() == 0:
        return NAN3
    value = float(x.mean() / y.mean())
    if x.size < 2 and y.size < 2:
        return (value, float("nan"), float("nan"))
    if np.ptp(x) == 0 and np.ptp(y) == 0:
        return (value, value, value)
    samples = [s for s in (x, y) if s.size > 1 and np.ptp(s) > 0]
    fixed = {0: x.mean(), 1: y.mean()}

    def stat(*resampled: np.ndarray, axis: int = -1) -> np.ndarray:
        it = iter(resampled)
        num = np.mean(next(it), axis=axis) if x.size > 1 and np.ptp(x) > 0 else fixed[0]
        den = np.mean(next(it), axis=axis) if y.size > 1 and np.ptp(y) > 0 else fixed[1]
        return num / den

    res = st.bootstrap(
        tuple(samples),
        stat,
        n_resamples=resamples,
        confidence_level=confidence,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return (value, float(res.confidence_interval.low), float(res.confidence_interval.high))


def iqm(values: Iterable[float]) -> float:
    """Interquartile mean: the mean of the middle 50% (scipy ``trim_mean``, 25% each side)."""
    from scipy import stats as st

    x = np.asarray(list(values), dtype=np.float64)
    return float(st.trim_mean(x, 0.25)) if x.size else float("nan")


def _stratified(
    strata: Sequence[np.ndarray],
    statistic: Callable[[list[np.ndarray]], np.ndarray],
    resamples: int,
    confidence: float,
    seed: int,
) -> tuple[float, float]:
    """Percentile interval of ``statistic`` when every stratum (a task's seeds) is
    resampled with replacement on its own (rliable's stratified bootstrap)."""
    rng = np.random.default_rng(seed)
    drawn = [s[rng.integers(0, s.size, size=(resamples, s.size))] for s in strata]
    stats = statistic(drawn)
    alpha = (1 - confidence) / 2
    lo, hi = np.quantile(stats, [alpha, 1 - alpha])
    return float(lo), float(hi)


def iqm_interval(
    scores_by_task: Sequence[Iterable[float]],
    *,
    confidence: float = 0.95,
    resamples: int = 4000,
    seed: int = 0,
) -> Interval:
    """IQM of every run's score pooled over tasks, with a stratified bootstrap interval
    (each task's runs resampled on their own), as in rliable."""
    from scipy import stats as st

    strata = [np.asarray(list(s), dtype=np.float64) for s in scores_by_task]
    strata = [s[np.isfinite(s)] for s in strata]
    strata = [s for s in strata if s.size]
    if not strata:
        return NAN3
    value = iqm(np.concatenate(strata))
    lo, hi = _stratified(
        strata,
        lambda d: st.trim_mean(np.concatenate(d, axis=1), 0.25, axis=1),
        resamples,
        confidence,
        seed,
    )
    return (value, lo, hi)


def _p_greater(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``P(X > Y) + P(X = Y) / 2`` along the last axis pairs (broadcast over leading axes)."""
    gt = (x[..., :, None] > y[..., None, :]).mean(axis=(-2, -1))
    eq = (x[..., :, None] == y[..., None, :]).mean(axis=(-2, -1))
    return gt + 0.5 * eq


def probability_of_improvement(
    x_by_task: Sequence[Iterable[float]],
    y_by_task: Sequence[Iterable[float]],
    *,
    confidence: float = 0.95,
    resamples: int = 4000,
    seed: int = 0,
) -> Interval:
    """rliable's probability of improvement: the mean over tasks of ``P(X > Y)`` (ties
    count half; the Mann–Whitney U statistic over ``n·m``, scipy), higher scores better,
    with a stratified bootstrap interval (each task's X and Y resampled on their own)."""
    from scipy import stats as st

    pairs = []
    for xs, ys in zip(x_by_task, y_by_task, strict=True):
        x, y = np.asarray(list(xs), dtype=np.float64), np.asarray(list(ys), dtype=np.float64)
        x, y = x[np.isfinite(x)], y[np.isfinite(y)]
        if x.size and y.size:
            pairs.append((x, y))
    if not pairs:
        return NAN3
    value = float(np.mean([st.mannwhitneyu(x, y).statistic / (x.size * y.size) for x, y in pairs]))
    strata = [s for pair in pairs for s in pair]

    def stat(drawn: list[np.ndarray]) -> np.ndarray:
        return np.mean([_p_greater(drawn[2 * k], drawn[2 * k + 1]) for k in range(len(pairs))], 0)

    lo, hi = _stratified(strata, stat, resamples, confidence, seed)
    return (value, lo, hi)


HOLDS, FAILS, UNSURE = "holds", "does not hold", "inconclusive"
"""The verdicts of a claim."""


def verdict_bound(
    interval: Interval, *, at_most: float | None = None, at_least: float | None = None
) -> str:
    """Verdict on "the quantity is at most / at least a bound" from its 95% interval: holds
    if the whole interval is on the claimed side, does not hold if it is wholly on the
    other, else inconclusive (also without an interval)."""
    _, lo, hi = interval
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return UNSURE
    if at_most is not None and at_least is not None:
        if at_least <= lo and hi <= at_most:
            return HOLDS
        return FAILS if hi < at_least or lo > at_most else UNSURE
    if at_most is not None:
        return HOLDS if hi <= at_most else FAILS if lo > at_most else UNSURE
    if at_least is not None:
        return HOLDS if lo >= at_least else FAILS if hi < at_least else UNSURE
    raise ValueError("verdict_bound needs at_most or at_least")


def verdict_test(p_claimed: float, p_opposite: float, alpha: float = 0.05) -> str:
    """Verdict of a one-sided comparison: holds if the claimed direction's p-value is below
    ``alpha``, does not hold if the opposite direction's is, else inconclusive."""
    if np.isfinite(p_claimed) and p_claimed < alpha:
        return HOLDS
    if np.isfinite(p_opposite) and p_opposite < alpha:
        return FAILS
    return UNSURE
