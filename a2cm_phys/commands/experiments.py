"""The reproduction report: every claim of the paper and ours, from real runs.

    python -m a2cm_phys.experiments [--groups paper,ours,continuous,selfplay,descent]
        [--seeds 0-4]
        [--dry-run] [--sequential] [--logdir logs/experiments] [--out docs]
        [--quote-in README.md,BENCHMARKS.md]

Groups of cells (scenario × algorithm × seed), each a sweep in ``<logdir>/<group>/``
(:mod:`a2cm_phys.sweep`: Ray when installed, finished runs skipped, unfinished resumed):

- ``paper``: the paper's three experiments (SPEC §4, §7) × A2C/A2CM × grid/physics with
  ``--preset paper`` (the faithful reproduction), ``--updates`` each (the paper: 5,000);
- ``ours``: the same with our defaults (as shipped, unless ``--updates``);
- ``continuous``: ``phys_cont``, ``phys_cont_flee``, ``phys_cont_collision`` × A2C/A2CM,
  beside ``pursuit`` played on the same scenario (``--cont-updates``, by default
  continuous control's step budget, 2,000,000 or 4,000,000 against the fleeing evader;
  ``--cont-set``);
- ``selfplay``: ``grid_vs`` × A2C/A2CM pursuers against a learning evader, the cross-play
  table and the exact exploitability of the final actors (``--exploit-max-steps``
  truncates the best response's horizon, ``--no-exploit`` skips it);
- ``descent``: the same game with ``--preset descent`` (both teams learn by exploitability
  descent), with the same exact measures beside the game's value bracket.

Before training, one short timed run per cell type gives the wall-time estimate per group
(``--dry-run`` lists the runs and the estimate, and stops). The report ``<out>/RESULTS.md``
opens with the claims table (measured figures, 95% CIs, verdicts and tests), then the
tables (each row linking its runs), figures drawn by :mod:`a2cm_phys.plot` (x in
environment steps, mean across seeds with a 95% band, the optimum or reference dashed),
the per-cell and total wall time, and any run that could not be made. ``--quote-in``
rewrites the headline figures other documents quote from it
(:mod:`a2cm_phys.study.report.headline`).
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import sys
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import ConfigError, load_train
from ..study.report.build import build_report, record_session
from ..study.report.headline import quote_in
from ..study.report.plan import (
    ALGOS,
    EXPERIMENTS,
    GROUPS,
    MODES,
    SELF_PLAY_GROUPS,
    GroupOptions,
    PlannedRun,
    budgets,
    check_groups,
    estimate_seconds,
    plan,
    time_cells,
)
from .options import (
    ASSIGNMENT,
    Parser,
    UsageError,
    check_device,
    int_range,
    run_cli,
    split_assignments,
    writable_dir,
)
from .sweep import parse_seeds

if TYPE_CHECKING:  # the launcher (torch, ray) is imported once the options are parsed
    from ..study.results import Outcome
    from ..study.runspec import RunSpec

__all__ = ["ALGOS", "EXPERIMENTS", "GROUPS", "build_parser", "main"]


_SET_FLAGS = (
    ("--set", "every group: train.KEY=VALUE"),
    ("--cont-set", "continuous runs: train.KEY=VALUE or a scenario KEY=VALUE"),
    ("--selfplay-set", "self-play runs: train.KEY=VALUE"),
)


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.experiments`` argument parser."""
    p = Parser(prog="python -m a2cm_phys.experiments", description=__doc__.split("\n")[0])
    p.add_argument(
        "--groups", default=",".join(GROUPS), help=f"comma-separated, of {', '.join(GROUPS)}"
    )
    p.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 1,3,7 (every group)")
    p.add_argument(
        "--modes", default=",".join(MODES), help="modes of the paper's experiments: grid, physics"
    )
    p.add_argument(
        "--updates",
        type=int_range(1),
        help="updates of the paper/ours runs (default: the paper's 5,000 with its method,"
        " the shipped defaults with ours)",
    )
    p.add_argument(
        "--cont-updates",
        type=int_range(1),
        help="updates of the continuous runs (default: train's step budget, 2,000,000 steps"
        " at 10 Hz; 4,000,000 against the fleeing evader)",
    )
    p.add_argument(
        "--selfplay-updates",
        type=int_range(1),
        help="updates of the self-play and descent runs (default: the shipped defaults,"
        " and the descent preset's)",
    )
    for flag, what in _SET_FLAGS:
        p.add_argument(
            flag,
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help=f"{what}; one pair per flag, repeat the flag for more",
        )
    _add_report_options(p)
    p.add_argument(
        "--logdir", "--sweep-dir", dest="logdir", default="logs/experiments", help="runs go here"
    )
    p.add_argument("--out", default="docs", help="where RESULTS.md and figures/ go")
    p.add_argument("--address", help="Ray cluster address (default: start Ray on this machine)")
    p.add_argument("--sequential", action="store_true", help="no Ray, even if installed")
    p.add_argument("--dry-run", action="store_true", help="list the runs and the estimate; stop")
    p.add_argument("--report-only", action="store_true", help="no training: report what exists")
    p.add_argument(
        "--estimate-updates",
        type=int_range(0),
        default=20,
        help="updates of the timed short run per cell type; 0: no estimate",
    )
    return p


def _add_report_options(p: argparse.ArgumentParser) -> None:
    """The options of what the report measures and where its figures go."""
    p.add_argument(
        "--eval-episodes",
        type=int_range(1, 10_000_000),
        default=2000,
        help="greedy episodes evaluating each run's final policy",
    )
    p.add_argument(
        "--crossplay-episodes",
        type=int_range(1, 10_000_000),
        default=500,
        help="episodes per pairing of the self-play cross-play table",
    )
    p.add_argument(
        "--exploit-max-steps",
        type=int_range(1),
        help="truncate the evader's exact best response at this horizon (faster; a lower"
        " bound, said so in the report; default: the scenario's max_steps, exact)",
    )
    p.add_argument("--no-exploit", action="store_true", help="skip the exact exploitability")
    p.add_argument(
        "--bench-records",
        default="benchmarks/results",
        metavar="DIR",
        help="the benchmarks' records (*.jsonl) the claims on partial observability, scale"
        " and speed are tested on (none there: those claims are left out)",
    )
    p.add_argument(
        "--quote-in",
        metavar="FILES",
        help="comma-separated documents (e.g. README.md,BENCHMARKS.md) whose quotes of the"
        " report's headline figures (<!-- results: KEY -->…<!-- /results -->) are rewritten"
        " from the new results.json (default: none)",
    )


def check_one_pair_per_flag(argv: Sequence[str]) -> None:
    """A :class:`UsageError` for ``--cont-set A=1 B=2`` (the old several-pairs form; the
    parser refuses it for ``--set``), showing the repeated form."""
    for flag, _ in _SET_FLAGS[1:]:
        for i, word in enumerate(argv[:-2]):
            if word == flag and ASSIGNMENT.match(argv[i + 2]):
                raise UsageError(
                    f"{flag} takes one KEY=VALUE per flag: write {flag} {argv[i + 1]}"
                    f" {flag} {argv[i + 2]} (repeat {flag} for each pair)"
                )


def _given(key: str, value: Any) -> dict[str, Any]:
    """``{key: value}``, or nothing when the option was not given (train's default)."""
    return {} if value is None else {key: value}


def _options(args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, GroupOptions]]:
    scenario, base = split_assignments(args.set)
    if scenario:
        raise ConfigError(
            f"--set {next(iter(scenario))}: only train.KEY=VALUE (the scenarios are fixed;"
            " --cont-set takes scenario keys)"
        )
    cont_scenario, cont_train = split_assignments(args.cont_set)
    sp_scenario, sp_train = split_assignments(args.selfplay_set)
    if sp_scenario:
        raise ConfigError(f"--selfplay-set {next(iter(sp_scenario))}: only train.KEY=VALUE")
    options = {
        "paper": GroupOptions(_given("updates", args.updates)),
        "ours": GroupOptions(_given("updates", args.updates)),
        "continuous": GroupOptions(
            {**_given("updates", args.cont_updates), **cont_train}, cont_scenario
        ),
        "selfplay": GroupOptions({**_given("updates", args.selfplay_updates), **sp_train}),
        "descent": GroupOptions({**_given("updates", args.selfplay_updates), **sp_train}),
    }
    return base, options


def _parallel(args: argparse.Namespace) -> tuple[int, str]:
    if args.sequential:
        return 1, "sequential"
    try:
        import ray  # noqa: F401
    except ImportError:
        return 1, "sequential (no Ray)"
    cores = os.cpu_count() or 1
    return cores, f"on Ray, {cores} at a time"


def print_plan(
    runs: list[PlannedRun], estimates: dict[tuple[str, str], Any], args: argparse.Namespace,
    listing: bool,
) -> None:  # fmt: skip
    """The runs (with ``listing``) and the wall-time estimate per group, on stdout."""
    parallel, how = _parallel(args)
    horizon = 0 if args.no_exploit else args.exploit_max_steps
    total = 0.0
    print(f"{len(runs)} runs, training {how}")
    for group in GROUPS:
        mine = [r for r in runs if r.cell.group == group]
        if not mine:
            continue
        states = [r.state for r in mine]
        counts = ", ".join(f"{states.count(s)} {s}" for s in ("new", "partial", "done"))
        if listing:
            for r in mine:
                print(f"  {group}/{r.run_dir.name}: {r.state}")
        line = f"{group}: {len(mine)} runs ({counts})"
        if estimates:
            serial = sum(
                estimate_seconds(
                    r,
                    estimates[(group, r.cell.scenario)],
                    args.crossplay_episodes if group in SELF_PLAY_GROUPS else args.eval_episodes,
                    horizon,
                )
                for r in mine
            )
            wall = serial / min(parallel, max(1, len(mine)))
            total += wall
            line += f", ~{duration(serial)} of runs, ~{duration(wall)} wall"
        print(line)
    if estimates:
        print(
            f"estimated total: ~{duration(total)} wall ({how}; from one timed "
            f"{args.estimate_updates}-update run per cell type; runs sharing cores go slower)"
        )


def duration(seconds: float) -> str:
    """``42 s``, ``17 min`` or ``2.3 h``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.experiments``; returns the exit status."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    check_one_pair_per_flag(argv)
    args = build_parser().parse_args(argv)
    start = time.perf_counter()
    groups = check_groups(args.groups)
    seeds = parse_seeds(args.seeds)
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        raise ConfigError(f"--modes: unknown mode {(bad or [args.modes])[0]!r} (grid, physics)")
    base, options = _options(args)
    check_device(load_train(base).device)
    logdir = writable_dir(args.logdir, "--logdir")
    out = writable_dir(args.out, "--out")
    quoting = [Path(name.strip()) for name in (args.quote_in or "").split(",") if name.strip()]
    for path in quoting:
        if not path.is_file():
            raise ConfigError(f"--quote-in: no file {path}")
    runs = plan(groups, modes, seeds, logdir, base, options)
    estimates = {}
    if args.estimate_updates and not args.report_only:
        todo = [r for r in runs if r.state != "done"] or runs
        estimates = time_cells(todo, args.estimate_updates, logdir / "estimate_cache.json")
    print_plan(runs, estimates, args, listing=args.dry_run)
    if args.dry_run:
        return 0
    errors: dict[str, str] = {}
    use_ray = False
    if not args.report_only:
        try:
            use_ray = _train(runs, groups, logdir, args, errors)
        except KeyboardInterrupt:
            # the session's time still counts towards the report's total
            record_session(logdir, _meta(args, argv, False, budgets(runs)), start)
            print(
                "interrupted: finished runs are kept; run the same command to go on, or"
                " add --report-only for a report of what exists",
                file=sys.stderr,
            )
            return 130

    meta = _meta(args, argv, use_ray, budgets(runs))
    missing = build_report(runs, errors, out, logdir, meta, start, args, groups, modes)
    print(f"report: {out / 'RESULTS.md'}")
    for path in quote_in(quoting, out / "results.json"):
        print(f"quotes rewritten: {path}")
    for run, why in missing:
        print(f"not in the report: {run.cell.group}/{run.run_dir.name}: {why}", file=sys.stderr)
    return 1 if errors else 0


def _train(
    runs: list[PlannedRun],
    groups: list[str],
    logdir: Path,
    args: argparse.Namespace,
    errors: dict[str, str],
) -> bool:
    """Train the runs, group by group, with their progress (runs done of all, the one
    going on) on stderr; each failure into ``errors``; whether Ray trained them."""
    from ..study.launch import run_all
    from ..study.watch import RunsProgress

    use_ray = False
    with RunsProgress("runs", len(runs), out=sys.stderr) as progress:
        for group in groups:
            mine = [r for r in runs if r.cell.group == group]
            sweep_dir = logdir / group
            sweep_dir.mkdir(parents=True, exist_ok=True)

            def done(o: Outcome, group: str = group) -> None:
                what = o.summary.get("sweep") if o.summary else f"FAILED ({o.error})"
                progress.finished(f"{group}/{o.spec.name}", f"{group}/{o.name}: {what}")

            def begin(spec: RunSpec, group: str = group) -> None:
                progress.started(f"{group}/{spec.name}")

            outcomes, use_ray = run_all(
                [r.spec for r in mine],
                sweep_dir,
                done,
                args.address,
                1.0,
                args.sequential,
                on_start=begin,
            )
            errors.update({f"{group}/{o.spec.name}": o.error for o in outcomes if o.error})
    return use_ray


def _meta(
    args: argparse.Namespace, argv: Sequence[str], use_ray: bool, budget: str
) -> dict[str, Any]:
    """What the report says of this session: its command, date, machine, budgets."""
    return {
        "command": shlex.join(["python", "-m", "a2cm_phys.experiments", *argv]),
        "date": datetime.now().strftime("%Y-%m-%d"),
        "machine": f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores"
        f" ({platform.processor() or 'cpu'}), Python {platform.python_version()}",
        "parallel": "on Ray" if use_ray else _parallel(args)[1],
        "seeds": args.seeds,
        "eval_episodes": args.eval_episodes,
        "budget": budget,
    }


if __name__ == "__main__":
    sys.exit(main())
