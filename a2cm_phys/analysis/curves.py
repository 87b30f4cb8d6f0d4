"""Learning curves of single runs against environment steps (``plot RUN_DIR…`` draws them).

Like the paper's figures 5–12, but so that each answers its question at a glance: every
run on the same x axis (environment steps, all games: a run of one game and a run of
sixteen are compared at equal experience, not equal episode counts), a moving average per
run, the scenario's reference (the exact optimum, or a reference policy played) dashed
with each run's gap to it, the return split into its time and collision parts so that the
collision penalty's scale (1.5e8 a collision) hides nothing, and one y-scale rule
(:data:`~.figure_parts.Y_SCALES`, named on each axis). Raw episodes are off by default; on
request they are a light band (the 10th–90th percentile of the episodes ending in each
step bin). Figures (:data:`KINDS`) are returned as matplotlib figures
(:func:`runs_figure`) and written by :func:`plot_runs`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .figure_parts import COLOURS, COLUMNS, Reference, axis_label, draw_reference
from .run_series import Run, collision_weight, penalised

__all__ = [
    "KINDS",
    "moving_average",
    "plot_runs",
    "raw_band",
    "runs_figure",
    "smoothed",
    "unique_labels",
]

KINDS = {
    "lengths": (("length",), "Steps per episode: how far from the reference?"),
    "returns": (
        ("time", "collision_part"),
        "Return split into its time part and its collision penalty",
    ),
    "collisions": (("collisions",), "Collisions per episode: do the pursuers avoid them?"),
    "overview": (("length", "time", "collisions"), "Learning curves"),
}
"""Each single-run figure: its file stem, the columns drawn (one panel each) and its title."""


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


def smoothed(run: Run, column: str, window: int) -> tuple[np.ndarray, np.ndarray]:
    """``(env_steps, moving average)`` of ``column``, the episodes in the order they ended."""
    order = np.argsort(run.columns["env_steps"], kind="stable")
    x = run.columns["env_steps"][order].astype(np.float64)
    return x, moving_average(run.columns[column][order], window)


def raw_band(run: Run, column: str, bins: int = 100) -> tuple[np.ndarray, ...]:
    """``(bin centres, 10th, 90th percentile)`` of ``column`` over the episodes ending in
    each of ``bins`` equal env-step bins (bins where none ends are left out)."""
    x = run.columns["env_steps"].astype(np.float64)
    y = run.columns[column].astype(np.float64)
    edges = np.linspace(0.0, max(float(x.max(initial=0)), 1.0), bins + 1)
    idx = np.clip(np.searchsorted(edges, x, side="left") - 1, 0, bins - 1)
    keep = [b for b in range(bins) if np.any(idx == b)]
    lo = [np.percentile(y[idx == b], 10) for b in keep]
    hi = [np.percentile(y[idx == b], 90) for b in keep]
    centres = (edges[:-1] + edges[1:]) / 2
    return centres[keep], np.array(lo), np.array(hi)


def _gap(value: float, level: float, column: str) -> str:
    """``, +0.93 (+32%) over the optimum`` where the reference is known, else ``""``."""
    if column != "length" or not math.isfinite(level) or not level:
        return ""
    diff = value - level
    return f", {diff:+.3g} steps ({100 * diff / level:+.0f}%) from the reference"


def draw_column(
    ax: object,
    runs: list[Run],
    labels: list[str],
    column: str,
    window: int,
    references: dict[str, Reference],
    raw: bool = False,
) -> None:
    """One panel: each run's moving average of ``column`` against environment steps (and
    its raw episodes as a light band if ``raw``), each scenario's reference dashed."""
    names = list(dict.fromkeys(r.scenario.name for r in runs if r.scenario is not None))
    levels = {}
    for name in names:
        if name in references:
            where = name if len(names) > 1 else ""
            levels[name] = draw_reference(ax, references[name], column, where)
    for i, (run, label) in enumerate(zip(runs, labels, strict=True)):
        colour = COLOURS[i % len(COLOURS)]
        if raw:
            centres, lo, hi = raw_band(run, column)
            ax.fill_between(centres, lo, hi, color=colour, alpha=0.12, lw=0)
        x, y = smoothed(run, column, window)
        n = len(y)
        level = levels.get(run.scenario.name if run.scenario else "", math.nan)
        text = (
            f"{label}: {n:,} episodes, {int(x[-1]):,} steps; last {min(window, n)}: "
            f"{y[-1]:.4g}{_gap(float(y[-1]), level, column)}"
        )
        ax.plot(x, y, color=colour, lw=1.8, label=text)
    ax.set_xlabel("environment steps (all games)")
    ax.set_ylabel(axis_label(column))
    ax.set_yscale("linear")  # the rule: figure_parts.Y_SCALES; no column here is a ratio
    ax.grid(True, alpha=0.3)
    ax.margins(x=0.01)
    ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 4))
    ax.legend(loc="best", fontsize=7.5, framealpha=0.85)


def runs_figure(
    runs: list[Run],
    labels: list[str],
    kind: str,
    window: int,
    references: dict[str, Reference] | None = None,
    raw: bool = False,
) -> object:
    """The ``kind`` figure (:data:`KINDS`) of ``runs`` as a matplotlib ``Figure``. Where
    no run's scenario penalises collisions, the return is drawn whole (it is all time
    part) and its collision panel is left out."""
    from matplotlib.figure import Figure

    columns, title = KINDS[kind]
    weights = sorted({collision_weight(r.scenario) for r in runs if penalised(r)})
    if not weights:  # no collision penalty: the return is all time part, drawn whole
        columns = tuple("return" if c == "time" else c for c in columns if c != "collision_part")
        if kind == "returns":
            title = "Return per episode (collisions carry no penalty: it is all time part)"
    fig = Figure(figsize=(9, 1.0 + 3.6 * len(columns)), dpi=115, layout="constrained")
    for k, column in enumerate(columns):
        ax = fig.add_subplot(len(columns), 1, k + 1)
        draw_column(ax, runs, labels, column, window, references or {}, raw)
        if len(columns) > 1:
            what = COLUMNS[column].split(" (")[0]
            if column == "collision_part":
                what += f" ({', '.join(f'{w:.3g}' for w in weights)} a collision)"
            ax.set_title(what[0].upper() + what[1:], fontsize=9)
    titles = sorted({r.title for r in runs})
    suffix = f"\n{'; '.join(titles)}" if titles else ""
    raw_note = "; raw episodes: 10–90% band" if raw else ""
    fig.suptitle(f"{title} (moving average of {window} episodes{raw_note}){suffix}", fontsize=10)
    return fig


def plot_runs(
    runs: list[Run],
    labels: list[str],
    out: Path,
    window: int,
    references: dict[str, Reference] | None = None,
    raw: bool = False,
) -> list[Path]:
    """Write the figures of ``runs`` into ``out`` (one per :data:`KINDS`, and
    ``exploitability.png`` where a run logged it); return their paths."""
    import matplotlib

    matplotlib.use("Agg")
    from .exploit_figure import EXPLOIT_FILE, exploit_figure

    out.mkdir(parents=True, exist_ok=True)
    written = []
    for kind in KINDS:
        runs_figure(runs, labels, kind, window, references, raw).savefig(out / f"{kind}.png")
        written.append(out / f"{kind}.png")
    if any(r.exploit for r in runs):
        exploit_figure(runs, labels).savefig(out / EXPLOIT_FILE)
        written.append(out / EXPLOIT_FILE)
    return written
