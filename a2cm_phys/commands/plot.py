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
environment steps, with the game's value as a grey band where ``oracle --game-value`` has
cached it: the pursuers' worst case falls to it from above, the learned evader's rises to it
from below.

``--group LABEL=RUN_DIR[,RUN_DIR…]`` (repeatable) or ``--mean`` plots a set of runs as
seeds: one panel per scenario, one line per label (``--group``'s, else the log's
algorithm), the mean across runs with a 95% band (Student t), against environment steps,
the optimum (grid: the exact oracle) or a reference policy (physics: the oracle driven in
physics, or ``pursuit`` under continuous control) dashed; writes ``lengths_mean.png`` and
``returns_mean.png`` (the return relative to the reference's: 1 is as good, higher worse).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..analysis.figures import (
    Reference,
    panels_of,
    plot_aggregate,
    plot_runs,
    reference_for,
    unique_labels,
)
from ..analysis.run_series import load_logged_run
from .options import Parser, UsageError, int_range, run_cli, writable_dir


def parse_group(text: str) -> tuple[str, list[Path]]:
    """``LABEL=DIR[,DIR…]`` → ``(LABEL, [DIR, …])``; a :class:`UsageError` otherwise."""
    label, sep, dirs = text.partition("=")
    paths = [Path(d.strip()) for d in dirs.split(",") if d.strip()]
    if not sep or not label.strip() or not paths:
        raise UsageError(f"--group {text!r}: expected LABEL=RUN_DIR[,RUN_DIR...]")
    return label.strip(), paths


def main(argv: Sequence[str] | None = None) -> int:
    """Plot the runs; return the exit code (2 on errors)."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    p = Parser(prog="python -m a2cm_phys.plot", description="Learning curves (PNG) from run logs.")
    p.add_argument(
        "runs", type=Path, nargs="*", metavar="RUN_DIR", help="run folders (or episodes.mcap files)"
    )
    p.add_argument(
        "--group",
        action="append",
        default=[],
        metavar="LABEL=DIR[,DIR...]",
        help="runs of one label (seeds), plotted as a mean with a 95%% band (repeatable)",
    )
    p.add_argument(
        "--mean",
        action="store_true",
        help="plot the runs as seeds: one panel per scenario, one line per label, mean ± 95%%",
    )
    p.add_argument(
        "--reference-episodes",
        type=int_range(0, 1_000_000),
        default=500,
        help="episodes the physics reference policy plays (0: no reference line)",
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
    groups = [parse_group(g) for g in args.group]
    if not args.runs and not groups:
        raise UsageError("give run folders, or --group LABEL=RUN_DIR[,RUN_DIR...]")
    if groups or args.mean:
        return _main_mean(args, groups)
    out = args.out or (
        args.runs[0] if len(args.runs) == 1 and args.runs[0].is_dir() else Path("plots")
    )
    writable_dir(out, "--out")
    runs = [load_logged_run(path) for path in args.runs]
    for run, path in zip(runs, args.runs, strict=True):
        if not run.clean:
            print(f"note: {path}: a log was not closed cleanly; plotting what was recovered")
        for problem in run.problems:
            print(f"note: {path}: {problem} (no episode is missing)")
    for path in plot_runs(runs, unique_labels(runs, args.runs), out, args.window):
        print(f"wrote {path}")
    return 0


def _main_mean(args: object, groups: list[tuple[str, list[Path]]]) -> int:
    out = args.out or Path("plots")
    writable_dir(out, "--out")
    labelled = [(label, load_logged_run(p)) for label, paths in groups for p in paths]
    labelled += [(run.label, run) for run in (load_logged_run(p) for p in args.runs)]
    references: dict[str, Reference | None] = {}
    for _, run in labelled:
        sc = run.scenario
        if sc is not None and sc.name not in references:
            grid = sc.mode == "grid"
            references[sc.name] = (
                reference_for(sc, args.reference_episodes)
                if grid or args.reference_episodes
                else None
            )
    panels = panels_of(labelled, references)
    for column, name, what in (
        ("length", "lengths_mean.png", "Steps per episode"),
        ("return", "returns_mean.png", "Return relative to the reference"),
    ):
        path = plot_aggregate(panels, column, out / name, f"{what}: mean across seeds, 95% band")
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
