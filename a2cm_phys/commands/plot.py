"""``python -m a2cm_phys.plot RUN_DIR… [--out DIR]``: learning curves from run logs alone.

Each figure answers one question, every run against environment steps (all games), so
that a run of one game and one of sixteen are compared at equal experience:
``lengths.png`` (steps per episode: has it reached the optimum?), ``returns.png`` (the
return split into its time part and its collision penalty: what costs the return?),
``collisions.png`` (do the pursuers learn to avoid each other?) and ``overview.png`` (the
three at once). Each run is a moving average (``--window`` episodes; ``--raw`` adds its
raw episodes as a light band), labelled from its run folder (``A2CM``, ``A2CM (paper)`` for
a run of the paper preset); the scenario's reference is dashed, with each run's gap to it
(the exact optimum on grids the oracle solves; in physics the oracle driven in the arena,
or ``pursuit`` under continuous control, played ``--reference-episodes`` times), or the
legend says why there is none (a learned evader). Every y axis is linear, and says so.

A RUN_DIR's log parts (a resumed run writes ``episodes-KKK-from-NNNNNN.mcap``) are read as
one run, each episode once (see :mod:`a2cm_phys.record.parts`); a file path is read alone.
A damaged or empty log is an error, not an empty figure. ``exploitability.png`` where a run
logged exact exploitability (grid self-play), with the game's value where ``oracle
--game-value`` has cached it.

``--group LABEL=RUN_DIR[,RUN_DIR…]`` (repeatable) or ``--mean`` plots a set of runs as
seeds: one panel per scenario, one line per label (``--group``'s, else the run's label),
the mean across runs with a 95% band (Student t) against environment steps, the reference
dashed; writes ``lengths_mean.png``, ``returns_mean.png`` (the return's time part and its
collision penalty, one row each) and ``collisions_mean.png``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from .options import Parser, UsageError, int_range, run_cli, writable_dir

GROUP_FIGURES = (
    ("lengths_mean.png", ("length",), "Steps per episode"),
    ("returns_mean.png", ("time", "collision_part"), "Return: its time part and its collisions"),
    ("collisions_mean.png", ("collisions",), "Collisions per episode"),
)
"""(file, columns (one row each), title) of each ``--group`` figure."""


def parse_group(text: str) -> tuple[str, list[Path]]:
    """``LABEL=DIR[,DIR…]`` → ``(LABEL, [DIR, …])``; a :class:`UsageError` otherwise."""
    label, sep, dirs = text.partition("=")
    paths = [Path(d.strip()) for d in dirs.split(",") if d.strip()]
    if not sep or not label.strip() or not paths:
        raise UsageError(f"--group {text!r}: expected LABEL=RUN_DIR[,RUN_DIR...]")
    return label.strip(), paths


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.plot`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.plot",
        description="Learning curves (PNG) from run logs, against environment steps,\n"
        "the optimum or the reference policy dashed.\n"
        "  RUN_DIR…: lengths.png (has it reached the optimum?), returns.png (the\n"
        "    return's time part and collision penalty), collisions.png, overview.png\n"
        "  --group: lengths_mean.png, returns_mean.png, collisions_mean.png (95% bands)\n"
        "Every y axis is linear (a ratio to the reference: log) and says so.",
    )
    p.add_argument(
        "runs", type=Path, nargs="*", metavar="RUN_DIR", help="run folders (or episodes.mcap files)"
    )
    p.add_argument(
        "--group",
        action="append",
        default=[],
        metavar="LABEL=DIR[,DIR...]",
        help="runs of one label (seeds), plotted as a mean with a 95%% band; repeatable"
        " (default: none, each run on its own)",
    )
    p.add_argument(
        "--mean",
        action="store_true",
        help="plot the RUN_DIRs as seeds: one panel per scenario, one line per label,"
        " mean ± 95%% (default: off)",
    )
    p.add_argument(
        "--reference-episodes",
        type=int_range(0, 1_000_000),
        default=500,
        help="episodes a physics scenario's reference policy plays for its dashed line"
        " (grids: the exact optimum, none played); 0: no line in physics",
    )
    p.add_argument(
        "--out",
        type=Path,
        help="output folder (default: the run's folder if one run, else ./plots)",
    )
    p.add_argument(
        "--window", type=int_range(1), default=100, help="moving-average window (episodes)"
    )
    p.add_argument(
        "--raw",
        action="store_true",
        help="also draw each run's raw episodes as a light band (10th–90th percentile per"
        " step bin) (default: off, the moving average alone)",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Plot the runs; return the exit code (2 on errors)."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    groups = [parse_group(g) for g in args.group]
    if not args.runs and not groups:
        raise UsageError("give run folders, or --group LABEL=RUN_DIR[,RUN_DIR...]")
    if groups or args.mean:
        return _main_mean(args, groups)
    from ..analysis.figures import plot_runs, unique_labels
    from ..analysis.run_series import load_logged_run

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
    references = _references(runs, args.reference_episodes)
    labels = unique_labels(runs, args.runs)
    for path in plot_runs(runs, labels, out, args.window, references, args.raw):
        print(f"wrote {path}")
    return 0


def _references(runs: list, episodes: int) -> dict:
    """Each distinct scenario's reference line, by name; a note for each that has none."""
    from ..analysis.figure_parts import references_for

    references = references_for([run.scenario for run in runs], episodes)
    for name, ref in references.items():
        if ref.unavailable is not None:
            print(f"note: {name}: no reference line ({ref.unavailable})")
    return references


def _main_mean(args: argparse.Namespace, groups: list[tuple[str, list[Path]]]) -> int:
    from ..analysis.figures import panels_of, plot_aggregate
    from ..analysis.run_series import load_logged_run

    out = args.out or Path("plots")
    writable_dir(out, "--out")
    labelled = [(label, load_logged_run(p)) for label, paths in groups for p in paths]
    labelled += [(run.label, run) for run in (load_logged_run(p) for p in args.runs)]
    panels = panels_of(labelled, _references([r for _, r in labelled], args.reference_episodes))
    for name, columns, what in GROUP_FIGURES:
        title = f"{what}: mean across seeds, 95% band"
        print(f"wrote {plot_aggregate(panels, columns, out / name, title)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
