"""Learning curves from run logs alone (the ``plot`` command draws them).

Like the paper's figures 5–12: return per episode and steps per episode (each episode
faint, a moving average bold), and collisions per episode; several runs overlaid (A2C
against A2CM), each labelled from its log's metadata (:func:`plot_runs`). The runs are read
from their logs by :mod:`.run_series` (a damaged or empty log is an error, not an empty
figure). Runs as seeds (:func:`plot_aggregate`): the mean across runs with a 95% band
against environment steps, the optimum or a reference policy dashed (:func:`reference_for`).
Exact exploitability, where a run logged it, against the game's value where it is cached.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Scenario
from .run_series import EXPLOIT_SERIES, Run

__all__ = [
    "COLOURS",
    "EXPLOIT_FILE",
    "SERIES",
    "Panel",
    "Reference",
    "binned",
    "moving_average",
    "panels_of",
    "plot_aggregate",
    "plot_runs",
    "reference_for",
    "seed_band",
    "unique_labels",
]

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#17becf")
SERIES = (
    ("return", "returns.png", "Return per episode", "return (raw team reward)"),
    ("length", "lengths.png", "Steps per episode", "steps"),
    ("collisions", "collisions.png", "Collisions per episode", "pursuer collisions"),
)
"""(column, file, title, y label) of each figure."""
EXPLOIT_FILE = "exploitability.png"


def moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over up to ``window`` episodes (shorter at the start)."""
    values = np.asarray(values, dtype=np.float64)
    if len(values) == 0:
        return values
    csum = np.concatenate([[0.0], np.cumsum(values)])
    idx = np.arange(1, len(values) + 1)
    lo = np.maximum(idx - window, 0)
    return (csum[idx] - csum[lo]) / (idx - lo)


def unique_labels(runs: list[Run], paths: list[Path]) -> list[str]:
    """Each run's label, its folder's name added where two runs share one."""
    labels = [r.label for r in runs]
    return [
        f"{lab} ({p.name})" if labels.count(lab) > 1 else lab
        for lab, p in zip(labels, paths, strict=True)
    ]


def _draw(
    ax: object, runs: list[Run], labels: list[str], column: str, window: int, ylabel: str
) -> None:
    for i, (run, label) in enumerate(zip(runs, labels, strict=True)):
        colour = COLOURS[i % len(COLOURS)]
        y = run.columns[column].astype(np.float64)
        x = np.arange(1, len(y) + 1)
        ax.plot(x, y, color=colour, alpha=0.18, lw=0.6, rasterized=True)
        ax.plot(
            x,
            moving_average(y, window),
            color=colour,
            lw=2.0,
            label=f"{label}: {len(y):,} episodes, mean of last {min(window, len(y))} "
            f"= {moving_average(y, window)[-1]:.3g}"
            if len(y)
            else label,
        )
    ax.set_xlabel("episode")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.margins(x=0.01)
    if column == "length":
        top = max((float(r.columns[column].max(initial=1)) for r in runs), default=1.0)
        if top > 100:
            ax.set_yscale("log")
    ax.legend(loc="best", fontsize=8, framealpha=0.85)


def plot_runs(runs: list[Run], labels: list[str], out: Path, window: int) -> list[Path]:
    """Write the figures of ``runs`` into ``out``; return their paths."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    out.mkdir(parents=True, exist_ok=True)
    titles = sorted({r.title for r in runs})
    suffix = f" — {'; '.join(titles)}" if titles else ""
    written = []
    for column, name, title, ylabel in SERIES:
        fig = Figure(figsize=(9, 4.8), dpi=120, layout="constrained")
        ax = fig.add_subplot()
        _draw(ax, runs, labels, column, window, ylabel)
        ax.set_title(f"{title} (moving average over {window}){suffix}", fontsize=10)
        fig.savefig(out / name)
        written.append(out / name)
    fig = Figure(figsize=(9, 11), dpi=110, layout="constrained")
    for k, (column, _, title, ylabel) in enumerate(SERIES):
        ax = fig.add_subplot(len(SERIES), 1, k + 1)
        _draw(ax, runs, labels, column, window, ylabel)
        ax.set_title(title, fontsize=10)
    fig.suptitle(f"Learning curves (moving average over {window}){suffix}", fontsize=11)
    fig.savefig(out / "overview.png")
    written.append(out / "overview.png")
    if any(r.exploit for r in runs):
        fig = Figure(figsize=(9, 4.8), dpi=120, layout="constrained")
        ax = fig.add_subplot()
        _draw_exploit(ax, runs, labels)
        _draw_game_values(ax, [r.scenario for r in runs if r.exploit and r.scenario])
        ax.set_title(f"Exploitability (exact best responses){suffix}", fontsize=10)
        fig.savefig(out / EXPLOIT_FILE)
        written.append(out / EXPLOIT_FILE)
    return written


def _draw_exploit(ax: object, runs: list[Run], labels: list[str]) -> None:
    """Each run's exploitability metrics against environment steps (one colour per run)."""
    for i, (run, label) in enumerate(zip(runs, labels, strict=True)):
        colour = COLOURS[i % len(COLOURS)]
        for key, what, style in EXPLOIT_SERIES:
            if key not in run.exploit:
                continue
            steps, values = run.exploit[key]
            ax.plot(
                steps,
                values,
                style,
                color=colour,
                marker="o",
                ms=3,
                lw=1.6,
                label=f"{label}: {what}, last {values[-1]:.4g}",
            )
    ax.set_xlabel("environment steps")
    ax.set_ylabel("expected capture time (steps)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, framealpha=0.85)


def _draw_game_values(ax: object, scenarios: list[Scenario]) -> None:
    """The game's value of each distinct game, a grey band between its bounds, where it
    is cached (``oracle --game-value``: minutes to solve, too long for a plot); a note
    otherwise."""
    from ..solve.cache import cached_value, value_cache_key

    seen: set[str] = set()
    for sc in scenarios:
        if sc.mode != "grid" or value_cache_key(sc) in seen:
            continue
        seen.add(value_cache_key(sc))
        value = cached_value(sc)
        if value is None:
            print(
                f"note: the game's value of {sc.name} is not cached; `python -m"
                f" a2cm_phys.oracle --scenario {sc.name} --game-value` solves it for this figure"
            )
            continue
        label = f"{sc.name}: the game's value, {value.lower:.4g}–{value.upper:.4g}"
        ax.axhspan(value.lower, value.upper, color="0.55", alpha=0.5, lw=0, zorder=0)
        ax.axhline(value.lower, color="0.35", ls="--", lw=1.0, label=label)
    if seen:
        ax.legend(loc="best", fontsize=8, framealpha=0.85)


# --------------------------------------------------------------------------- runs as seeds


@dataclass(frozen=True)
class Reference:
    """A dashed line on aggregate panels: the optimum or a reference policy."""

    name: str
    length: float
    ret: float


@dataclass
class Panel:
    """One panel of an aggregate figure: a title, runs by label (seeds), a reference."""

    title: str
    runs: dict[str, list[Run]]
    reference: Reference | None = None


def binned(run: Run, column: str, edges: np.ndarray) -> np.ndarray:
    """The mean of ``column`` over the episodes ending in each env-step bin (``nan`` where
    none ends)."""
    x = run.columns["env_steps"]
    y = run.columns[column].astype(np.float64)
    idx = np.clip(np.searchsorted(edges, x, side="left") - 1, 0, len(edges) - 2)
    sums = np.bincount(idx, y, minlength=len(edges) - 1)
    counts = np.bincount(idx, minlength=len(edges) - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def seed_band(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean over seeds (rows) per column and its 95% Student t band (``nan`` below two
    seeds with a value)."""
    from scipy import stats as st

    values = np.asarray(values, dtype=np.float64)
    n = np.sum(np.isfinite(values), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-nan bins
        mean = np.nanmean(values, axis=0)
        sd = np.nanstd(values, axis=0, ddof=1)
        t = st.t.ppf(0.975, np.maximum(n - 1, 1))
        half = np.where(n >= 2, t * sd / np.sqrt(np.maximum(n, 1)), np.nan)
    return mean, mean - half, mean + half


def _spans_decades(values: np.ndarray) -> bool:
    v = values[np.isfinite(values) & (values > 0)]
    return bool(v.size) and float(v.max() / v.min()) > 20


def plot_aggregate(
    panels: list[Panel], column: str, path: Path, title: str, bins: int = 60
) -> Path:
    """One figure of ``panels`` side by side: ``column`` (``length`` or ``return``, the
    latter relative to the panel's reference) per env-step bin, mean across each label's
    runs with a 95% band, the reference dashed; log scale where values span decades."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    path.parent.mkdir(parents=True, exist_ok=True)
    cols = max(1, len(panels))
    fig = Figure(figsize=(4.2 * cols + 0.6, 4.2), dpi=110, layout="constrained")
    for k, panel in enumerate(panels):
        ax = fig.add_subplot(1, cols, k + 1)
        all_runs = [r for rs in panel.runs.values() for r in rs]
        top = max((float(r.columns["env_steps"].max(initial=0)) for r in all_runs), default=1)
        edges = np.linspace(0.0, max(top, 1.0), bins + 1)
        centres = (edges[:-1] + edges[1:]) / 2
        relative = column == "return" and panel.reference is not None and panel.reference.ret
        drawn = []
        for i, (label, runs) in enumerate(panel.runs.items()):
            if not runs:
                continue
            colour = COLOURS[i % len(COLOURS)]
            rows = np.array([binned(r, column, edges) for r in runs])
            if relative:
                rows = rows / panel.reference.ret
            mean, lo, hi = seed_band(rows)
            if column == "length":  # a t band of skewed lengths can dip below one step
                lo = np.maximum(lo, 1.0)
            drawn.append(mean)
            shown = np.isfinite(mean)  # bins where no episode ended are skipped, not gaps
            ax.plot(
                centres[shown],
                mean[shown],
                color=colour,
                lw=1.8,
                marker="." if shown.sum() < 15 else None,
                label=f"{label} ({len(runs)} seeds)",
            )
            band = np.isfinite(lo) & np.isfinite(hi)
            ax.fill_between(centres[band], lo[band], hi[band], color=colour, alpha=0.2, lw=0)
        ref = panel.reference
        if ref is not None:
            level = 1.0 if relative else ref.length if column == "length" else ref.ret
            if column == "length" or relative:
                ax.axhline(level, color="k", ls="--", lw=1.2, label=f"{ref.name}: {level:.3g}")
                drawn.append(np.array([level]))
        values = np.concatenate(drawn) if drawn else np.zeros(0)
        if _spans_decades(values):
            ax.set_yscale("log")
        ax.set_title(panel.title, fontsize=9)
        ax.set_xlabel("environment steps")
        if k == 0:
            ax.set_ylabel(
                "steps per episode"
                if column == "length"
                else "return ÷ reference's return (1 = as good)"
                if relative
                else "return (raw team reward)"
            )
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))
        ax.legend(loc="best", fontsize=7, framealpha=0.85)
    fig.suptitle(title, fontsize=10)
    fig.savefig(path)
    return path


def reference_for(scenario: Scenario, episodes: int = 500) -> Reference | None:
    """The dashed line of a scenario: its reference (:func:`~.evaluation.reference_of`),
    the exact optimum on grids the oracle solves, else the reference policy played for
    ``episodes`` episodes; ``None`` where there is none."""
    from .evaluation import reference_of

    ref = reference_of(scenario, episodes=episodes)
    if ref is None or ref.unavailable is not None:
        return None
    return Reference("optimum (oracle)" if ref.exact else ref.label, ref.length, ref.ret)


def panels_of(
    labelled: list[tuple[str, Run]], references: dict[str, Reference | None]
) -> list[Panel]:
    """Runs grouped into one panel per scenario (in first-seen order), one line per label."""
    panels: dict[str, Panel] = {}
    for label, run in labelled:
        name = run.scenario.name if run.scenario else run.title
        panel = panels.setdefault(name, Panel(name, {}, references.get(name)))
        panel.runs.setdefault(label, []).append(run)
    return list(panels.values())
