"""Learning-curve figures from run logs alone (the ``plot`` command and the report draw them).

Single runs (:mod:`.curves`: :func:`plot_runs`): each run's moving average against
environment steps, the reference dashed, the return split into its time and collision
parts. Runs as seeds (:func:`aggregate_figure`, :func:`plot_aggregate`): one panel per
scenario, one line per label, the mean across runs with a 95% band against environment
steps, the optimum or a reference policy dashed (:func:`~.figure_parts.reference_for`), or
a note of why there is none. Exact exploitability, where a run logged it, against the
game's value where it is cached (:mod:`.exploit_figure`). Every axis follows one y-scale
rule and names it (:data:`~.figure_parts.Y_SCALES`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .curves import moving_average, plot_runs, runs_figure, unique_labels
from .exploit_figure import EXPLOIT_FILE
from .figure_parts import (
    COLOURS,
    Y_SCALES,
    Reference,
    axis_label,
    draw_reference,
    reference_for,
)
from .run_series import Run, penalised

__all__ = [
    "COLOURS",
    "EXPLOIT_FILE",
    "Panel",
    "Reference",
    "aggregate_figure",
    "binned",
    "moving_average",
    "panels_of",
    "plot_aggregate",
    "plot_runs",
    "reference_for",
    "runs_figure",
    "seed_band",
    "unique_labels",
]


@dataclass
class Panel:
    """One panel of an aggregate figure: a title, runs by label (seeds), a reference."""

    title: str
    runs: dict[str, list[Run]]
    reference: Reference | None = None


def binned(run: Run, column: str, edges: np.ndarray) -> np.ndarray:
    """The mean of ``column`` over the episodes ending in each env-step bin (``nan`` where
    none ends); rows of a thinned series (:func:`~.run_series.thinned`) count as their
    ``episodes``."""
    x = run.columns["env_steps"]
    y = run.columns[column].astype(np.float64)
    weight = run.columns.get("episodes")
    w = np.ones(len(y)) if weight is None else np.asarray(weight, dtype=np.float64)
    idx = np.clip(np.searchsorted(edges, x, side="left") - 1, 0, len(edges) - 2)
    sums = np.bincount(idx, y * w, minlength=len(edges) - 1)
    counts = np.bincount(idx, w, minlength=len(edges) - 1)
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


def shown_column(column: str, reference: Reference | None) -> str:
    """What a ``column`` panel shows: ``return`` becomes ``relative`` (the return ÷ the
    reference's) where the panel has a reference return; every other column is itself."""
    ref = reference
    if column != "return" or ref is None or ref.unavailable is not None:
        return column
    return "relative" if math.isfinite(ref.ret) and ref.ret else column


def _clipped(
    column: str, values: np.ndarray, lo: np.ndarray, hi: np.ndarray, mean: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A t band kept within the episodes' ``values`` (no mean of them lies outside; a band
    of few, skewed seeds would reach below one step, below no collision, above a zero
    return)."""
    values = values[np.isfinite(values)]
    if values.size:
        lo, hi = np.maximum(lo, values.min()), np.minimum(hi, values.max())
    if column == "relative":  # a log axis: a band edge at or below zero cannot be drawn
        lo = np.maximum(lo, np.abs(mean) * 1e-3)
    return lo, hi


def _draw_panel(ax: object, panel: Panel, column: str, bins: int) -> str:
    """``column`` of ``panel``'s runs per env-step bin, each label's mean with its 95%
    band, the reference dashed (or why there is none); return the column shown."""
    shown = shown_column(column, panel.reference)
    all_runs = [r for rs in panel.runs.values() for r in rs]
    top = max((float(r.columns["env_steps"].max(initial=0)) for r in all_runs), default=1)
    edges = np.linspace(0.0, max(top, 1.0), bins + 1)
    centres = (edges[:-1] + edges[1:]) / 2
    if panel.reference is not None:
        draw_reference(ax, panel.reference, shown)
    for i, (label, runs) in enumerate(panel.runs.items()):
        if not runs:
            continue
        colour = COLOURS[i % len(COLOURS)]
        rows = np.array([binned(r, column, edges) for r in runs])
        if shown == "relative":
            rows = rows / panel.reference.ret
        mean, lo, hi = seed_band(rows)
        values = np.concatenate([r.columns[column] for r in runs]).astype(np.float64)
        if shown == "relative":
            values = values / panel.reference.ret
        lo, hi = _clipped(shown, values, lo, hi, mean)
        drawn = np.isfinite(mean)  # bins where no episode ended are skipped, not gaps
        ax.plot(
            centres[drawn],
            mean[drawn],
            color=colour,
            lw=1.8,
            marker="." if drawn.sum() < 15 else None,
            label=f"{label} ({len(runs)} seeds)",
        )
        band = np.isfinite(lo) & np.isfinite(hi)
        ax.fill_between(centres[band], lo[band], hi[band], color=colour, alpha=0.2, lw=0)
    ax.set_yscale(Y_SCALES[shown])
    ax.set_xlabel("environment steps (all games)")
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))
    ax.legend(loc="best", fontsize=7, framealpha=0.85)
    return shown


def aggregate_figure(
    panels: list[Panel], columns: Sequence[str], title: str, bins: int = 60
) -> object:
    """A matplotlib ``Figure`` of ``panels`` side by side, one row per column (``length``,
    ``time``, ``collision_part``, ``collisions``, or ``return``: relative to the panel's
    reference where it has one): each label's mean across its runs per env-step bin with
    a 95% band, the reference dashed. The ``collision_part`` row is left out where no
    run's scenario penalises collisions (the return is all time part)."""
    from matplotlib.figure import Figure

    if not any(penalised(r) for p in panels for rs in p.runs.values() for r in rs):
        columns = [c for c in columns if c != "collision_part"] or ["time"]  # no penalty
    cols = max(1, len(panels))
    fig = Figure(
        figsize=(4.2 * cols + 0.6, 0.6 + 3.6 * len(columns)), dpi=110, layout="constrained"
    )
    for row, column in enumerate(columns):
        first = None
        for k, panel in enumerate(panels):
            ax = fig.add_subplot(len(columns), cols, row * cols + k + 1)
            shown = _draw_panel(ax, panel, column, bins)
            if row == 0:
                ax.set_title(panel.title, fontsize=9)
            if first is None or shown != first:  # each row's label, and where it differs
                ax.set_ylabel(axis_label(shown), fontsize=8)
            first = first or shown
    fig.suptitle(title, fontsize=10)
    return fig


def plot_aggregate(
    panels: list[Panel], column: str | Sequence[str], path: Path, title: str, bins: int = 60
) -> Path:
    """Write :func:`aggregate_figure` of ``column`` (one, or several as rows) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = [column] if isinstance(column, str) else list(column)
    aggregate_figure(panels, columns, title, bins).savefig(path)
    return path


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
