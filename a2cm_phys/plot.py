"""``python -m a2cm_phys.plot RUN_DIR… [--out DIR]``: learning curves from run logs alone.

Like the paper's figures 5–12: return per episode and steps per episode (each episode
faint, a moving average bold), and collisions per episode; several runs overlaid (A2C
against A2CM), each labelled from its log's metadata. A RUN_DIR's log parts (a resumed run
writes ``episodes-from-NNNNNN.mcap``) are read as one run, each episode once (see
:mod:`a2cm_phys.record.parts`); a file path is read alone. A damaged or empty log is an
error, not an empty figure. Writes ``returns.png``, ``lengths.png``, ``collisions.png`` and
``overview.png``; and ``exploitability.png`` when a run logged exact exploitability (grid
self-play: the evader's best response to the pursuers, i.e. their worst-case capture time,
and the pursuers' best response to the learned evader, every K updates) against
environment steps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .cli import Parser, int_range, run_cli, writable_dir
from .record.reader import LogError, RunLog, read_run

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#17becf")
SERIES = (
    ("return", "returns.png", "Return per episode", "return (raw team reward)"),
    ("length", "lengths.png", "Steps per episode", "steps"),
    ("collisions", "collisions.png", "Collisions per episode", "pursuer collisions"),
)
"""(column, file, title, y label) of each figure."""
EXPLOIT_SERIES = (
    ("exploit_worst_case", "evader's best response (pursuers' worst case)", "-"),
    ("exploit_pursuers_br", "pursuers' best response to the learned evader", "--"),
)
"""(update metric, legend text, line style) of the exploitability figure."""
EXPLOIT_FILE = "exploitability.png"


@dataclass
class Run:
    """One run's per-episode series, read from its log(s)."""

    label: str
    title: str
    columns: dict[str, np.ndarray]
    clean: bool
    exploit: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    """Sparse update metrics of :data:`EXPLOIT_SERIES`: ``(env_steps, values)`` where logged."""


def log_files(path: Path) -> list[Path]:
    """The log files of a run: ``path`` itself, or a run folder's parts in session order."""
    from .record.parts import part_files

    if path.is_dir():
        files = part_files(path)
        if not files:
            raise LogError(f"{path}: no episodes.mcap in this folder")
        return files
    if not path.exists():
        raise LogError(f"{path}: no such file or folder")
    return [path]


def load_run(path: Path) -> Run:
    """Read a run (every part of a run folder's log, each episode once) or one log file.

    A :class:`LogError` if the log is damaged or holds no finished episode: a figure of
    nothing, or of a silently shortened run, would mislead.
    """
    if not path.exists():
        raise LogError(f"{path}: no such file or folder")
    log = read_run(path)
    if log.damaged:
        raise LogError(f"{path}: the log is damaged ({log.error}); see python -m a2cm_phys.replay")
    if not log.n_episodes:
        raise LogError(f"{path}: the log holds no finished episode")
    columns = {k: log.episodes[k] for k in ("return", "length", "collisions", "captured")}
    sc = log.scenario
    title = f"{sc.name} ({sc.mode}, collisions {sc.collisions.mode}, {sc.evader} evader)"
    return Run(
        label=log.label, title=title, columns=columns, clean=log.clean, exploit=_exploit(log)
    )


def _exploit(log: RunLog) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each exploitability metric's ``(env_steps, values)`` over the updates that logged it
    (a finite value; absent, null or NaN elsewhere)."""
    out = {}
    for key, _, _ in EXPLOIT_SERIES:
        pairs = [
            (u["env_steps"], float(u[key]))
            for u in log.updates
            if isinstance(u.get(key), (int, float)) and np.isfinite(u[key])
        ]
        if pairs:
            steps, values = np.array(pairs, dtype=np.float64).T
            out[key] = (steps, values)
    return out


def moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over up to ``window`` episodes (shorter at the start)."""
    values = np.asarray(values, dtype=np.float64)
    if len(values) == 0:
        return values
    csum = np.concatenate([[0.0], np.cumsum(values)])
    idx = np.arange(1, len(values) + 1)
    lo = np.maximum(idx - window, 0)
    return (csum[idx] - csum[lo]) / (idx - lo)


def _unique_labels(runs: list[Run], paths: list[Path]) -> list[str]:
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


def main(argv: Sequence[str] | None = None) -> int:
    """Plot the runs; return the exit code (2 on errors)."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    p = Parser(prog="python -m a2cm_phys.plot", description="Learning curves (PNG) from run logs.")
    p.add_argument(
        "runs", type=Path, nargs="+", metavar="RUN_DIR", help="run folders (or episodes.mcap files)"
    )
    p.add_argument(
        "--out",
        type=Path,
        help="output folder (default: the run's folder if one run, else ./plots)",
    )
    p.add_argument(
        "--window", type=int_range(1), default=100, help="moving-average window (episodes)"
    )
    args = p.parse_args(argv)
    out = args.out or (
        args.runs[0] if len(args.runs) == 1 and args.runs[0].is_dir() else Path("plots")
    )
    writable_dir(out, "--out")
    runs = [load_run(path) for path in args.runs]
    for run, path in zip(runs, args.runs, strict=True):
        if not run.clean:
            print(f"note: {path}: a log was not closed cleanly; plotting what was recovered")
    for path in plot_runs(runs, _unique_labels(runs, args.runs), out, args.window):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
